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
    """
    moments: Moments
    gain: np.ndarray
    predict: np.ndarray
    error_cov: np.ndarray
    knot_error_cov: list[np.ndarray] = field(default_factory=list)
    knot_estimate_mean: list[np.ndarray] = field(default_factory=list)
    prior_error_cov: np.ndarray | None = None


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

    Sensor noise, actuator noise and model mismatch keep the loop linear and compose with the
    filter (docs/theory/estimator.md, "Faults"); a missed tick, a computation delay and the
    sensor quantizer are refused."""
    why = "with a [measurement] sensor the loop"
    if faults.miss_probability:
        return "faults.miss_probability", (f"{why} does not run missed ticks (the filter's "
                                           f"skipped predictions are not modelled yet)")
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
                       faults: Faults | None = None) -> EstimatorLoop:
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
        the predictor. The filter is the nominal one (its LMMSE gains and mean maps, unless
        `gains`/`predictor` are given). Raises ProblemError for the faults that
        `estimator_faults_unsupported` names.

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
    plant = faults.plant_of(problem) if faulty else problem
    sig_x = faults.sensor_noise if faulty and np.any(faults.sensor_noise) else None
    act_cov = (np.diag(faults.actuator_noise ** 2)
               if faulty and np.any(faults.actuator_noise) else None)
    extra_R = None if sig_x is None else (meas.C * sig_x ** 2) @ meas.C.T
    n, m, nl = table.dims
    p = meas.p
    h = 1.0 / table.tick_hz
    C = meas.C
    xs, hs, vs = slice(0, n), slice(n, 2 * n), slice(2 * n, 2 * n + nl)
    d = 2 * n + nl + 1                      # z = [x; x̂; v; 1]
    rs = slice(d - 1, d - 1 + p)            # during an update: z_r = [x; x̂; v; r; 1]
    x0 = problem.x0
    z0 = np.concatenate([x0, x0, np.zeros(nl), [1.0]])
    M = np.outer(z0, z0)
    M[xs, xs] += meas.prior_cov(n)
    keep = np.r_[0:d - 1, d - 1 + p]        # z inside z_r
    J = 0.0
    means, covs, cons, err_knot, est_knot = [], [], [], [], []
    gain_out = np.zeros((table.n_ticks, n, p))
    predict = np.zeros((table.n_ticks, n, n + m + 1))
    err_cov = np.zeros((table.n_ticks, n, n))
    prior_cov = np.zeros((table.n_ticks, n, n))
    rec = _PathRecord(x0, path)
    eye = np.eye(d)
    Tw = _w_map(n, m, d, xs)                # w = [x; u; 1] = Tw z
    Th = _w_map(n, m, d, hs)                # [x̂; u; 1]: what the predictor moves
    for k in range(table.n_stages):
        plant_k = _StagePlant(plant.stages[k], n, m, table.t0, h, propagator, substeps)
        relatch = k == 0 or table.stage_n_latch[k] > 0
        for j in range(int(table.stage_start[k]), int(table.stage_start[k + 1])):
            prior_cov[j] = _error_cov(M, xs, hs)
            if meas.samples_at(j):
                M = _update(M, meas, C, gain_out, j, n, xs, hs, rs, keep, d, p,
                            None if gains is None else gains[j], table.t0 + j * h, extra_R)
            err_cov[j] = _error_cov(M, xs, hs)
            if relatch and j == table.stage_start[k]:
                T = eye.copy()
                T[vs] = 0.0
                T[vs, hs] = table.Lambda[k].astype(float)
                T[vs, -1] = table.lambda0[k].astype(float)
                M = T @ M @ T.T
            Fu = np.zeros((m, d))               # u = Fu z
            Fu[:, hs] = -table.K[j].astype(float)
            Fu[:, vs] = -table.L[j].astype(float)
            Fu[:, -1] = -table.k0[j].astype(float)
            Tw[n:n + m] = Fu
            Th[n:n + m] = Fu
            TM = Tw @ M
            Mw = TM @ Tw.T
            if act_cov is not None:    # u + eta: eta independent of z (so E x+ a' as without)
                Mw[n:n + m, n:n + m] += act_cov
            rec.command(Mw, n, m)
            Mw, dJ, Fmean = plant_k.tick(Mw, j)
            J += dJ
            predict[j] = Fmean
            Ta = np.zeros((d - n, d))           # passengers a = [x̂'; v; 1]
            Ta[:n] = (Fmean if predictor is None else predictor[j]) @ Th
            Ta[n:] = eye[2 * n:]
            Mn = np.empty_like(M)
            Mn[xs, xs] = Mw[:n, :n]
            Mn[xs, n:] = Fmean @ TM @ Ta.T      # E x+ a' (the plant's noise is uncorrelated)
            Mn[n:, xs] = Mn[xs, n:].T
            Mn[n:, n:] = Ta @ M @ Ta.T
            Mn[xs, -1] = Mn[-1, xs] = Mw[:n, -1]
            M = 0.5 * (Mn + Mn.T)
            rec.state(M, n)
        sub = np.r_[0:n, d - 1]
        pen, mean, cov, con = _knot_terms(problem, k, M[np.ix_(sub, sub)], n)
        J += pen
        means.append(mean); covs.append(cov); cons.append(con)
        err_knot.append(_error_cov(M, xs, hs))
        est_knot.append(M[hs, -1].copy())
    mom = rec.moments(J, means, covs, cons, problem.t0, h, table.n_ticks)
    return EstimatorLoop(mom, gain_out, predict, err_cov, err_knot, est_knot, prior_cov)


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
    R = meas.noise_cov(Mxx, t)
    Lf = lmmse_gain(P, C, R) if given is None else np.asarray(given, dtype=float)
    if extra_R is not None:
        R = R + extra_R
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
