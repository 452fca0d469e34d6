"""Exact fourth moments of the estimator loop under the Monte Carlo plant scheme: the
standard errors of a run of `harness.estimator_loop.simulate_estimator` (`oracle.tails` for the
full-state loop, whose plant step this reuses).

The loop's state between ticks is ``z = [x; x̂; v; u_last; 1]`` (`estimator.oracle`; ``u_last``,
the command held on a missed tick, only with missed ticks). A tick in which the controller runs:

    update   x̂ += Lf_j (C x + r - C x̂)      at a sampling tick; r the sensor's noise
    latch    v = Lambda x̂ + lambda0          a stage's first tick run
    plant    q = [x; u + eta; x̂; v; u_last; 1], u = -K x̂ - L v - k0, the scheme's steps
    predict  x̂ = pred_j [x̂; u; 1], u_last = u

Given z, the sensor's noise ``r = sqrt(V(t_j)) e + C nu_f + sum_a x_a D_a nu`` (``nu_f`` the
sensor-noise fault) is Gaussian with covariance ``R(z) = V(t_j) + C diag(sigma_x^2) C' + sum_ab
x_a x_b D_a D_b'``, a quadratic form of z, so the moments of ``[z; r]`` up to the fourth are
contractions of those of z (Isserlis: ``E r r r r = R R + R R + R R``); the actuator-noise
fault ``eta ~ N(0, diag sigma_u^2)`` is appended the same way (a constant form). The plant
(model mismatch: `Faults.plant_of`) moves ``u + eta``; the predictor and ``u_last`` take the
command written, rebuilt from q's ``x̂`` and ``v``. A missed tick (probability
``miss_probability``, independent of everything) runs no controller: ``u = u_last``, no
reading, ``x̂ = pred_j [x̂; u_last; 1]``. The moments are then kept unnormalised,
``E[z^(x)4 1{branch}]`` (and ``E[J z z' 1{branch}]``, ``E[J^2 1{branch}]``), for the paths that
have latched the current stage and those that have not run in it yet; each branch's map is
linear, and a tick adds each branch's image weighted by its probability. The start ``x ~
N(x0, x0_cov)``, ``x̂ = x0`` is Gaussian too. The filter's gains and predictor are those of the
second-moment oracle (`evaluate_estimator`), whose knot moments and cost the loop must
reproduce (`oracle.tails.TailsMismatch`). The plant step's map is built by the oracle's C
kernel where its module builds (`oracle.tails_kernel`; its numpy reference otherwise); the
ticks run here in numpy.
"""
from __future__ import annotations

import itertools

import numpy as np

from stospline.oracle.tails import (MAX_DIM, TailMoments, _mode, _Sym, _TickOperator,
                                    check_second_moments, knot_step, step_matrix,
                                    too_many_channels)
from stospline.oracle.tails_kernel import compiled_tails
from stospline.problem.faults import Faults
from stospline.problem.model import Problem




__all__ = ["evaluate_estimator_tails", "estimator_tails_unsupported"]


def estimator_tails_unsupported(problem: Problem, table,
                                faults: Faults | None = None) -> str | None:
    """Why `evaluate_estimator_tails` cannot evaluate the loop with `faults` (None: it can)."""
    if any(st.varying is not None for st in problem.stages[:table.n_stages]):
        return "time-varying stage data"
    faulty = faults is not None and faults.any
    if faulty:
        from stospline.estimator.oracle import estimator_faults_unsupported
        why = estimator_faults_unsupported(faults)
        if why is not None:
            return f"{why[0]} ({why[1]})"
    n, m, nl = table.dims
    mu = m if faulty and faults.miss_probability else 0
    if 2 * n + m + nl + mu + 1 > MAX_DIM:
        held = ", held commands (missed ticks)" if mu else ""
        return (f"more than {MAX_DIM - 1} states, estimates, inputs{held} and multipliers "
                f"together")
    return too_many_channels(faults.plant_of(problem) if faulty else problem, table)


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


def _sensor_form(meas, n: int, d: int, V=None) -> np.ndarray:
    """``Rq`` (p, p, d, d): ``R(z)_pq = sum_ij Rq[p, q, i, j] z_i z_j`` (`V`: the additive
    covariance, ``meas.V`` by default)."""
    p = meas.p
    Rq = np.zeros((p, p, d, d))
    Rq[:, :, d - 1, d - 1] = meas.V if V is None else V
    if meas.D.size and meas.D.any():
        Rq[:, :, :n, :n] = np.einsum("apk,bqk->pqab", meas.D, meas.D)
    return Rq


def _with_noise(T4, P, Rq):
    """The moments of ``z_r = [z without its 1; r; 1]`` from ``E z^(x)4`` and ``E J z z'``,
    for ``r`` Gaussian given z (and J) with mean 0 and covariance ``R(z)_pq = Rq[p, q] : z
    z'``. Returns ``(E z_r^(x)4, E J z_r z_r', zi, ri)``, zi and ri the places of z and r in
    z_r."""
    d, p = T4.shape[0], Rq.shape[0]
    dr = d + p
    zi = np.r_[0:d - 1, dr - 1]
    ri = np.arange(d - 1, d - 1 + p)
    if Rq[:, :, :-1].any() or Rq[:, :, -1, :-1].any():
        B2 = np.einsum("pqkl,ijkl->ijpq", Rq, T4)           # E z_i z_j r_p r_q
        G = np.einsum("pqij,stkl,ijkl->pqst", Rq, Rq, T4)  # E R_pq R_st
    else:                                   # R constant: on z's 1 only
        R0 = Rq[:, :, -1, -1]
        B2 = np.multiply.outer(T4[:, :, -1, -1], R0)
        G = T4[-1, -1, -1, -1] * np.multiply.outer(R0, R0)
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
    return W, Pr, zi, ri


def _update(T4, P, Rq, Lf, C, n, d):
    """The measurement update on ``E z^(x)4`` and ``E J z z'`` (``x̂`` at ``n:2n``)."""
    W, Pr, zi, ri = _with_noise(T4, P, Rq)
    U = np.zeros((d, d + Rq.shape[0]))        # z+ = U z_r
    U[np.arange(d), zi] = 1.0
    hs = slice(n, 2 * n)
    U[hs, :n] += Lf @ C
    U[hs, hs] -= Lf @ C
    U[hs, ri] = Lf
    return _mode(W, U), U @ Pr @ U.T


def _add(acc, br, w: float):
    """``acc + w br`` on ``(E z^(x)4, E J z z', E J^2)``, None for nothing."""
    if br is None:
        return acc
    if w != 1.0:
        br = (w * br[0], w * br[1], w * br[2])
    return br if acc is None else (acc[0] + br[0], acc[1] + br[1], acc[2] + br[2])


def evaluate_estimator_tails(problem: Problem, table, loop, *, predictor=None,
                             substeps: int, faults: Faults | None = None) -> TailMoments:
    """The exact cost variance and knot moments up to the fourth of the estimator loop with
    the filter of `loop` (an `estimator.oracle.EstimatorLoop` evaluated with
    ``propagator="euler"``, these `substeps` and these `faults`: its gains, and `predictor`
    or else the predictor maps of the nominal filter), the plant advanced by the Monte Carlo
    scheme. `faults` (None: none; ``problem.faults`` is not read) are those of
    `evaluate_estimator`: sensor noise on the state read, actuator noise, model mismatch,
    missed ticks. A time-varying ``measurement.V`` is taken at each sampling tick. Raises
    ValueError for what `estimator_tails_unsupported` names, `oracle.tails.TailsMismatch`
    when the second moments differ from `loop`'s."""
    why = estimator_tails_unsupported(problem, table, faults)
    if why is not None:
        raise ValueError(f"evaluate_estimator_tails: {why} is not supported")
    faulty = faults is not None and faults.any
    meas = problem.measurement
    n, m, nl = table.dims
    h = 1.0 / table.tick_hz
    if predictor is None and faulty:    # loop.predict is the faulty plant's mean map
        from stospline.estimator.oracle import evaluate_estimator
        predictor = evaluate_estimator(problem, table, meas, propagator="euler",
                                       substeps=substeps).predict
    pred = loop.predict if predictor is None else np.asarray(predictor, float)
    plant = faults.plant_of(problem) if faulty else problem
    miss = float(faults.miss_probability) if faulty else 0.0
    sig_u = faults.actuator_noise if faulty and np.any(faults.actuator_noise) else None
    sig_x = faults.sensor_noise if faulty and np.any(faults.sensor_noise) else None
    extra_R = 0.0 if sig_x is None else (meas.C * sig_x ** 2) @ meas.C.T
    mu = m if miss else 0
    d = 2 * n + nl + mu + 1                 # z = [x; x̂; v; u_last; 1]
    dq = d + m                              # q = [x; u; x̂; v; u_last; 1]
    hs, vs = slice(n, 2 * n), slice(2 * n, 2 * n + nl)
    ls = slice(2 * n + nl, 2 * n + nl + mu)
    s4, s2 = _Sym(dq, 4), _Sym(dq, 2)
    x0 = np.asarray(problem.x0, float)
    z0 = np.concatenate([x0, x0, np.zeros(nl), np.asarray(table.u_hold, float)[:mu], [1.0]])
    Rq = _sensor_form(meas, n, d)
    Ra = None
    if sig_u is not None:                   # eta: a constant form on z
        Ra = np.zeros((m, m, d, d))
        Ra[:, :, -1, -1] = np.diag(sig_u ** 2)
    ops: dict = {}
    kernel = compiled_tails(n, m, d - n - 1, s4, s2, sym=_Sym, step_matrix=step_matrix)
    operator = None if kernel is None else kernel.operator      # the step's map in C

    def tick(br, j, op, Fu):
        """The plant and the predictor over tick j from the moments `br` of z (after the
        update and latch), the command written ``u = Fu z``."""
        T4, P, J2 = br
        Fq = np.zeros((m, dq))              # the command on q's passengers
        Fq[:, n + m:] = Fu[:, n:]
        out = np.zeros((d, dq))             # z+ = out q
        out[:n, :n] = np.eye(n)
        out[n:, n + m:] = np.eye(d - n)
        out[hs] = pred[j][:, :n] @ np.eye(n, dq, n + m) + pred[j][:, n:n + m] @ Fq
        out[hs, -1] += pred[j][:, -1]
        out[ls] = Fq[:mu]
        if Ra is None:
            into = np.zeros((dq, d))        # q = into z
            into[:n, :n] = np.eye(n)
            into[n:n + m] = Fu
            into[n + m:, n:] = np.eye(d - n)
        else:                               # q = into [z without 1; eta; 1]
            T4, P, zi, ri = _with_noise(T4, P, Ra)
            into = np.zeros((dq, d + m))
            into[:n, zi[:n]] = np.eye(n)
            into[n:n + m, zi] = Fu
            into[n:n + m, ri] = np.eye(m)
            into[n + m:, zi[n:]] = np.eye(d - n)
        return op.apply(T4, P, J2, into, out)

    def run(br, j, k, op, latch):
        """The controller runs at tick j: update, latch (`latch`), command, tick."""
        T4, P, J2 = br
        if meas.samples_at(j):
            Rq[:, :, -1, -1] = meas.V_at(table.t0 + j * h) + extra_R
            T4, P = _update(T4, P, Rq, loop.gain[j], meas.C, n, d)
        if latch:
            T = np.eye(d)
            T[vs] = 0.0
            T[vs, hs] = table.Lambda[k].astype(float)
            T[vs, -1] = table.lambda0[k].astype(float)
            T4, P = _mode(T4, T), T @ P @ T.T
        Fu = np.zeros((m, d))
        Fu[:, hs] = -table.K[j].astype(float)
        Fu[:, vs] = -table.L[j].astype(float)
        Fu[:, -1] = -table.k0[j].astype(float)
        return tick((T4, P, J2), j, op, Fu)

    Fu_miss = np.zeros((m, d))              # a missed tick: the plant holds u_last
    Fu_miss[:, ls] = np.eye(m)[:, :mu]
    # "L": the paths that have latched the current stage; "U": not run in it yet.
    L, U = (_start(z0, meas.prior_cov(n), n), np.zeros((d, d)), 0.0), None
    means, covs, mu4s = [], [], []
    for k in range(table.n_stages):
        stage = plant.stages[k]
        if id(stage) not in ops:
            ops[id(stage)] = (stage, _TickOperator(stage, n, m, d - n - 1, h, substeps, s4, s2,
                                                   operator))
        op = ops[id(stage)][1]
        if k == 0 or table.stage_n_latch[k] > 0:
            L, U = None, _add(U, L, 1.0)
        else:
            L, U = _add(L, U, 1.0), None
        for j in range(int(table.stage_start[k]), int(table.stage_start[k + 1])):
            L_next = U_next = None
            for br, latch in ((L, False), (U, True)):
                if br is None:
                    continue
                L_next = _add(L_next, run(br, j, k, op, latch), 1.0 - miss)
                if miss:
                    missed = tick(br, j, op, Fu_miss)
                    if latch:
                        U_next = _add(U_next, missed, miss)
                    else:
                        L_next = _add(L_next, missed, miss)
            L, U = L_next, U_next
        T4, P, J2 = _add(L, U, 1.0)
        P, J2, mean, cov, mu4 = knot_step(problem.knots[k], T4, P, J2, n)
        L, U = (T4, P, J2), None
        means.append(mean)
        covs.append(cov)
        mu4s.append(mu4)
    J = float(L[1][-1, -1])
    tails = TailMoments(J, L[2] - J * J, means, covs, mu4s, substeps)
    check_second_moments(tails, loop.moments)
    return tails
