"""Monte Carlo of a table with runtime parameters through the compiled C: the firmware's
``stsp_set_params`` and ``stsp_param_step`` (stsp_params.h) drive the harness's plant
(plant.c) on the problem at the parameters in force, set once before tick 0 or changed during
the plan (at a stage start or at any tick).

Build and run are separate steps: `build_params_controller` compiles ``firmware/src/*.c``
with the generated gain table and its parameter table; `simulate_params` runs paths through it.
`build_params_qcontroller` compiles the Q15/Q31 build with a fixed-point parametric table:
`ParamsController.steps` drives it with Q integers (no plant), and `simulate_params` runs it
on the plant as the Monte Carlo of a Q15/Q31 gain table does (`controller.q_io`: the states
rounded half up to their Q format and saturated, the integer commands times their LSB).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stospline.harness.build import PLANT_CDEF, build_harness_module
from stospline.harness.controller import VARIANTS, CompiledController, q_io
from stospline.harness.montecarlo import joint_verdict
from stospline.harness.plant_spec import zoh_step
from stospline.problem.parameters import problem_at
from stospline.table.codegen import generate_c
from stospline.table.parametric_c import generate_parametric_c, generate_parametric_qc

__all__ = ["build_params_controller", "build_params_qcontroller",
           "build_params_qspline_controller", "ParamsController",
           "ParamsRun", "simulate_params"]

_CDEF = PLANT_CDEF + """
typedef int... stsp_status_t;
typedef struct { ...; } stsp_param_t;
const char *stsp_status_str(stsp_status_t status);
int harness_param_init(stsp_param_t *pc, size_t count);
int harness_param_set(stsp_param_t *pc, size_t count, const float *theta);
int harness_param_step(stsp_param_t *pc, size_t count, uint32_t tick, const %(s)s *X,
                       %(s)s *U);
"""

# Harness-only C: every path's instance in one call. Init validates instance 0 (both tables'
# CRCs) and copies it: the instances hold no pointer into themselves.
_BATCH = """
#include "plant.h"
#include "%(p)s_params.h"
int harness_param_init(stsp_param_t *pc, size_t count) {
    size_t i;
    stsp_status_t st = stsp_param_init(&pc[0], &%(p)s_table, &%(p)s_params);
    for (i = 1; i < count; ++i) pc[i] = pc[0];
    return (int)st;
}
int harness_param_set(stsp_param_t *pc, size_t count, const float *theta) {
    size_t i;
    int worst = 0;
    for (i = 0; i < count; ++i) {
        const stsp_status_t st = stsp_set_params(&pc[i], theta);
        if ((int)st < worst) worst = (int)st;
    }
    return worst;
}
/* X (count x nx) states, U (count x nu), the build's scalars; returns the worst status. */
int harness_param_step(stsp_param_t *pc, size_t count, uint32_t tick, const %(s)s *X,
                       %(s)s *U) {
    size_t i;
    int worst = 0;
    for (i = 0; i < count; ++i) {
        const stsp_status_t st = stsp_param_step(&pc[i], tick, &X[i * %(P)s_NX],
                                                 &U[i * %(P)s_NU]);
        if ((int)st < worst) worst = (int)st;
    }
    return worst;
}
"""


@dataclass
class ParamsController:
    """The compiled parametric controller; `plant_helpers` the harness's plant and normals."""
    ffi: object
    lib: object
    table: object

    @property
    def plant_helpers(self) -> CompiledController:
        return CompiledController(self.ffi, self.lib, self.table)

    def status_str(self, status: int) -> str:
        return self.ffi.string(self.lib.stsp_status_str(status)).decode()

    def steps(self, thetas: dict, X: np.ndarray, dtype=np.float32) -> tuple[np.ndarray, int]:
        """Every tick in order from 0 for the paths of `X` (ticks, paths, nx), the parameters
        `thetas[j]` set just before tick j (every path alike; 0 or a missing entry: nominal
        until the first): the commands (ticks, paths, nu) and the worst status."""
        T, paths, _ = X.shape
        ffi, lib = self.ffi, self.lib
        inst = ffi.new("stsp_param_t[]", paths)
        st = lib.harness_param_init(inst, paths)
        if st < 0:
            raise RuntimeError(f"stsp_param_init failed: {self.status_str(st)}")
        U = np.zeros((T, paths, self.table.dims[1]), dtype)
        ctype = "float[]" if dtype == np.float32 else f"{np.dtype(dtype).name}_t[]"
        worst = 0
        for j in range(T):
            if j in thetas:
                _set(self, inst, paths, thetas[j])
            x = np.ascontiguousarray(X[j], dtype)
            worst = min(worst, int(lib.harness_param_step(
                inst, paths, j, ffi.from_buffer(ctype, x), ffi.from_buffer(ctype, U[j]))))
        return U, worst


@dataclass
class ParamsRun:
    """Each path's realised cost (paths,), its states at the knots (knot: (paths, n)) and the
    worst status the controller returned."""
    cost: np.ndarray
    knots: list
    worst_status: int

    def agreement(self, J: float | None, knot_means, confidence: float = 0.99, *,
                  allowance=None, exact_se=None):
        """`joint_verdict` of the cost and every knot-mean component against exact values,
        z-scores from the sample's own standard errors (Bonferroni over all of them), or with
        `exact_se` (`oracle.tails.TailMoments` of the loop run, e.g.
        `oracle.parametric.tails_at`) from its exact ones, which the heavy tails of
        multiplicative noise do not make too small. With
        `allowance` (per knot, (n,): a bound on how far the run's expected state may be from
        the exact values, e.g. a fixed-point error bound propagated,
        `stospline.oracle.fixed_point_margin`), a difference within it counts as none and one
        beyond it by the excess only. ``J=None`` leaves the cost out."""
        N = len(self.cost)

        def z(sample, exact, allow=0.0, se=None):
            if se is None or np.all(sample == sample[0]):
                se = sample.std(ddof=1) / np.sqrt(sample.size)
            diff = sample.mean() - exact
            excess = np.sign(diff) * max(0.0, abs(diff) - allow)
            return (None if se == 0 else float(excess / se), float(sample.mean()),
                    float(exact))
        stats = [] if J is None else [("cost", *z(
            self.cost, J, se=None if exact_se is None else exact_se.cost_mean_se(N)))]
        allowance = allowance if allowance is not None else [np.zeros(len(m)) for m in knot_means]
        for k, (X, mean, allow) in enumerate(zip(self.knots, knot_means, allowance)):
            se = [None] * X.shape[1] if exact_se is None else exact_se.knot_mean_se(k, N)
            stats += [(f"knot {k} mean[{i}]", *z(X[:, i], mean[i], allow[i], se[i]))
                      for i in range(X.shape[1])]
        return joint_verdict(stats, confidence)


def build_params_controller(ptable, table, *, build_dir=None,
                            quiet: bool = True) -> ParamsController:
    """Compile the firmware with `table`'s (the float32 gain table) and `ptable`'s
    (`stospline.table.parametric.ParametricTable`) generated C, cached by a hash of every
    input as `harness.controller.build_controller`."""
    name = table.name
    header, source = generate_c(table)
    ph, pc = generate_parametric_c(ptable, prefix=name)
    files = {f"{name}.h": header, f"{name}.c": source, f"{name}_params.h": ph,
             f"{name}_params.c": pc}
    return _build(files, name, table, "float32", build_dir, quiet)


def build_params_qcontroller(ptable, pf, *, build_dir=None,
                             quiet: bool = True) -> ParamsController:
    """Compile the Q15/Q31 firmware with the fixed-point parametric table `pf`
    (`stospline.table.qparams.quantize_parametric` of `ptable`): its gain table and columns
    (`stospline.table.parametric_c.generate_parametric_qc`), cached as
    `build_params_controller`. Its ``table`` is the gain table."""
    ft = pf.augmented
    name = f"{ptable.table.name}_{ft.arith}"
    return _build(generate_parametric_qc(ptable, pf, prefix=name), name, pf.gain_table(name),
                  ft.arith, build_dir, quiet)


def build_params_qspline_controller(ptable, pf, gains, cols, *, build_dir=None,
                                    quiet: bool = True) -> ParamsController:
    """`build_params_qcontroller` of the Q15/Q31 spline parametric controller
    (`stospline.table.spline.qparams.quantize_spline_parametric` of `ptable`: `pf`, the gain
    spline `gains` and the spline columns `cols`, format 2). Its ``table`` is the Q spline
    gain table."""
    from stospline.table.spline.qparams import spline_gain_table
    ft = pf.augmented
    name = f"{ptable.table.name}_{ft.arith}_spline"
    files = generate_parametric_qc(ptable, pf, prefix=name, spline=(gains, cols))
    return _build(files, name, spline_gain_table(pf, gains, name), ft.arith, build_dir, quiet)


def _build(files: dict, name: str, table, arith: str, build_dir, quiet) -> ParamsController:
    n, m, _ = table.dims
    scalar, _, defs = VARIANTS[arith]
    mod = build_harness_module(f"_stsp_par_{name}", files, _CDEF % {"s": scalar},
                               _BATCH % {"p": name, "P": name.upper(), "s": scalar},
                               [*defs, f"-DHARNESS_N={n}", f"-DHARNESS_M={m}"],
                               build_dir=build_dir, quiet=quiet)
    return ParamsController(mod.ffi, mod.lib, table)


def simulate_params(problem, ctl: ParamsController, theta, *, paths: int, seed: int,
                    substeps: int = 4, change=None, observe=None) -> ParamsRun:
    """`paths` paths from the problem's x0 with the parameters `theta` set before tick 0 and,
    with ``change=(stage, theta2)``, `theta2` set just before that stage's first tick (with
    ``change=(stage, theta2, tick)``, just before that tick of the stage). Each stage's plant
    and each knot's penalty are the problem's at `theta`, from the changed stage on at
    `theta2` (`problem_at`; as `stospline.oracle.parametric.evaluate_switched`); the
    plant's noise from the harness's C generator (seeded); constant stage data. A Q15/Q31
    controller (`build_params_qcontroller`) reads each state rounded to its Q format and its
    integer commands reach the plant times their LSB (`controller.q_io`). `observe`, optional, is called with ``(tick, X)`` after each tick (X: the states
    at the tick's end, (paths, n); the callback must not keep it)."""
    table = ctl.table
    n, m, _ = table.dims
    dt = 1.0 / table.tick_hz / substeps
    helpers = ctl.plant_helpers
    normals = helpers.normals(np.random.SeedSequence(seed))
    ffi, lib = ctl.ffi, ctl.lib
    inst = ffi.new("stsp_param_t[]", paths)
    st = lib.harness_param_init(inst, paths)
    if st < 0:
        raise RuntimeError(f"stsp_param_init failed: {ctl.status_str(st)}")
    X = np.ascontiguousarray(np.tile(problem.x0, (paths, 1)), dtype=float)
    arith = helpers.arith
    dtype = helpers.dtype
    Xs = np.zeros((paths, n), dtype)             # the states the controller reads
    Us = np.zeros((paths, m), dtype)             # and its commands, in the build's scalar
    U = Us if arith == "float32" else np.zeros((paths, m), np.float32)
    ctype = f"{VARIANTS[arith][0]}[]"
    px, pu = ffi.from_buffer(ctype, Xs), ffi.from_buffer(ctype, Us)
    to_q, to_real = (None, None) if arith == "float32" else q_io(table)
    cost = np.zeros(paths)
    knots, worst = [], 0
    first, later = problem_at(problem, theta), None
    if change is not None:
        later = problem_at(problem, change[1])
        at_tick = int(table.stage_start[change[0]]) if len(change) < 3 else int(change[2])
        if not table.stage_start[change[0]] <= at_tick < table.stage_start[change[0] + 1]:
            raise ValueError(f"simulate_params: tick {at_tick} is not in stage {change[0]}")
    for k in range(table.n_stages):
        p = later if change is not None and k >= change[0] else first
        if k == 0:
            _set(ctl, inst, paths, theta)
        stage = p.stages[k]
        if stage.varying is not None:
            raise ValueError("simulate_params: time-varying plant data are not simulated")
        plant = helpers.plant(stage, *zoh_step(stage, dt), dt, substeps)
        dZ = np.empty((paths, substeps, stage.G.shape[2]))
        fill = normals(dZ)
        for j in range(int(table.stage_start[k]), int(table.stage_start[k + 1])):
            if change is not None and j == at_tick:
                _set(ctl, inst, paths, change[1])
            Xs[...] = X if to_q is None else to_q(X)
            worst = min(worst, int(lib.harness_param_step(inst, paths, j, px, pu)))
            if to_real is not None:
                U[...] = to_real(Us)
            fill()
            helpers.plant_tick(plant, dZ, U, X, cost)
            if observe is not None:
                observe(j + 1, X)
        knot = p.knots[k]
        if knot.penalty is not None:
            r = X @ knot.penalty.C.T - knot.penalty.target
            cost += knot.penalty.weight * np.einsum("pi,pi->p", r, r)
        knots.append(X.copy())
    return ParamsRun(cost, knots, worst)


def _set(ctl: ParamsController, inst, paths: int, theta) -> None:
    st = ctl.lib.harness_param_set(inst, paths, ctl.ffi.from_buffer(
        "float[]", np.ascontiguousarray(theta, np.float32)))
    if st < 0:
        raise ValueError(f"stsp_set_params refused {list(theta)}: {ctl.status_str(st)}")
