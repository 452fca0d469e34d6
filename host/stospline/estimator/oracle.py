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

from stospline.estimator.gain import lmmse_gain
from stospline.problem.model import Problem
from stospline.oracle.tick_moments import Moments, _knot_terms, _PathRecord, _StagePlant, _w_map
from stospline.table.format import GainTable

__all__ = ["EstimatorLoop", "evaluate_estimator"]


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


def evaluate_estimator(problem: Problem, table: GainTable, measurement=None, *,
                       propagator: str = "exact", substeps: int = 4,
                       path: bool = False, gains: np.ndarray | None = None,
                       predictor: np.ndarray | None = None,
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
    rec = _PathRecord(x0, path, None if output is None else np.asarray(output, float))
    if path:                                # the true start's spread (the record assumes none)
        rec.x_var[0] = np.diag(meas.prior_cov(n)).copy()
    if output is not None:
        rec.y_cov[0] = rec.Cy @ meas.prior_cov(n) @ rec.Cy.T
    eye = np.eye(d)
    Tw = _w_map(n, m, d, xs)                # w = [x; u; 1] = Tw z
    Th = _w_map(n, m, d, hs)                # [x̂; u; 1]: what the predictor moves
    for k in range(table.n_stages):
        plant_k = _StagePlant(problem.stages[k], n, m, table.t0, h, propagator, substeps)
        relatch = k == 0 or table.stage_n_latch[k] > 0
        for j in range(int(table.stage_start[k]), int(table.stage_start[k + 1])):
            E = M[xs, xs] - M[xs, hs] - M[hs, xs] + M[hs, hs]
            prior_cov[j] = 0.5 * (E + E.T)
            if meas.samples_at(j):
                M = _update(M, meas, C, gain_out, j, n, xs, hs, rs, keep, d, p,
                            None if gains is None else gains[j])
            E = M[xs, xs] - M[xs, hs] - M[hs, xs] + M[hs, hs]
            err_cov[j] = 0.5 * (E + E.T)
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
        E = M[xs, xs] - M[xs, hs] - M[hs, xs] + M[hs, hs]
        err_knot.append(0.5 * (E + E.T))
        est_knot.append(M[hs, -1].copy())
    mom = rec.moments(J, means, covs, cons, problem.t0, h, table.n_ticks)
    return EstimatorLoop(mom, gain_out, predict, err_cov, err_knot, est_knot, prior_cov)


def _update(M, meas, C, gains, j, n, xs, hs, rs, keep, d, p, given=None):
    """The measurement update of tick j on ``E zz'``: the LMMSE gain from these moments, or
    `given` (stored in ``gains[j]``), then ``x̂ += Lf (C x + r - C x̂)`` with the sensor noise ``r``
    appended (uncorrelated with z) and dropped again."""
    Mxx = M[xs, xs]
    P = Mxx - M[xs, hs] - M[hs, xs] + M[hs, hs]
    P = 0.5 * (P + P.T)
    R = meas.noise_cov(Mxx)
    Lf = lmmse_gain(P, C, R) if given is None else np.asarray(given, dtype=float)
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
