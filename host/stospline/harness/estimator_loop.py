"""Monte Carlo of the loop on a sensor through the compiled C: the plant (the harness's
exponential Euler-Maruyama integrator, plant.c) emits ``y = C x + noise`` every `every` ticks
(additive ``V`` and the state-proportional ``D`` terms of `problem.measurement`), and the
firmware's ``stsp_est_step`` (stsp_estimator.h) turns it into the command the plant holds.

Build and run are separate steps: `build_estimator_controller` compiles ``firmware/src/*.c``
with the generated gain and estimator tables; `simulate_estimator` runs paths through it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stospline.estimator.ctable import EstimatorTable, estimator_c
from stospline.firmware_interface import STATUS
from stospline.harness.build import PLANT_CDEF, build_harness_module
from stospline.harness.controller import CompiledController
from stospline.harness.loop_state import CorridorWatch
from stospline.harness.montecarlo import MonteCarloResult
from stospline.harness.plant_spec import zoh_step
from stospline.harness.path_stats import COST_SAMPLE, CorridorExits, Moments
from stospline.table.codegen import generate_c

__all__ = ["build_estimator_controller", "EstimatorController", "simulate_estimator"]

_CDEF = PLANT_CDEF + """
typedef int... stsp_status_t;
typedef struct { ...; } stsp_table_t;
typedef struct { uint32_t crc32; ...; } stsp_est_table_t;
typedef struct { ...; } stsp_est_t;
uint32_t stsp_est_table_crc32(const stsp_est_table_t *est);
const char *stsp_status_str(stsp_status_t status);
const stsp_est_table_t *harness_est_table(void);
int harness_est_init(stsp_est_t *e, size_t count);
int harness_est_step(stsp_est_t *e, size_t count, uint32_t tick, const float *Y, float *U,
                     int *status);
void harness_est_xhat(const stsp_est_t *e, size_t count, float *out);
"""

# Harness-only C: every path's estimator controller in one call. Init validates instance 0
# (the CRC of both tables) and copies it: the instances hold no pointer into themselves.
_BATCH = """
#include "plant.h"
#include "stospline/stsp_estimator.h"
#include "%(p)s.h"
const stsp_est_table_t *harness_est_table(void) { return &%(p)s_estimator; }
int harness_est_init(stsp_est_t *e, size_t count) {
    size_t i;
    stsp_status_t st = stsp_est_init(&e[0], &%(p)s_table, &%(p)s_estimator);
    for (i = 1; i < count; ++i) e[i] = e[0];
    return (int)st;
}
/* Y (count x ny) or NULL (no reading this tick); U (count x nu); status per path. */
int harness_est_step(stsp_est_t *e, size_t count, uint32_t tick, const float *Y, float *U,
                     int *status) {
    size_t i;
    int worst = 0;
    for (i = 0; i < count; ++i) {
        const float *y = (Y == NULL) ? NULL : &Y[i * %(P)s_NY];
        const stsp_status_t st = stsp_est_step(&e[i], tick, y, &U[i * %(P)s_NU]);
        status[i] = (int)st;
        if ((int)st < worst) worst = (int)st;
    }
    return worst;
}
/* Each path's prediction x̂ for its next tick (count x nx). */
void harness_est_xhat(const stsp_est_t *e, size_t count, float *out) {
    size_t i, j;
    for (i = 0; i < count; ++i)
        for (j = 0; j < %(P)s_NX; ++j) out[i * %(P)s_NX + j] = e[i].xhat[j];
}
"""


@dataclass
class EstimatorController:
    """The compiled estimator controller: `plant` and `normals` as `CompiledController`'s."""
    ffi: object
    lib: object
    table: object
    est: EstimatorTable

    @property
    def plant_helpers(self) -> CompiledController:
        return CompiledController(self.ffi, self.lib, self.table)

    def status_str(self, status: int) -> str:
        return self.ffi.string(self.lib.stsp_status_str(status)).decode()

    def stepper(self, count: int):
        """``step(tick, Y) -> (U, status)`` over `count` fresh instances; Y (count, ny)
        float32 or None (no reading)."""
        ffi, lib = self.ffi, self.lib
        inst = ffi.new("stsp_est_t[]", count)
        st = lib.harness_est_init(inst, count)
        if st < 0:
            raise RuntimeError(f"stsp_est_init failed: {self.status_str(st)}")
        m = self.table.dims[1]
        U = np.zeros((count, m), np.float32)
        S = np.zeros(count, np.intc)
        pu, ps = ffi.from_buffer("float[]", U), ffi.from_buffer("int[]", S)

        def step(tick: int, Y):
            py = ffi.NULL if Y is None else ffi.from_buffer(
                "float[]", np.ascontiguousarray(Y, np.float32))
            lib.harness_est_step(inst, count, tick, py, pu, ps)
            return U, S

        n = self.table.dims[0]
        xh = np.zeros((count, n), np.float32)
        pxh = ffi.from_buffer("float[]", xh)

        def xhat():
            """Each path's prediction for its next tick, (count, n) float32."""
            lib.harness_est_xhat(inst, count, pxh)
            return xh

        step.instances, step.xhat = inst, xhat
        return step


def build_estimator_controller(problem, table, est: EstimatorTable, *, build_dir=None,
                               quiet: bool = True) -> EstimatorController:
    """Compile the firmware with `table`'s and `est`'s generated C (cached by a hash of every
    input, as `harness.controller.build_controller`)."""
    name = table.name
    header, source = generate_c(table)
    eh, ec = estimator_c(est, name)
    body, guard = header.rsplit("#endif", 1)
    header, source = body + eh + "\n#endif" + guard, source + ec
    n, m, _ = table.dims
    mod = build_harness_module(f"_stsp_est_{name}", {f"{name}.h": header, f"{name}.c": source},
                               _CDEF, _BATCH % {"p": name, "P": name.upper()},
                               [f"-DHARNESS_N={n}", f"-DHARNESS_M={m}"], build_dir=build_dir,
                               quiet=quiet)
    return EstimatorController(mod.ffi, mod.lib, table, est)


def simulate_estimator(problem, ctl: EstimatorController, *, paths: int, seed: int,
                       substeps: int = 4, record: int = 0) -> tuple[MonteCarloResult, dict]:
    """`paths` paths of the loop: the start drawn from ``N(x0, x0_cov)``, the sensor's noise
    from numpy (seeded), the plant's from the harness's C generator; constant stage data.

    Returns the Monte Carlo result (cost, knot states, one path, the mean path, saturation)
    and ``{"x": (ticks + 1, record, n), "xhat": (ticks + 1, record, n), "u": (ticks, record,
    m), "knot_error": [Moments]}``: for the first `record` paths the true state at each tick,
    the controller's prediction of it (before that tick's update) and the commands; over all
    paths the moments of the estimation error ``x - x̂`` at each knot (x̂ the prediction the
    controller holds for the knot's tick). With corridors, the result's ``exits`` are each
    path's first exit of the *true* state, by tick and wall, as `montecarlo.simulate` counts
    them (`loop_state.CorridorWatch`)."""
    table, meas = ctl.table, problem.measurement
    n, m, _ = table.dims
    h = 1.0 / table.tick_hz
    dt = h / substeps
    ss = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    plant_seed, sensor_seed = ss.spawn(2)
    rng = np.random.default_rng(sensor_seed)
    helpers = ctl.plant_helpers
    normals = helpers.normals(plant_seed)
    X = np.tile(problem.x0, (paths, 1)).astype(float)
    S0 = meas.prior_cov(n)
    if S0.any():
        w, Q = np.linalg.eigh(S0)
        X += rng.standard_normal((paths, n)) @ (Q * np.sqrt(np.maximum(w, 0.0))).T
    X = np.ascontiguousarray(X)
    wv, Qv = np.linalg.eigh(meas.V)
    sqV = Qv * np.sqrt(np.maximum(wv, 0.0))
    D = meas.D if meas.D.size and meas.D.any() else None
    step = ctl.stepper(paths)
    cost = np.zeros(paths)
    knots, knot_error, worst = [], [], 0
    saturated = np.zeros(paths, np.int64)
    u_low, u_high = np.full(m, np.inf), np.full(m, -np.inf)
    x_sum = np.empty((table.n_ticks + 1, n))
    x_sum[0] = X.sum(axis=0)
    sample_x = np.empty((table.n_ticks + 1, n))
    sample_x[0] = X[0]
    sample_u = np.empty((table.n_ticks, m))
    record = min(record, paths)            # fewer paths than asked to record: record them all
    rec = {"x": np.empty((table.n_ticks + 1, record, n)),
           "u": np.empty((table.n_ticks, record, m), np.float32)}
    rec["xhat"] = np.empty((table.n_ticks + 1, record, n), np.float32)
    rec["x"][0], rec["xhat"][0] = X[:record], step.xhat()[:record]
    watch = (CorridorWatch.of(problem.corridors, paths, problem.t0, table.tick_hz)
             if problem.corridors else None)
    if watch is not None:
        watch.check(0, X)
    for k in range(table.n_stages):
        st = problem.stages[k]
        if st.varying is not None:
            raise ValueError("simulate_estimator: time-varying plant data are not simulated")
        plant = helpers.plant(st, *zoh_step(st, dt), dt, substeps)
        dZ = np.empty((paths, substeps, st.G.shape[2]))
        fill = normals(dZ)
        for j in range(int(table.stage_start[k]), int(table.stage_start[k + 1])):
            Y = None
            if meas.samples_at(j):
                Y = X @ meas.C.T + rng.standard_normal((paths, meas.p)) @ sqV.T
                if D is not None:
                    nu = rng.standard_normal((paths, D.shape[2]))
                    Y += np.einsum("Pa,apk,Pk->Pp", X, D, nu)
                Y = Y.astype(np.float32)
            U, status = step(j, Y)
            worst = min(worst, int(status.min()))
            saturated += status == STATUS["WARN_SATURATED"]
            u_low, u_high = np.minimum(u_low, U.min(axis=0)), np.maximum(u_high, U.max(axis=0))
            fill()
            helpers.plant_tick(plant, dZ, U, X, cost)
            if watch is not None:
                watch.check(j + 1, X)
            x_sum[j + 1] = X.sum(axis=0)
            sample_x[j + 1], sample_u[j] = X[0], U[0]
            rec["x"][j + 1], rec["u"][j] = X[:record], U[:record]
            if record:
                rec["xhat"][j + 1] = step.xhat()[:record]
        knot = problem.knots[k]
        if knot.penalty is not None:
            r = X @ knot.penalty.C.T - knot.penalty.target
            cost += knot.penalty.weight * np.einsum("pi,pi->p", r, r)
        knots.append(Moments.of(X))
        knot_error.append(Moments.of(X - step.xhat()))
    t = problem.t0 + h * np.arange(table.n_ticks + 1)
    mc = MonteCarloResult(paths, Moments.of(cost), knots, t, sample_x, sample_u, x_sum / paths,
                          worst, int(saturated.sum()), int(np.count_nonzero(saturated)),
                          u_low, u_high, substeps, record_x=rec["x"].astype(np.float32),
                          record_u=rec["u"], cost_sample=cost[:COST_SAMPLE].copy())
    if watch is not None:
        mc.exits = CorridorExits.of(watch.exit_tick, watch.exit_wall,
                                    [len(c.wall_names()) for c in problem.corridors],
                                    table.n_ticks)
    rec["knot_error"] = knot_error
    return mc, rec
