"""A second, independent computation of the estimator loop's gains and moments, for tests.

It shares no tick code with `stospline.estimator.oracle`: the loop's state is ``xi = [x; e; v;
1]`` with the error ``e = x - x̂`` in place of the estimate, the predictor runs as the ODE
``dx̂ = (A x̂ + B u + f) dt`` inside the tick, and one tick is the Van Loan exponential of the
whole moment generator of ``chi = [xi; u]`` (u held), built with Kronecker products on ``vec E
chi chi'`` (row-major). Constant stage data only; small problems only (the generator is
(d^2)^2).
"""
from __future__ import annotations

import numpy as np
from scipy.linalg import expm


def _tick_generator(stage, n, nl):
    """Generator of vec E chi chi' over a tick, ``chi = [x; e; v; u; 1]`` with u held, and the
    running cost's rate matrix."""
    A, B = stage.A, stage.B
    m = B.shape[1]
    d = 2 * n + nl + m + 1
    us = slice(2 * n + nl, 2 * n + nl + m)
    f = np.zeros(n) if stage.f is None else stage.f
    Ab = np.zeros((d, d))
    Ab[:n, :n] = A
    Ab[:n, us] = B
    Ab[:n, -1] = f
    Ab[n:2 * n, n:2 * n] = A                             # de = A e dt + the plant's noise
    G = stage.G                                          # (n, n, mz): x_i G_i
    H = stage.H if stage.H is not None else np.zeros((m,) + G.shape[1:])
    # The noise of x (and of e: x̂ has none) per component of chi.
    Gam = np.zeros((d, d, G.shape[2]))
    for a in range(n):
        Gam[a, :n] = Gam[a, n:2 * n] = G[a]
    for j in range(m):
        Gam[us.start + j, :n] = Gam[us.start + j, n:2 * n] = H[j]
    I = np.eye(d)
    gen = np.kron(Ab, I) + np.kron(I, Ab)
    gen += np.einsum("apk,bqk->pqab", Gam, Gam).reshape(d * d, d * d)
    Lb = np.zeros((n + m + 1, n + m + 1))
    Lb[:n, :n], Lb[:n, n:n + m], Lb[n:n + m, :n] = stage.Q, stage.S, stage.S.T
    Lb[n:n + m, n:n + m] = stage.R
    Lb[:n, -1] = Lb[-1, :n] = stage.q
    Lb[n:n + m, -1] = Lb[-1, n:n + m] = stage.r
    Lb[-1, -1] = stage.rho
    Tw = np.zeros((n + m + 1, d))
    Tw[:n, :n] = np.eye(n)
    Tw[n:n + m, us] = np.eye(m)
    Tw[-1, -1] = 1.0
    return gen, Tw.T @ Lb @ Tw


def brute_loop(problem, table, meas):
    """(J, knot means, knot covariances, gains per tick) of the estimator loop."""
    n, m, nl = table.dims
    p = meas.C.shape[0]
    h = 1.0 / table.tick_hz
    d = 2 * n + nl + 1
    x0 = problem.x0
    S0 = np.zeros((n, n)) if meas.x0_cov is None else meas.x0_cov
    mu = np.concatenate([x0, np.zeros(n + nl), [1.0]])
    M = np.outer(mu, mu)
    M[:n, :n] += S0
    M[:n, n:2 * n] += S0                      # e = x - x0 at the start
    M[n:2 * n, :n] += S0
    M[n:2 * n, n:2 * n] += S0
    J, means, covs, gains = 0.0, [], [], []
    ex, ee = slice(0, n), slice(n, 2 * n)
    vv = slice(2 * n, 2 * n + nl)
    for k in range(table.n_stages):
        stage = problem.stages[k]
        for j in range(int(table.stage_start[k]), int(table.stage_start[k + 1])):
            Lf = np.zeros((n, p))
            if j % meas.every == 0:
                P = M[ee, ee]
                R = meas.V.copy()
                for a in range(n):
                    for b in range(n):
                        if meas.D.size:
                            R += M[a, b] * meas.D[a] @ meas.D[b].T
                S = meas.C @ P @ meas.C.T + R
                Lf = P @ meas.C.T @ np.linalg.pinv(S, rcond=1e-12, hermitian=True)
                # xi_r = [xi; r]: e+ = (I - Lf C) e - Lf r
                D = d + p
                Mr = np.zeros((D, D))
                Mr[:d, :d] = M
                Mr[d:, d:] = R
                U = np.zeros((d, D))
                U[:, :d] = np.eye(d)
                U[ee, ee] = np.eye(n) - Lf @ meas.C
                U[ee, d:] = -Lf
                M = U @ Mr @ U.T
            gains.append(Lf)
            if j == table.stage_start[k] and (k == 0 or table.stage_n_latch[k] > 0):
                T = np.eye(d)
                T[vv] = 0.0
                Lam = table.Lambda[k].astype(float)
                T[vv, ex] = Lam                     # v = Lambda (x - e) + lambda0
                T[vv, ee] = -Lam
                T[vv, -1] = table.lambda0[k].astype(float)
                M = T @ M @ T.T
            F = np.zeros((m, d))                    # u = -K (x - e) - L v - k0
            K = table.K[j].astype(float)
            F[:, ex], F[:, ee] = -K, K
            F[:, vv] = -table.L[j].astype(float)
            F[:, -1] = -table.k0[j].astype(float)
            gen, Lchi = _tick_generator(stage, n, nl)
            dc = d + m                              # chi = [x; e; v; u; 1] = Tc xi
            Tc = np.zeros((dc, d))
            Tc[:d - 1, :d - 1] = np.eye(d - 1)
            Tc[d - 1:d - 1 + m] = F
            Tc[-1, -1] = 1.0
            D2 = dc * dc
            big = np.zeros((2 * D2, 2 * D2))
            big[:D2, :D2] = gen * h
            big[:D2, D2:] = np.eye(D2) * h
            E = expm(big)
            vecM = (Tc @ M @ Tc.T).ravel()
            J += Lchi.ravel() @ (E[:D2, D2:] @ vecM)
            Mc = (E[:D2, :D2] @ vecM).reshape(dc, dc)
            keep = np.r_[0:d - 1, dc - 1]           # drop u
            M = Mc[np.ix_(keep, keep)]
            M = 0.5 * (M + M.T)
        mean = M[:n, -1].copy()
        cov = M[:n, :n] - np.outer(mean, mean)
        knot = problem.knots[k]
        if knot.penalty is not None:
            C, rho, w = knot.penalty.C, knot.penalty.target, knot.penalty.weight
            J += w * (np.trace(C @ M[:n, :n] @ C.T) - 2 * rho @ C @ mean + rho @ rho)
        means.append(mean)
        covs.append(cov)
    return J, means, covs, np.array(gains)
