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
from stospline.estimator.oracle import estimator_faults_unsupported
from stospline.firmware_interface import STATUS
from stospline.harness.build import PLANT_CDEF, build_harness_module
from stospline.harness.controller import CompiledController
from stospline.errors import ProblemError
from stospline.harness.loop_state import CorridorWatch
from stospline.harness.montecarlo import MonteCarloResult
from stospline.harness.montecarlo import _plant_tick as plant_tick
from stospline.harness.plant_spec import zoh_step
from stospline.harness.path_stats import COST_SAMPLE, CorridorExits, Moments
from stospline.table.codegen import generate_c

__all__ = ["build_estimator_controller", "EstimatorController", "simulate_estimator",
           "build_estimator_q"]

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
                     int *status, const unsigned char *run);
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
    stsp_status_t st = %(init)s;
    for (i = 1; i < count; ++i) e[i] = e[0];
    return (int)st;
}
/* Y (count x ny) or NULL (no reading this tick); U (count x nu); status per path; run NULL
 * (every path) or per path 0 for a missed tick: not stepped, U and status left as they are. */
int harness_est_step(stsp_est_t *e, size_t count, uint32_t tick, const float *Y, float *U,
                     int *status, const unsigned char *run) {
    size_t i;
    int worst = 0;
    for (i = 0; i < count; ++i) {
        const float *y = (Y == NULL) ? NULL : &Y[i * %(P)s_NY];
        stsp_status_t st;
        if (run != NULL && run[i] == 0u) continue;
        st = stsp_est_step(&e[i], tick, y, &U[i * %(P)s_NU]);
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
        """``step(tick, Y, run=None) -> (U, status)`` over `count` fresh instances; Y (count,
        ny) float32 or None (no reading); `run` (count,) bool or None (every path): a path
        with False misses the tick (not stepped; U keeps its last command, u_hold at first,
        and its status is 0)."""
        ffi, lib = self.ffi, self.lib
        inst = ffi.new("stsp_est_t[]", count)
        st = lib.harness_est_init(inst, count)
        if st < 0:
            raise RuntimeError(f"stsp_est_init failed: {self.status_str(st)}")
        m = self.table.dims[1]
        U = np.tile(np.asarray(self.table.u_hold, np.float32), (count, 1))
        S = np.zeros(count, np.intc)
        pu, ps = ffi.from_buffer("float[]", U), ffi.from_buffer("int[]", S)

        def step(tick: int, Y, run=None):
            py = ffi.NULL if Y is None else ffi.from_buffer(
                "float[]", np.ascontiguousarray(Y, np.float32))
            pr = ffi.NULL
            if run is not None:
                S[:] = 0
                pr = ffi.from_buffer("unsigned char[]", np.ascontiguousarray(run, np.uint8))
            lib.harness_est_step(inst, count, tick, py, pu, ps, pr)
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
    input, as `harness.controller.build_controller`); an `est` with a gain spline
    (`estimator.ctable.SplineEstimatorTable`) is bound by ``stsp_est_init_spline``."""
    name = table.name
    header, source = generate_c(table)
    eh, ec = estimator_c(est, name)
    body, guard = header.rsplit("#endif", 1)
    header, source = body + eh + "\n#endif" + guard, source + ec
    n, m, _ = table.dims
    init = (f"stsp_est_init_spline(&e[0], &{name}_table, &{name}_estimator, "
            f"&{name}_est_gain_spline)" if getattr(est, "gain_spline", None) is not None else
            f"stsp_est_init(&e[0], &{name}_table, &{name}_estimator)")
    mod = build_harness_module(f"_stsp_est_{name}", {f"{name}.h": header, f"{name}.c": source},
                               _CDEF, _BATCH % {"p": name, "P": name.upper(), "init": init},
                               [f"-DHARNESS_N={n}", f"-DHARNESS_M={m}"], build_dir=build_dir,
                               quiet=quiet)
    return EstimatorController(mod.ffi, mod.lib, table, est)


def simulate_estimator(problem, ctl: EstimatorController, *, paths: int, seed: int,
                       substeps: int = 4, record: int = 0) -> tuple[MonteCarloResult, dict]:
    """`paths` paths of the loop: the start drawn from ``N(x0, x0_cov)``, the sensor's noise
    from numpy (seeded), the plant's from the harness's C generator. Time-varying stage data
    are frozen at each plant step's midpoint (as `harness.montecarlo` runs them); a
    time-varying ``V`` is taken at each sampling tick's time.

    The faults of ``problem.faults`` that `estimator.oracle.estimator_faults_unsupported`
    accepts compose with the sensor (docs/theory/estimator.md, "Faults"): ``sensor_noise``
    (per state) is noise on the state the sensor reads, ``y = C (x + nu) + r``;
    ``actuator_noise`` is added to the command the plant receives (the filter predicts with
    the command it wrote); model mismatch changes the plant, not the filter's predictor; a
    missed tick (``miss_probability``, per path and tick) does not step the path's
    controller, whose command the plant keeps holding.

    Returns the Monte Carlo result (cost, knot states, one path, the mean path, saturation)
    and ``{"x": (ticks + 1, record, n), "xhat": (ticks + 1, record, n), "u": (ticks, record,
    m), "knot_error": [Moments]}``: for the first `record` paths the true state at each tick,
    the controller's prediction of it (before that tick's update; after missed ticks, carried
    over them as the controller's next step will) and the commands; over all
    paths the moments of the estimation error ``x - x̂`` at each knot (x̂ the prediction the
    controller holds for the knot's tick), and ``"x_sum"`` (ticks + 1, n), the states summed
    over the paths at every tick (for merging blocks, `harness.sensor_blocks`). With corridors, the result's ``exits`` are each
    path's first exit of the *true* state, by tick and wall, as `montecarlo.simulate` counts
    them (`loop_state.CorridorWatch`)."""
    table, meas = ctl.table, problem.measurement
    n, m, _ = table.dims
    h = 1.0 / table.tick_hz
    dt = h / substeps
    faults = problem.faults
    why = estimator_faults_unsupported(faults)
    if why:
        raise ProblemError(*why)
    plant_of = faults.plant_of(problem)
    ss = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    plant_seed, sensor_seed, fault_seed = ss.spawn(3)  # the first two as without faults
    rng = np.random.default_rng(sensor_seed)
    fault_rng = np.random.default_rng(fault_seed)
    sig_x = faults.sensor_noise if np.any(faults.sensor_noise) else None
    sig_u = faults.actuator_noise if np.any(faults.actuator_noise) else None
    miss = float(faults.miss_probability)
    helpers = ctl.plant_helpers
    normals = helpers.normals(plant_seed)
    X = np.tile(problem.x0, (paths, 1)).astype(float)
    S0 = meas.prior_cov(n)
    if S0.any():
        w, Q = np.linalg.eigh(S0)
        X += rng.standard_normal((paths, n)) @ (Q * np.sqrt(np.maximum(w, 0.0))).T
    X = np.ascontiguousarray(X)
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
    next_tick = np.zeros(paths, np.int64)     # each path's controller: its next tick
    pred = ctl.est.per_tick()[1] if miss else None

    def estimate(tick: int) -> np.ndarray:
        """Each path's prediction for `tick`: the controller's, carried over the ticks it
        missed with its held command as its next step will (the firmware's maps)."""
        xh = step.xhat()
        if pred is None:
            return xh
        xh = xh.astype(float)
        for t in range(int(next_tick.min()), tick):
            late = next_tick <= t
            P = pred[t]
            xh[late] = xh[late] @ P[:, :n].T + U[late] @ P[:, n:n + m].T + P[:, -1]
        return xh
    watch = (CorridorWatch.of(problem.corridors, paths, problem.t0, table.tick_hz)
             if problem.corridors else None)
    if watch is not None:
        watch.check(0, X)
    for k in range(table.n_stages):
        st = plant_of.stages[k]
        plant = None if st.varying is not None else helpers.plant(st, *zoh_step(st, dt), dt,
                                                                  substeps)
        dZ = np.empty((paths, substeps, st.G.shape[2]))
        fill = normals(dZ)
        for j in range(int(table.stage_start[k]), int(table.stage_start[k + 1])):
            Y = None
            if meas.samples_at(j):
                sqV = _sqrt_psd(meas.V_at(problem.t0 + j * h))
                Y = X @ meas.C.T + rng.standard_normal((paths, meas.p)) @ sqV.T
                if D is not None:
                    nu = rng.standard_normal((paths, D.shape[2]))
                    Y += np.einsum("Pa,apk,Pk->Pp", X, D, nu)
                if sig_x is not None:
                    Y += (fault_rng.standard_normal((paths, n)) * sig_x) @ meas.C.T
                Y = Y.astype(np.float32)
            ran = None if not miss else fault_rng.random(paths) >= miss
            U, status = step(j, Y, ran)
            if ran is not None:
                next_tick[ran] = j + 1
            worst = min(worst, int(status.min()))
            saturated += status == STATUS["WARN_SATURATED"]
            u_low, u_high = np.minimum(u_low, U.min(axis=0)), np.maximum(u_high, U.max(axis=0))
            fill()
            applied = U
            if sig_u is not None:
                applied = np.ascontiguousarray(
                    (U + fault_rng.standard_normal((paths, m)) * sig_u).astype(np.float32))
            plant_tick(helpers, problem, plant, st, j, h, dt, substeps, dZ, applied, X, cost)
            if watch is not None:
                watch.check(j + 1, X)
            x_sum[j + 1] = X.sum(axis=0)
            sample_x[j + 1], sample_u[j] = X[0], U[0]
            rec["x"][j + 1], rec["u"][j] = X[:record], U[:record]
            if record:
                rec["xhat"][j + 1] = estimate(j + 1)[:record]
        knot = problem.knots[k]
        if knot.penalty is not None:
            r = X @ knot.penalty.C.T - knot.penalty.target
            cost += knot.penalty.weight * np.einsum("pi,pi->p", r, r)
        knots.append(Moments.of(X))
        knot_error.append(Moments.of(X - estimate(int(table.stage_start[k + 1]))))
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
    rec["x_sum"] = x_sum          # the states summed over the paths at every tick (exact sums)
    return mc, rec


def _sqrt_psd(V: np.ndarray) -> np.ndarray:
    """``S`` with ``S S' = V`` for a positive semidefinite `V`."""
    w, Q = np.linalg.eigh(V)
    return Q * np.sqrt(np.maximum(w, 0.0))


_QCDEF = """
typedef struct { ...; } stsp_est_t;
uint32_t harness_q_crc(int stored);
int harness_q_init(stsp_est_t *e, size_t count);
int harness_q_step(stsp_est_t *e, size_t count, uint32_t tick, const int32_t *Y, int32_t *U,
                   int *status, int32_t *xhat);
"""

# Harness-only C of a Q15/Q31 estimator controller: readings, commands and each path's
# prediction as int32 whatever the format (a Q15 value is an int16 widened).
_QBATCH = """
#include "plant.h"
#include "stospline/stsp_estimator.h"
#include "%(p)s.h"
uint32_t harness_q_crc(int stored) {
    return stored ? %(p)s_estimator.crc32 : stsp_est_table_crc32(&%(p)s_estimator);
}
int harness_q_init(stsp_est_t *e, size_t count) {
    size_t i;
    stsp_status_t st = stsp_est_init(&e[0], &%(p)s_table, &%(p)s_estimator);
    for (i = 1; i < count; ++i) e[i] = e[0];
    return (int)st;
}
int harness_q_step(stsp_est_t *e, size_t count, uint32_t tick, const int32_t *Y, int32_t *U,
                   int *status, int32_t *xhat) {
    size_t i, j;
    int worst = 0;
    for (i = 0; i < count; ++i) {
        stsp_scalar_t y[%(P)s_NY], u[%(P)s_NU];
        stsp_status_t st;
        for (j = 0; Y != NULL && j < %(P)s_NY; ++j) y[j] = (stsp_scalar_t)Y[i * %(P)s_NY + j];
        st = stsp_est_step(&e[i], tick, (Y == NULL) ? NULL : y, u);
        for (j = 0; j < %(P)s_NU; ++j) U[i * %(P)s_NU + j] = u[j];
        for (j = 0; j < %(P)s_NX; ++j) xhat[i * %(P)s_NX + j] = e[i].xhat[j];
        status[i] = (int)st;
        if ((int)st < worst) worst = (int)st;
    }
    return worst;
}
"""


def build_estimator_q(ft, qt, *, build_dir=None, quiet: bool = True):
    """Compile the Q15/Q31 estimator controller of the law `ft` (`FixedPointTable`) and the
    filter `qt` (`estimator.qformat.QEstimatorTable`); returns ``(ffi, lib)`` with
    ``harness_q_crc``, ``harness_q_init`` and ``harness_q_step`` (int32 readings, commands
    and predictions)."""
    from stospline.estimator.qformat import estimator_q_c
    from stospline.harness.controller_c import VARIANTS
    name = ft.name
    header, source = generate_c(ft)
    eh, ec = estimator_q_c(qt, name)
    body, guard = header.rsplit("#endif", 1)
    header, source = body + eh + "\n#endif" + guard, source + ec
    n, m, _ = ft.dims
    mod = build_harness_module(f"_stsp_estq_{name}", {f"{name}.h": header, f"{name}.c": source},
                               PLANT_CDEF + _QCDEF, _QBATCH % {"p": name, "P": name.upper()},
                               VARIANTS[ft.arith][2] + [f"-DHARNESS_N={n}", f"-DHARNESS_M={m}"],
                               build_dir=build_dir, quiet=quiet)
    return mod.ffi, mod.lib
