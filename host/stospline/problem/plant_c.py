"""Build a ``[plant]`` model (`stospline.problem.plant_model.PlantSpec`) into a cffi module
through the build cache (`stospline.cache`) and call it from Python.

The model's C text is checked first by the compiler alone (``-fsyntax-only`` with the
interface header in front), so that a wrong prototype, an undeclared function or any other
compile error is one `ProblemError` on ``plant.source`` quoting the compiler's first error;
a function declared but never defined is found when the module loads. Every call checks the
model's status and that its outputs are finite (`PlantModel.drift`, `PlantModel.diffusion`).
"""
from __future__ import annotations

import re
import subprocess
from pathlib import Path

import numpy as np

from stospline.cache import c_compiler, cached_build, compile_cffi, load_module, source_key
from stospline.errors import ProblemError

__all__ = ["PlantModel", "build_plant", "HEADER", "FUNCTIONS"]

HEADER = Path(__file__).with_name("stospline_plant.h")
FUNCTIONS = ("stospline_plant_dims", "stospline_plant_drift", "stospline_plant_diffusion")
_CDEF = """
void stospline_plant_dims(int dims[4]);
int stospline_plant_drift(double t, const double *x, const double *u, const double *p,
                          double *f);
int stospline_plant_diffusion(double t, const double *x, const double *u, const double *p,
                              double *g);
int stospline__drift_many(int N, const double *t, const double *x, const double *u,
                          const double *p, double *f, int *status);
int stospline__diffusion_many(int N, const double *t, const double *x, const double *u,
                              const double *p, double *g, int *status);
int stospline__exp_em_steps(int N, int steps, double t, double dt, double dz_scale,
                            const double *u, const double *p, const double *lin,
                            const double *z, double *x, double *xs, double *work,
                            int *status);
"""
# Batches of points in one call (a linearisation evaluates the model at tens of thousands of
# points): the index of the first point refused, its status in *status; -1 when all are fine.
_MANY = """
static int stospline__dims_(int which)
{
    int dims[4];
    stospline_plant_dims(dims);
    return dims[which];
}

int stospline__drift_many(int N, const double *t, const double *x, const double *u,
                          const double *p, double *f, int *status)
{
    int n = stospline__dims_(0), m = stospline__dims_(1);
    for (int k = 0; k < N; ++k) {
        *status = stospline_plant_drift(t[k], x + k * n, u + k * m, p, f + k * n);
        if (*status != 0) return k;
    }
    return -1;
}

int stospline__diffusion_many(int N, const double *t, const double *x, const double *u,
                              const double *p, double *g, int *status)
{
    int n = stospline__dims_(0), m = stospline__dims_(1), mz = stospline__dims_(2);
    for (int k = 0; k < N; ++k) {
        *status = stospline_plant_diffusion(t[k], x + k * n, u + k * m, p, g + k * n * mz);
        if (*status != 0) return k;
    }
    return -1;
}

/* Exponential Euler-Maruyama about a linear model (A, B, c) of the drift: `steps` steps of dt
 * from t for each of N paths, u (N, m) held, z (N, steps, mz) standard normal numbers:
 *     x+ = Ad x + Bd u + fd + dt (f(t, x, u) - A x - B u - c) + g(t, x, u) dz_scale z,
 * lin = [Ad (n, n), Bd (n, m), fd (n), A (n, n), B (n, m), c (n)], Ad, Bd, fd the exact step
 * of the linear model over dt. x (N, n) advanced in place, xs (N, steps, n) the state at each
 * step's start; work: 2 n + n mz doubles. The linear part is summed in the order of the
 * harness's plant step (harness/plant.c, from +0.0), so on a model the linear one matches the
 * remainder is +0.0 and the step is the harness's. */
int stospline__exp_em_steps(int N, int steps, double t, double dt, double dz_scale,
                            const double *u, const double *p, const double *lin,
                            const double *z, double *x, double *xs, double *work,
                            int *status)
{
    int n = stospline__dims_(0), m = stospline__dims_(1), mz = stospline__dims_(2);
    const double *Ad = lin, *Bd = Ad + n * n, *fd = Bd + n * m;
    const double *A = fd + n, *B = A + n * n, *c = B + n * m;
    double *f = work, *xn = work + n, *g = work + 2 * n;
    for (int k = 0; k < N; ++k) {
        double *xk = x + k * n;
        const double *uk = u + k * m;
        for (int s = 0; s < steps; ++s) {
            const double *zs = z + (k * steps + s) * mz;
            double ts = t + s * dt;
            for (int i = 0; i < n; ++i) xs[(k * steps + s) * n + i] = xk[i];
            *status = stospline_plant_drift(ts, xk, uk, p, f);
            if (*status != 0) return k;
            *status = stospline_plant_diffusion(ts, xk, uk, p, g);
            if (*status != 0) return k;
            for (int i = 0; i < n; ++i) {
                double acc = 0.0, lin_f = 0.0;
                for (int j = 0; j < n; ++j) acc += Ad[i * n + j] * xk[j];
                for (int j = 0; j < m; ++j) acc += Bd[i * m + j] * uk[j];
                acc += fd[i];
                for (int j = 0; j < n; ++j) lin_f += A[i * n + j] * xk[j];
                for (int j = 0; j < m; ++j) lin_f += B[i * m + j] * uk[j];
                acc += dt * (f[i] - (lin_f + c[i]));
                for (int j = 0; j < mz; ++j) acc += g[i * mz + j] * (zs[j] * dz_scale);
                xn[i] = acc;
            }
            for (int i = 0; i < n; ++i) xk[i] = xn[i];
        }
    }
    return -1;
}
"""
# C99 and no implicit declarations: a model that calls an undeclared function is refused
# rather than miscompiled.
_CFLAGS = ["-std=c99", "-Werror=implicit-function-declaration", "-Werror=implicit-int"]
_FIELD = "plant.source"


def _wrapped(spec) -> str:
    """The C text cffi compiles: the header, then the model with its own line numbers."""
    return (f'#include "stospline_plant.h"\n{_MANY}\n'
            f'#line 1 "{spec.path.name}"\n{spec.source.decode()}\n')


def _first_error(stderr: str, name: str) -> str:
    lines = [ln for ln in stderr.splitlines() if "error" in ln]
    line = lines[0] if lines else (stderr.strip().splitlines() or ["(no message)"])[0]
    return line.split(f"{name}:", 1)[-1].strip() if name in line else line.strip()


def _syntax_check(spec) -> None:
    """Refuse a model the compiler rejects, naming the function with a wrong prototype."""
    compiler, found = c_compiler()
    if not found:
        return            # the build below raises CompilerMissing, which says so plainly
    cmd = [compiler, *_CFLAGS, "-fsyntax-only", "-I", str(HEADER.parent),
           "-I", str(spec.path.parent), "-x", "c", "-"]
    r = subprocess.run(cmd, input=_wrapped(spec), capture_output=True, text=True, timeout=120)
    if r.returncode == 0:
        return
    for fn in FUNCTIONS:
        if re.search(rf"conflicting types for .{fn}.", r.stderr):
            raise ProblemError(_FIELD, f"{fn} does not have the signature of "
                                       f"stospline_plant.h (docs/guide/plant-model.md)")
    raise ProblemError(_FIELD, f"{spec.path.name} does not compile: "
                               f"{_first_error(r.stderr, spec.path.name)}")


def _module(spec):
    _syntax_check(spec)
    text = _wrapped(spec)
    header = HEADER.read_bytes()
    key = source_key([text, _CDEF, header, " ".join(_CFLAGS), str(spec.path.parent)])
    modname = f"_stospline_plant_{key}"

    def build(out: Path) -> Path:
        return compile_cffi(out, modname, _CDEF, text, cflags=_CFLAGS,
                            include_dirs=[HEADER.parent, spec.path.parent])

    path = cached_build(key, modname, build)
    try:
        return load_module(path)
    except ImportError as exc:
        missing = re.search(r"undefined symbol: (\w+)", str(exc))
        what = f"does not define {missing.group(1)}" if missing else f"does not load ({exc})"
        raise ProblemError(_FIELD, f"{spec.path.name} {what} "
                                   f"(it must define {', '.join(FUNCTIONS)})") from None


class PlantModel:
    """The compiled drift ``f(t, x, u)`` (n,) and diffusion ``g(t, x, u)`` (n, mz) of a
    ``[plant]`` model at its parameters; `n`, `m`, `mz` as the model declares them."""

    def __init__(self, spec, n: int):
        self.spec = spec
        module = _module(spec)
        self.lib, self.ffi = module.lib, module.ffi
        dims = self.ffi.new("int[4]")
        self.lib.stospline_plant_dims(dims)
        self.n, self.m, self.mz, n_params = (int(d) for d in dims)
        if self.n != n:
            raise ProblemError(_FIELD, f"the model has n = {self.n} states "
                                       f"(stospline_plant_dims) but x0 has {n}")
        if self.m < 1 or self.mz < 1 or n_params < 0:
            raise ProblemError(_FIELD, f"stospline_plant_dims gives m = {self.m}, "
                                       f"mz = {self.mz}, {n_params} parameters; m and mz "
                                       f"must be at least 1")
        if spec.params.size != n_params:
            raise ProblemError("plant.params", f"has {spec.params.size} values but the "
                                               f"model reads {n_params} "
                                               f"(stospline_plant_dims)")
        self._p = self.ffi.new("double[]", max(1, n_params))
        for i, v in enumerate(spec.params):
            self._p[i] = float(v)

    def _many(self, fn, name: str, width: int, t, x, u) -> np.ndarray:
        t = np.ascontiguousarray(np.broadcast_to(np.asarray(t, dtype=float), np.shape(x)[:1]))
        x = np.ascontiguousarray(x, dtype=float).reshape(-1, self.n)
        u = np.ascontiguousarray(u, dtype=float).reshape(-1, self.m)
        out = np.zeros((x.shape[0], width))
        ffi = self.ffi
        status = ffi.new("int *")
        bad = fn(x.shape[0], ffi.from_buffer("double[]", t), ffi.from_buffer("double[]", x),
                 ffi.from_buffer("double[]", u), self._p, ffi.from_buffer("double[]", out),
                 status)
        what = f"returned {status[0]}"
        if bad < 0:
            rows = np.flatnonzero(~np.all(np.isfinite(out), axis=1))
            if rows.size == 0:
                return out
            bad, what = int(rows[0]), "gave a NaN or infinite value"
        raise ProblemError(_FIELD, f"{name} {what} at t = {t[bad]:g}, "
                                   f"x = {np.array2string(x[bad], precision=4)}, "
                                   f"u = {np.array2string(u[bad], precision=4)}")

    def drift(self, t, x, u) -> np.ndarray:
        """f at the points ``(t[k], x[k], u[k])``: shape (N, n) for x (N, n), u (N, m)."""
        return self._many(self.lib.stospline__drift_many, "stospline_plant_drift", self.n,
                          t, x, u)

    def diffusion(self, t, x, u) -> np.ndarray:
        """g at the points ``(t[k], x[k], u[k])``: shape (N, n, mz)."""
        return self._many(self.lib.stospline__diffusion_many, "stospline_plant_diffusion",
                          self.n * self.mz, t, x, u).reshape(-1, self.n, self.mz)


    def exp_em_steps(self, t: float, dt: float, dz_scale: float, X: np.ndarray,
                     U: np.ndarray, lin: np.ndarray, z: np.ndarray) -> np.ndarray:
        """Exponential Euler-Maruyama about the linear model `lin` (``[Ad, Bd, fd, A, B, c]``
        raveled, ``stospline__exp_em_steps``) over ``z.shape[1]`` steps of `dt` from `t` for
        every path: X (N, n) advanced in place, U (N, m) held, z (N, steps, mz) standard
        normal numbers, the Brownian increments ``dz_scale * z``; returns the state at each
        step's start (N, steps, n)."""
        N, steps = z.shape[:2]
        U = np.ascontiguousarray(U, dtype=float)
        xs = np.empty((N, steps, self.n))
        work = np.empty(2 * self.n + self.n * self.mz)
        ffi, status = self.ffi, self.ffi.new("int *")
        buf = ffi.from_buffer
        assert X.flags.c_contiguous and z.flags.c_contiguous and lin.flags.c_contiguous
        bad = self.lib.stospline__exp_em_steps(
            N, steps, float(t), float(dt), float(dz_scale), buf("double[]", U), self._p,
            buf("double[]", lin), buf("double[]", z), buf("double[]", X),
            buf("double[]", xs), buf("double[]", work), status)
        if bad >= 0:
            raise ProblemError(_FIELD, f"the model returned {status[0]} at t = {t:g} on "
                                       f"Monte Carlo path {bad}")
        return xs


def build_plant(spec, n: int) -> PlantModel:
    """Compile (or load from the cache) and check the model of `spec` for `n` states."""
    return PlantModel(spec, n)
