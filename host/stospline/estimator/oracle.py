"""The filter's gains and the exact moments of the loop it closes, in one forward pass.

The controller runs the table's law on the estimate ``x̂`` of a linear filter fed by the
sensor of ``problem.measurement`` (docs/theory/estimator.md). At tick j, with ``x̂`` the
prediction from the tick before:

    update   x̂+ = x̂ + Lf_j (y_j - C x̂)                  (only at a sampling tick)
    latch    v   = Lambda x̂+ + lambda0                   (a stage's first tick)
    command  u   = -K x̂+ - L v - k0                      held over the tick
    predict  x̂'  = Ad x̂+ + Bd u + fd                     (the plant's mean map over the tick)

Between ticks the loop's state is ``z = [x; x̂; v; 1]``; everything above is a linear map of
``z`` and the sensor noise ``r = y - C x``, which is uncorrelated with ``z`` and has ``E rr' =
V + sum_ab E[x_a x_b] D_a D_b'``. So ``E zz'`` follows an exact linear recursion (the plant's
one-tick moment map on ``w = [x; u; 1]``, the passengers ``[x̂'; v]`` by the mean map, as in
`oracle.faults`), and the gain ``Lf_j = P C' (C P C' + R)^+`` that minimises the error
covariance is computed from the same moments (``P = E (x - x̂)(x - x̂)'``, ``R`` above) before
they move on.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from stospline.errors import ProblemError
from stospline.estimator.filter_kernel import filter_gains
from stospline.estimator.gain import lmmse_gain
from stospline.problem.faults import Faults
from stospline.problem.model import Problem
from stospline.oracle.tick_moments import Moments, _knot_terms, _PathRecord, _StagePlant, _w_map
from stospline.table.format import GainTable

__all__ = ["EstimatorLoop", "evaluate_estimator", "estimator_faults_unsupported"]


@dataclass
class EstimatorLoop:
    """The filter of a loop and the loop's exact moments.

    ``gain[j]`` (n x p) is the update gain at tick j (zero where the sensor does not sample),
    ``predict[j]`` the mean map ``[Ad, Bd, fd]`` (n x (n + m + 1)) of tick j, ``x0`` and
    ``x0_cov`` the filter's start. ``error_cov[j]`` is the covariance of ``x - x̂+`` after the
    update of tick j, ``prior_error_cov[j]`` before it (the prediction the controller holds
    when tick j starts); ``knot_error_cov[k]`` that of ``x - x̂`` at knot k (the prediction).
    ``moments`` are the cost, knot means and covariances of the true state ``x``.
    ``innovation_cov[j]`` is ``E ee'`` of the innovation ``e = y - C x̂`` at tick j (zero where
    the sensor does not sample; its mean is zero), ``output_cov[j]`` the second moment
    ``E yy'`` of the reading, ``estimate_ms[j]`` the largest of ``E x̂_i^2`` before and after
    tick j's update: what the fixed-point scales of `estimator.qformat` need.
    """
    moments: Moments
    gain: np.ndarray
    predict: np.ndarray
    error_cov: np.ndarray
    knot_error_cov: list[np.ndarray] = field(default_factory=list)
    knot_estimate_mean: list[np.ndarray] = field(default_factory=list)
    prior_error_cov: np.ndarray | None = None
    innovation_cov: np.ndarray | None = None
    output_cov: np.ndarray | None = None
    estimate_ms: np.ndarray | None = None


def _check(problem: Problem, table: GainTable, meas) -> None:
    if meas is None:
        raise ValueError("evaluate_estimator: the problem has no [measurement] table")
    if getattr(table, "delay_ticks", 0):
        raise ValueError("evaluate_estimator: a table designed for a one-tick delay is not "
                         "evaluated with an estimator")
    if table.band_qp is not None:
        raise ValueError("evaluate_estimator: the band latch solves a QP from the estimate, "
                         "which is not linear")
    n = problem.n
    if table.dims[0] != n or meas.C.shape[1] != n:
        raise ValueError(f"evaluate_estimator: the table has {table.dims[0]} states, the "
                         f"sensor {meas.C.shape[1]}, the problem {n}")


def estimator_faults_unsupported(faults: Faults) -> tuple[str, str] | None:
    """``(field, reason)`` for a fault that the loop on a sensor does not run, else None.

    Sensor noise, actuator noise, missed ticks and model mismatch compose with the filter
    (docs/theory/estimator.md, "Faults"); a computation delay and the sensor quantizer are
    refused."""
    why = "with a [measurement] sensor the loop"
    if faults.delay_ticks:
        return "faults.delay_ticks", f"{why} has no estimator form for a one-tick delay"
    if np.any(faults.sensor_quantum):
        return "faults.sensor_quantum", (f"{why} does not quantize the reading (nonlinear; "
                                         f"give the converter's step as measurement.V)")
    return None


def evaluate_estimator(problem: Problem, table: GainTable, measurement=None, *,
                       propagator: str = "exact", substeps: int = 4,
                       path: bool = False, gains: np.ndarray | None = None,
                       predictor: np.ndarray | None = None,
                       faults: Faults | None = None,
                       output: np.ndarray | None = None) -> EstimatorLoop:
    """Filter gains and exact moments of `table`'s law run on the filter's estimate.

    Parameters
    ----------
    problem : Problem
        The plant, cost, knots and prior mean ``x0``.
    table : GainTable
        The law (per-tick gains and latch maps), as the firmware runs it.
    measurement : Measurement, optional
        The sensor; default ``problem.measurement``.
    propagator, substeps
        As in `oracle.evaluate.evaluate_table` ("euler": the Monte Carlo plant scheme's moments).
    path : bool
        Also keep the true state's mean and variance at every tick.
    gains, predictor : ndarray, optional
        The filter as implemented (`estimator.ctable.EstimatorTable.per_tick`: float32 gains
        and predictor maps, per tick): the loop's exact moments with these in place of the
        LMMSE gains and the plant's exact mean map. A predictor that is not the plant's mean
        map (rounded to float32) biases the estimate by its error.
    faults : Faults, optional
        Faults of the loop around the filter (``problem.faults`` is not read by default: the
        filter is designed without them). ``sensor_noise`` is noise on the state the sensor
        reads, ``y = C (x + nu) + r``; ``actuator_noise`` is added to the command the plant
        holds, not to the one the filter predicts with; model mismatch changes the plant, not
        the predictor; a missed tick (``miss_probability``) runs no controller: the plant
        holds the last command, the reading is lost, the filter predicts over it with that
        command on its next run, and a stage entered late latches at its first tick run
        (``stsp_est_step``). The filter is the nominal one (its LMMSE gains and mean maps, unless
        `gains`/`predictor` are given). Raises ProblemError for the faults that
        `estimator_faults_unsupported` names.
    output : ndarray, optional
        An output matrix ``Cy``: also the mean and covariance of the true ``Cy x`` at every
        tick (``moments.path_y_mean``, ``path_y_cov``), as `oracle.evaluate.evaluate_table`'s
        `output` (a corridor's exit bounds, `oracle.exit_bound`).

    Returns
    -------
    EstimatorLoop
    """
    meas = problem.measurement if measurement is None else measurement
    _check(problem, table, meas)
    faulty = faults is not None and faults.any
    if faulty:
        why = estimator_faults_unsupported(faults)
        if why:
            raise ProblemError(*why)
        if gains is None or predictor is None:
            nominal = evaluate_estimator(problem, table, meas, propagator=propagator,
                                         substeps=substeps, gains=gains, predictor=predictor)
            gains = nominal.gain if gains is None else gains
            predictor = nominal.predict if predictor is None else predictor
    compiled = None
    if gains is None and predictor is None and not faulty:
        # The filter itself from the compiled recursion (`estimator.filter_kernel`): the same
        # bits on every machine; the moments below run on its gains.
        compiled = filter_gains(problem, table, meas, propagator)
        if compiled is not None:
            gains = compiled[0]
    plant = faults.plant_of(problem) if faulty else problem
    sig_x = faults.sensor_noise if faulty and np.any(faults.sensor_noise) else None
    act_cov = (np.diag(faults.actuator_noise ** 2)
               if faulty and np.any(faults.actuator_noise) else None)
    extra_R = None if sig_x is None else (meas.C * sig_x ** 2) @ meas.C.T
    n, m, nl = table.dims
    p = meas.p
    h = 1.0 / table.tick_hz
    C = meas.C
    miss = float(faults.miss_probability) if faulty else 0.0
    mu = m if miss else 0                   # the command held on a missed tick
    xs, hs, vs = slice(0, n), slice(n, 2 * n), slice(2 * n, 2 * n + nl)
    ls = slice(2 * n + nl, 2 * n + nl + mu)
    d = 2 * n + nl + mu + 1                 # z = [x; x̂; v; u_last (missed ticks); 1]
    rs = slice(d - 1, d - 1 + p)            # during an update: z_r = [x; x̂; v; u_last; r; 1]
    x0 = problem.x0
    z0 = np.concatenate([x0, x0, np.zeros(nl), np.asarray(table.u_hold, float)[:mu], [1.0]])
    M = np.outer(z0, z0)
    M[xs, xs] += meas.prior_cov(n)
    keep = np.r_[0:d - 1, d - 1 + p]        # z inside z_r
    J = 0.0
    means, covs, cons, err_knot, est_knot = [], [], [], [], []
    gain_out = np.zeros((table.n_ticks, n, p))
    predict = np.zeros((table.n_ticks, n, n + m + 1))
    err_cov = np.zeros((table.n_ticks, n, n))
    prior_cov = np.zeros((table.n_ticks, n, n))
    innov_cov = np.zeros((table.n_ticks, p, p))
    out_cov = np.zeros((table.n_ticks, p, p))
    est_ms = np.zeros((table.n_ticks, n))
    rec = _PathRecord(x0, path, None if output is None else np.asarray(output, float))
    if path:                                # the true start's spread (the record assumes none)
        rec.x_var[0] = np.diag(meas.prior_cov(n)).copy()
    if output is not None:
        rec.y_cov[0] = rec.Cy @ meas.prior_cov(n) @ rec.Cy.T
    eye = np.eye(d)
    Tw = _w_map(n, m, d, xs)                # w = [x; u; 1] = Tw z
    Th = _w_map(n, m, d, hs)                # [x̂; u; 1]: what the predictor moves
    Fu_miss = np.zeros((m, d))              # a missed tick: the plant holds u_last
    Fu_miss[:, ls] = np.eye(m)[:, :mu]

    def tick(M, j, k, Fu, ran):
        """One tick of the plant and the predictor from E zz' = M with ``u = Fu z``: the
        moments after it, the expected cost and ``E ww'`` (`ran`: u_last becomes u)."""
        Tw[n:n + m] = Fu
        Th[n:n + m] = Fu
        TM = Tw @ M
        Mw = TM @ Tw.T
        if act_cov is not None:    # u + eta: eta independent of z (so E x+ a' as without)
            Mw[n:n + m, n:n + m] += M[-1, -1] * act_cov
        Mw_in = Mw
        Mw, dJ, Fmean = plants[k].tick(Mw, j)
        predict[j] = Fmean
        Ta = np.zeros((d - n, d))           # passengers a = [x̂'; v; u_last'; 1]
        Ta[:n] = (Fmean if predictor is None else predictor[j]) @ Th
        Ta[n:] = eye[2 * n:]
        if ran and mu:
            Ta[nl + n:nl + n + mu] = Fu
        Mn = np.empty_like(M)
        Mn[xs, xs] = Mw[:n, :n]
        Mn[xs, n:] = Fmean @ TM @ Ta.T      # E x+ a' (the plant's noise is uncorrelated)
        Mn[n:, xs] = Mn[xs, n:].T
        Mn[n:, n:] = Ta @ M @ Ta.T
        Mn[xs, -1] = Mn[-1, xs] = Mw[:n, -1]
        return 0.5 * (Mn + Mn.T), dJ, Mw_in

    def run(M, j, k, latch):
        """The controller runs at tick j: update, latch (`latch`), command, tick. Returns the
        moments after the tick, the cost, ``E ww'`` and the moments after the update."""
        if meas.samples_at(j):
            M = _update(M, meas, C, gain_out, j, n, xs, hs, rs, keep, d, p,
                        None if gains is None else gains[j], table.t0 + j * h, extra_R)
        updated = M
        if latch:
            T = eye.copy()
            T[vs] = 0.0
            T[vs, hs] = table.Lambda[k].astype(float)
            T[vs, -1] = table.lambda0[k].astype(float)
            M = T @ M @ T.T
        Fu = np.zeros((m, d))               # u = Fu z
        Fu[:, hs] = -table.K[j].astype(float)
        Fu[:, vs] = -table.L[j].astype(float)
        Fu[:, -1] = -table.k0[j].astype(float)
        return (*tick(M, j, k, Fu, True), updated)

    # With missed ticks the moments are kept apart (unnormalised, E[zz' 1{branch}]) for the
    # paths that have latched the current stage ("L") and those that have not run in it yet
    # ("U": a stage entered late latches at its first tick run, stsp_est_step); the branch of
    # a tick (run with probability 1 - miss) is independent of z, so each is linear.
    plants = [_StagePlant(plant.stages[k], n, m, table.t0, h, propagator, substeps)
              for k in range(table.n_stages)]
    M_L, M_U = M, None
    for k in range(table.n_stages):
        if k == 0 or table.stage_n_latch[k] > 0:
            M_L, M_U = None, _add(M_U, M_L, 1.0)
        else:
            M_L, M_U = _add(M_L, M_U, 1.0), None
        for j in range(int(table.stage_start[k]), int(table.stage_start[k + 1])):
            total = _add(M_L, M_U, 1.0)
            prior_cov[j] = _error_cov(total, xs, hs)
            est_ms[j] = np.diag(total[hs, hs])
            if meas.samples_at(j):      # E ee' of the innovation y - C x̂, E yy' of the reading
                E = total[xs, xs] - total[xs, hs] - total[hs, xs] + total[hs, hs]
                R = meas.noise_cov(total[xs, xs], table.t0 + j * h)
                if extra_R is not None:
                    R = R + extra_R
                innov_cov[j] = C @ (0.5 * (E + E.T)) @ C.T + R
                out_cov[j] = C @ total[xs, xs] @ C.T + R
            L_next = U_next = Mw_all = after = None
            for Mb, latch in ((M_L, False), (M_U, True)):
                if Mb is None or Mb[-1, -1] == 0.0:
                    continue
                Mr, dJ, Mw, upd = run(Mb, j, k, latch)
                J += (1.0 - miss) * dJ
                L_next = _add(L_next, Mr, 1.0 - miss)
                Mw_all = _add(Mw_all, Mw, 1.0 - miss)
                after = _add(after, upd, 1.0 - miss)
                if miss:
                    Mm, dJ, Mw = tick(Mb, j, k, Fu_miss, False)
                    J += miss * dJ
                    Mw_all = _add(Mw_all, Mw, miss)
                    after = _add(after, Mb, miss)
                    if latch:
                        U_next = _add(U_next, Mm, miss)
                    else:
                        L_next = _add(L_next, Mm, miss)
            err_cov[j] = _error_cov(after, xs, hs)
            est_ms[j] = np.maximum(est_ms[j], np.diag(after[hs, hs]))
            rec.command(Mw_all, n, m)
            M_L, M_U = L_next, U_next
            rec.state(_add(M_L, M_U, 1.0), n)
        M = _add(M_L, M_U, 1.0)
        sub = np.r_[0:n, d - 1]
        pen, mean, cov, con = _knot_terms(problem, k, M[np.ix_(sub, sub)], n)
        J += pen
        means.append(mean); covs.append(cov); cons.append(con)
        err_knot.append(_error_cov(M, xs, hs))
        est_knot.append(M[hs, -1].copy())
    mom = rec.moments(J, means, covs, cons, problem.t0, h, table.n_ticks)
    if compiled is not None:
        predict = compiled[1]               # equal to the plant's maps above to rounding
    return EstimatorLoop(mom, gain_out, predict, err_cov, err_knot, est_knot, prior_cov,
                         innov_cov, out_cov, est_ms)


def _add(acc, M, w: float):
    """``acc + w M`` with None for zero (`w` 1: M itself, no rounding)."""
    if M is None:
        return acc
    term = M if w == 1.0 else w * M
    return term if acc is None else acc + term


def _error_cov(M, xs, hs) -> np.ndarray:
    """The covariance of ``e = x - x̂`` from ``E zz'``: its second moment less ``E e E e'``
    (E e = 0 for the plant's exact mean map; not for a rounded or mismatched one)."""
    E = M[xs, xs] - M[xs, hs] - M[hs, xs] + M[hs, hs]
    e = M[xs, -1] - M[hs, -1]
    E = E - np.outer(e, e)
    return 0.5 * (E + E.T)


def _update(M, meas, C, gains, j, n, xs, hs, rs, keep, d, p, given=None, t=None,
            extra_R=None):
    """The measurement update of tick j (at time `t`) on ``E zz'``: the LMMSE gain from these
    moments, or `given` (stored in ``gains[j]``), then ``x̂ += Lf (C x + r - C x̂)`` with the
    sensor noise ``r`` appended (uncorrelated with z) and dropped again; `extra_R` is a
    fault's noise in ``r`` that the LMMSE gain is not told about."""
    Mxx = M[xs, xs]
    P = Mxx - M[xs, hs] - M[hs, xs] + M[hs, hs]
    P = 0.5 * (P + P.T)
    w = M[-1, -1]                  # the branch's probability (1 without missed ticks)
    R = meas.noise_cov(Mxx, t)
    if w != 1.0:                   # E[rr' 1{branch}]: the additive parts scale with it
        R = R + (w - 1.0) * meas.V_at(t)
    Lf = lmmse_gain(P, C, R) if given is None else np.asarray(given, dtype=float)
    if extra_R is not None:
        R = R + w * extra_R
    gains[j] = Lf
    D = d + p
    Mr = np.zeros((D, D))
    Mr[np.ix_(keep, keep)] = M
    Mr[rs, rs] = R
    U = np.zeros((d, D))                     # z+ = U z_r
    U[:, keep] = np.eye(d)
    U[hs, xs] += Lf @ C
    U[hs, hs] -= Lf @ C
    U[hs, rs] = Lf
    return U @ Mr @ U.T
