"""C plant models for the tests: the unicycle's parts and a linear double integrator, with a
way to break each (`broken`)."""

DIMS = """
void stospline_plant_dims(int dims[4])
{
    dims[0] = 2; dims[1] = 1; dims[2] = 1; dims[3] = 1;
}
"""
# dx = (x1, u) dt + (0, p0 x1) dZ: the docs' noisy double integrator, linear in x and u.
DRIFT = """
int stospline_plant_drift(double t, const double *x, const double *u, const double *p,
                          double *f)
{
    (void)t; (void)p;
    f[0] = x[1];
    f[1] = u[0];
    return 0;
}
"""
DIFFUSION = """
int stospline_plant_diffusion(double t, const double *x, const double *u, const double *p,
                              double *g)
{
    (void)t; (void)u;
    g[0] = 0.0;
    g[1] = p[0] * x[1];
    return 0;
}
"""
LINEAR = '#include "stospline_plant.h"\n' + DIMS + DRIFT + DIFFUSION

# Each entry: (C text, words the one-line refusal must contain).
BROKEN = {
    "missing_diffusion": ('#include "stospline_plant.h"\n' + DIMS + DRIFT,
                          "does not define stospline_plant_diffusion"),
    "wrong_signature": (DIMS + DRIFT.replace("const double *p,\n", "const float *p,\n")
                        + DIFFUSION, "stospline_plant_drift does not have the signature"),
    "compile_error": (LINEAR + "int broken(void) { return 0 }\n", "does not compile"),
    "undeclared_call": (LINEAR + "int later(void) { return undeclared_fn(1); }\n",
                        "does not compile"),
    "nan_drift": ("#include <math.h>\n" + DIMS
                  + DRIFT.replace("f[1] = u[0];", "f[1] = u[0] + NAN;") + DIFFUSION,
                  "NaN or infinite"),
    "status": (DIMS + DRIFT.replace("return 0;", "return x[0] > 0.25 ? 7 : 0;") + DIFFUSION,
               "returned 7"),
    "dims_n": (DIMS.replace("dims[0] = 2", "dims[0] = 3") + DRIFT + DIFFUSION,
               "n = 3 states"),
    "dims_params": (DIMS.replace("dims[3] = 1", "dims[3] = 2") + DRIFT + DIFFUSION,
                    "model reads 2"),
    "additive_noise": (DIMS + DRIFT + DIFFUSION.replace("g[1] = p[0] * x[1];",
                                                        "g[1] = p[0] * x[1] + 0.1;"),
                       "independent of x and u"),
    "empty": ("", "does not define"),
}


def linear_doc(source: str = "model.c") -> dict:
    """The docs' noisy double integrator (tests/python/cli/hostile.py NOISY, one stage's data)
    with its dynamics given by the C model `source`."""
    return {
        "name": "di", "t0": 0.0, "x0": [0.5, 0.0], "tick_hz": 20,
        "plant": {"source": source, "params": [0.3]},
        "cost": {"Q": [[0.1, 0], [0, 0]], "R": [[1]]},
        "knots": [{"t": 1.0, "penalty": {"C": [[1, 0]], "target": [1.0], "weight": 2.0},
                   "constraint": {"C": [[1, 0]], "value": [1.0]}},
                  {"t": 2.0, "constraint": {"C": [[1, 0], [0, 1]], "value": [0.0, 0.0]}}],
    }


def the_same_linear_doc() -> dict:
    """`linear_doc` as today's linear problem: [dynamics] instead of [plant]."""
    doc = linear_doc()
    del doc["plant"]
    doc["dynamics"] = {"A": [[0, 1], [0, 0]], "B": [[0], [1]],
                       "noise": [{"state": 1, "G": [[0], [0.3]]}]}
    return doc


LINEAR_TOML = """\
name = "di"
t0 = 0.0
x0 = [0.5, 0.0]
tick_hz = 20

[plant]
source = "model.c"
params = [0.3]

[cost]
Q = [[0.1, 0], [0, 0]]
R = [[1]]

[[knots]]
t = 1.0
penalty = { C = [[1, 0]], target = [1.0], weight = 2.0 }
constraint = { C = [[1, 0]], value = [1.0] }

[[knots]]
t = 2.0
constraint = { C = [[1, 0], [0, 1]], value = [0.0, 0.0] }
"""   # linear_doc() as a file
