"""Small problem files that several test files start from and edit, written once here."""

# A noisy double integrator with two knots: position 1 (penalised and constrained) at t = 1,
# rest at t = 2. test_problem_errors.py edits it in one place per bad-input case.
BASE = """\
name = "di"
t0 = 0.0
x0 = [0.0, 0.0]
tick_hz = 10

[dynamics]
A = [[0, 1], [0, 0]]
B = [[0], [1]]
noise = [{ state = 1, G = [[0], [0.3]] }]

[cost]
Q = [[0, 0], [0, 0]]
R = [[1]]

[[knots]]
t = 1.0
penalty = { C = [[1, 0]], target = [1.0], weight = 2.0 }
constraint = { C = [[1, 0]], value = [1.0] }

[[knots]]
t = 2.0
constraint = { C = [[1, 0], [0, 1]], value = [0.0, 0.0] }
"""

# BASE with a per-stage input weight on stage 1 and a damped A on stage 2.
STAGES = BASE + """
[[stages]]
cost = { R = [[2]] }

[[stages]]
dynamics = { A = [[0, 1], [0, -1]] }
"""


def edit(base: str, *pairs: tuple[str, str]) -> str:
    """`base` with each ``(old, new)`` replaced; `old` must occur exactly once."""
    for old, new in pairs:
        assert base.count(old) == 1, f"{old!r} occurs {base.count(old)} times"
        base = base.replace(old, new)
    return base


def cart(*, name: str = "cart", t: str = "1.0", noise: bool = True) -> str:
    """The smallest problem: a double integrator that must reach position 1 at time `t`
    (noise on the velocity unless `noise` is false)."""
    noise_line = "noise = [{ state = 1, G = [[0], [0.3]] }]\n" if noise else ""
    return (f'name = "{name}"\nx0 = [0.0, 0.0]\ntick_hz = 10\n'
            f"[dynamics]\nA = [[0, 1], [0, 0]]\nB = [[0], [1]]\n{noise_line}"
            f"[cost]\nR = [[1]]\n"
            f"[[knots]]\nt = {t}\nconstraint = {{ C = [[1, 0]], value = [1.0] }}\n")


def tracked_cart_doc() -> dict:
    """A noisy cart with a drift following tracking paths, as a decoded file: the top-level
    path (two outputs, a coupled weight, an offset) on stages 0 and 2, stage 1's own path (one
    output, no offset written); runtime parameters on the three offsets, a knot value, the
    drift and the start."""
    return {
        "name": "tracked", "x0": [0.0, 0.5], "tick_hz": 10,
        "dynamics": {"A": [[0, 1], [0, -0.2]], "B": [[0], [1]], "f": [0.0, -0.5],
                     "noise": [{"state": 1, "G": [[0], [0.3]]}]},
        "cost": {"R": [[1]],
                 "tracking": {"C": [[1, 0], [0, 1]], "weight": [[2.0, 0.5], [0.5, 1.0]],
                              "t": [0, 1.5, 3], "y0": [[0, 0], [1, 0.5], [0.5, 0]],
                              "offset": [0.1, 0.0]}},
        "knots": [{"t": 1.0, "penalty": {"C": [[1, 0]], "target": [0.8], "weight": 2.0}},
                  {"t": 2.0},
                  {"t": 3.0, "constraint": {"C": [[1, 0], [0, 1]], "value": [0.0, 0.0]}}],
        "stages": [{}, {"cost": {"tracking": {"C": [[1, 0]], "weight": 3.0, "t": [1, 2],
                                              "y0": [[1.0], [0.0]], "interpolation": "zoh"}}},
                   {}],
        "parameters": [
            {"name": "shift_x", "sets": ["cost.tracking.offset[0]"], "range": [-0.4, 0.6]},
            {"name": "shift_v", "sets": ["cost.tracking.offset[1]"], "range": [-0.5, 0.5]},
            {"name": "late", "sets": ["stages[1].cost.tracking.offset[0]"], "range": [-1, 1]},
            {"name": "rest", "sets": ["knots[2].constraint.value[0]"], "range": [-0.5, 0.5]},
            {"name": "push", "sets": ["dynamics.f[1]"], "range": [-1.0, 0.0]},
            {"name": "v0", "sets": ["x0[1]"], "range": [0.0, 1.0]}]}
