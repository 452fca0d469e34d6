"""A Python Monte Carlo of the sampled estimator loop, for tests: paths of the plant by the
harness's scheme (exponential Euler–Maruyama, `substeps` per tick, left-point running cost),
a sensor drawing its noises, and the filter with the given gains. Constant stage data only."""
from __future__ import annotations

import numpy as np
from scipy.linalg import expm


def simulate_loop(problem, table, meas, gains, *, paths: int, substeps: int, seed: int):
    """Per path: the cost (paths,) and the true state at every knot (knots, paths, n)."""
    rng = np.random.default_rng(seed)
    n, m, nl = table.dims
    p = meas.C.shape[0]
    h = 1.0 / table.tick_hz
    dt = h / substeps
    S0 = np.zeros((n, n)) if meas.x0_cov is None else meas.x0_cov
    w, U = np.linalg.eigh(S0)
    x = problem.x0 + rng.standard_normal((paths, n)) @ (U * np.sqrt(np.maximum(w, 0))).T
    xh = np.tile(problem.x0, (paths, 1))
    v = np.zeros((paths, nl))
    wv, Uv = np.linalg.eigh(meas.V)
    sqV = Uv * np.sqrt(np.maximum(wv, 0.0))
    cost = np.zeros(paths)
    knots = []
    for k in range(table.n_stages):
        st = problem.stages[k]
        f = np.zeros(n) if st.f is None else st.f
        Ah = np.zeros((n + m + 1, n + m + 1))
        Ah[:n, :n], Ah[:n, n:n + m], Ah[:n, -1] = st.A, st.B, f
        Ed, Eh = expm(Ah * dt)[:n], expm(Ah * h)[:n]
        H = st.H if st.H is not None else np.zeros((m,) + st.G.shape[1:])
        Gall = np.concatenate([st.G, H])                    # multipliers [x; u]
        for j in range(int(table.stage_start[k]), int(table.stage_start[k + 1])):
            if j % meas.every == 0:
                y = x @ meas.C.T + rng.standard_normal((paths, p)) @ sqV.T
                if meas.D.size:
                    nu = rng.standard_normal((paths, meas.D.shape[2]))
                    y += np.einsum("Pa,apk,Pk->Pp", x, meas.D, nu)
                xh = xh + (y - xh @ meas.C.T) @ gains[j].T
            if j == table.stage_start[k] and (k == 0 or table.stage_n_latch[k] > 0):
                v = xh @ table.Lambda[k].astype(float).T + table.lambda0[k].astype(float)
            u = -(xh @ table.K[j].astype(float).T + v @ table.L[j].astype(float).T
                  + table.k0[j].astype(float))
            ones = np.ones((paths, 1))
            for _ in range(substeps):
                z = np.hstack([x, u, ones])
                cost += dt * (np.einsum("Pi,ij,Pj->P", x, st.Q, x)
                              + 2 * np.einsum("Pi,ij,Pj->P", x, st.S, u)
                              + np.einsum("Pi,ij,Pj->P", u, st.R, u)
                              + 2 * x @ st.q + 2 * u @ st.r + st.rho)
                dZ = rng.standard_normal((paths, Gall.shape[2])) * np.sqrt(dt)
                x = z @ Ed.T + np.einsum("Pa,aik,Pk->Pi", z[:, :n + m], Gall, dZ)
            xh = np.hstack([xh, u, ones]) @ Eh.T
        knot = problem.knots[k]
        if knot.penalty is not None:
            e = x @ knot.penalty.C.T - knot.penalty.target
            cost += knot.penalty.weight * np.sum(e * e, axis=1)
        knots.append(x.copy())
    return cost, np.array(knots)
