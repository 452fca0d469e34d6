"""Exact fourth moments of the estimator loop under the Monte Carlo plant scheme: the
standard errors of a run of `harness.estimator_loop.simulate_estimator` (`oracle.tails` for the
full-state loop, whose plant step this reuses).

The loop's state between ticks is ``z = [x; x̂; v; 1]`` (`estimator.oracle`). A tick is:

    update   x̂ += Lf_j (C x + r - C x̂)      at a sampling tick; r the sensor's noise
    latch    v = Lambda x̂ + lambda0          a stage's first tick
    plant    q = [x; u; x̂; v; 1], u = -K x̂ - L v - k0, the scheme's steps (x̂ and v ride along)
    predict  x̂ = pred_j [x̂; u; 1]

Given z, the sensor's noise ``r = sqrt(V) e + sum_a x_a D_a nu`` is Gaussian with covariance
``R(z) = V + sum_ab x_a x_b D_a D_b'``, a quadratic form of z, so the moments of ``[z; r]`` up
to the fourth are contractions of those of z (Isserlis: ``E r r r r = R R + R R + R R``). The
start ``x ~ N(x0, x0_cov)``, ``x̂ = x0`` is Gaussian too. The filter's gains and predictor are
those of the second-moment oracle (`evaluate_estimator`), whose knot moments and cost the loop
must reproduce (`oracle.tails.TailsMismatch`).
"""
from __future__ import annotations

import itertools

import numpy as np

from stospline.oracle.tails import (MAX_DIM, TailMoments, _mode, _Sym, _TickOperator,
                                    check_second_moments, knot_step, too_many_channels)
from stospline.problem.model import Problem

__all__ = ["evaluate_estimator_tails", "estimator_tails_unsupported"]


def estimator_tails_unsupported(problem: Problem, table) -> str | None:
    """Why `evaluate_estimator_tails` cannot evaluate the loop (None: it can)."""
    if any(st.varying is not None for st in problem.stages[:table.n_stages]):
        return "time-varying stage data"
    if problem.measurement is not None and problem.measurement.V_series is not None:
        return "a time-varying measurement.V"
    if problem.faults.any:
        return "faults"
    n, m, nl = table.dims
    if 2 * n + m + nl + 1 > MAX_DIM:
        return f"more than {MAX_DIM - 1} states, estimates, inputs and multipliers together"
    return too_many_channels(problem, table)


def _start(z0: np.ndarray, S: np.ndarray, n: int) -> np.ndarray:
    """``E z^(x)4`` for ``z = z0 + [e; 0]``, ``e ~ N(0, S)``: three-point Gauss-Hermite nodes
    on the eigenvectors of S (exact to degree five)."""
    w, Q = np.linalg.eigh(S)
    cols = [Q[:, i] * np.sqrt(w[i]) for i in range(n) if w[i] > 0]
    T = np.zeros((len(z0),) * 4)
    pts, wts = np.sqrt(3.0) * np.array([-1.0, 0.0, 1.0]), np.array([1.0, 4.0, 1.0]) / 6.0
    for pick in itertools.product(range(3), repeat=len(cols)):
        z = z0.copy()
        weight = 1.0
        for col, p in zip(cols, pick):
            z[:n] += pts[p] * col
            weight *= wts[p]
        T += weight * np.einsum("i,j,k,l->ijkl", z, z, z, z)
    return T


def _sensor_form(meas, n: int, d: int) -> np.ndarray:
    """``Rq`` (p, p, d, d): ``R(z)_pq = sum_ij Rq[p, q, i, j] z_i z_j``."""
    p = meas.p
    Rq = np.zeros((p, p, d, d))
    Rq[:, :, d - 1, d - 1] = meas.V
    if meas.D.size and meas.D.any():
        Rq[:, :, :n, :n] = np.einsum("apk,bqk->pqab", meas.D, meas.D)
    return Rq


def _update(T4, P, Rq, Lf, C, n, d):
    """The measurement update on ``E z^(x)4`` and ``E J z z'``."""
    p = Rq.shape[0]
    dr = d + p
    zi = np.r_[0:d - 1, dr - 1]            # z inside z_r = [x; x̂; v; r; 1]
    ri = np.arange(d - 1, d - 1 + p)
    B2 = np.einsum("pqkl,ijkl->ijpq", Rq, T4)               # E z_i z_j r_p r_q
    G = np.einsum("pqij,stkl,ijkl->pqst", Rq, Rq, T4)      # E R_pq R_st
    B4 = G + np.transpose(G, (0, 2, 1, 3)) + np.transpose(G, (0, 2, 3, 1))
    W = np.zeros((dr,) * 4)
    W[np.ix_(zi, zi, zi, zi)] = T4
    for a, b in itertools.combinations(range(4), 2):
        idx = [zi] * 4
        idx[a] = idx[b] = ri
        W[np.ix_(*idx)] = np.moveaxis(B2, [2, 3], [a, b])
    W[np.ix_(ri, ri, ri, ri)] = B4
    Pr = np.zeros((dr, dr))
    Pr[np.ix_(zi, zi)] = P
    Pr[np.ix_(ri, ri)] = np.einsum("pqkl,kl->pq", Rq, P)
    U = np.zeros((d, dr))                  # z+ = U z_r
    U[np.arange(d), zi] = 1.0
    hs = slice(n, 2 * n)
    U[hs, :n] += Lf @ C
    U[hs, hs] -= Lf @ C
    U[hs, ri] = Lf
    return _mode(W, U), U @ Pr @ U.T


def evaluate_estimator_tails(problem: Problem, table, loop, *, predictor=None,
                             substeps: int) -> TailMoments:
    """The exact cost variance and knot moments up to the fourth of the estimator loop with
    the filter of `loop` (an `estimator.oracle.EstimatorLoop` evaluated with
    ``propagator="euler"`` and these `substeps`: its gains, and `predictor` or else its
    predictor maps), the plant advanced by the Monte Carlo scheme. Raises ValueError for what
    `estimator_tails_unsupported` names, `oracle.tails.TailsMismatch` when the second moments
    differ from `loop`'s."""
    why = estimator_tails_unsupported(problem, table)
    if why is not None:
        raise ValueError(f"evaluate_estimator_tails: {why} is not supported")
    meas = problem.measurement
    n, m, nl = table.dims
    h = 1.0 / table.tick_hz
    d = 2 * n + nl + 1                      # z = [x; x̂; v; 1]
    dq = d + m                              # q = [x; u; x̂; v; 1]
    s4, s2 = _Sym(dq, 4), _Sym(dq, 2)
    x0 = np.asarray(problem.x0, float)
    z0 = np.concatenate([x0, x0, np.zeros(nl), [1.0]])
    T4 = _start(z0, meas.prior_cov(n), n)
    P = np.zeros((d, d))
    J2 = 0.0
    Rq = _sensor_form(meas, n, d)
    pred = loop.predict if predictor is None else np.asarray(predictor, float)
    into = np.zeros((dq, d))
    into[:n, :n] = np.eye(n)
    into[n + m:, n:] = np.eye(d - n)
    out = np.zeros((d, dq))
    out[:n, :n] = np.eye(n)
    out[2 * n:, n + m + n:] = np.eye(nl + 1)
    hs, vs = slice(n, 2 * n), slice(2 * n, 2 * n + nl)
    means, covs, mu4s = [], [], []
    ops: dict = {}
    for k in range(table.n_stages):
        stage = problem.stages[k]
        if id(stage) not in ops:
            ops[id(stage)] = (stage, _TickOperator(stage, n, m, n + nl, h, substeps, s4, s2))
        op = ops[id(stage)][1]
        relatch = k == 0 or table.stage_n_latch[k] > 0
        for j in range(int(table.stage_start[k]), int(table.stage_start[k + 1])):
            if meas.samples_at(j):
                T4, P = _update(T4, P, Rq, loop.gain[j], meas.C, n, d)
            if relatch and j == table.stage_start[k]:
                T = np.eye(d)
                T[vs] = 0.0
                T[vs, hs] = table.Lambda[k].astype(float)
                T[vs, -1] = table.lambda0[k].astype(float)
                T4, P = _mode(T4, T), T @ P @ T.T
            into[n:n + m] = 0.0
            into[n:n + m, hs] = -table.K[j].astype(float)
            into[n:n + m, vs] = -table.L[j].astype(float)
            into[n:n + m, -1] = -table.k0[j].astype(float)
            # x̂ <- pred_j [x̂; u; 1], from q's x̂, u and 1.
            out[hs] = 0.0
            out[hs, n + m:n + m + n] = pred[j][:, :n]
            out[hs, n:n + m] = pred[j][:, n:n + m]
            out[hs, -1] = pred[j][:, -1]
            T4, P, J2 = op.apply(T4, P, J2, into, out)
        P, J2, mean, cov, mu4 = knot_step(problem.knots[k], T4, P, J2, n)
        means.append(mean)
        covs.append(cov)
        mu4s.append(mu4)
    J = float(P[-1, -1])
    tails = TailMoments(J, J2 - J * J, means, covs, mu4s, substeps)
    check_second_moments(tails, loop.moments)
    return tails
