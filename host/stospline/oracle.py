"""Exact moment oracle: mean, covariance and expected cost of a latched affine law.

The oracle never looks at Riccati solutions. It takes a law (a continuous design's gain
functions, or a quantized per-tick `GainTable`) and propagates the first and second moments
of the augmented state ``y = [x; v; 1]`` (``v`` the latched multiplier, constant on a stage)
through the Ito moment equation

    d/dt M = Abar M + M Abar' + sum_ij M_ij Gbar_i Gbar_j'

For a table the control is held over each tick, so one tick is an exact linear map of the
moments of ``z = [x; u; v; 1]`` (computed once per stage with a block matrix exponential).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import solve_ivp
from scipy.linalg import expm

from .design import ContinuousDesign
from .problem import Problem, Stage
from .tables import GainTable

__all__ = ["Moments", "TickPropagator", "evaluate_continuous", "evaluate_table",
           "exact_tick", "euler_tick"]


@dataclass
class Moments:
    """Exact outcome of a law on a problem.

    ``knot_mean[k]``/``knot_cov[k]`` are the state's mean and covariance at knot k (end of
    stage k); ``knot_constraint[k]`` is ``E{C2 x}`` there (empty when unconstrained).
    ``path_t``/``path_mean`` sample the mean trajectory.
    """
    J: float
    knot_mean: list[np.ndarray]
    knot_cov: list[np.ndarray]
    knot_constraint: list[np.ndarray]
    path_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    path_mean: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))


def _noise_columns(G: np.ndarray, d: int) -> np.ndarray:
    """Matrix mapping vec(M) (row-major, d x d) to vec(sum_{i,j<n} M_ij Gbar_i Gbar_j')."""
    n = G.shape[0]
    Gbar = np.zeros((n, d, G.shape[2]))
    Gbar[:, :n, :] = G
    out = np.zeros((d * d, d * d))
    for i in range(n):
        for j in range(n):
            out[:, i * d + j] = (Gbar[i] @ Gbar[j].T).ravel()
    return out


def _moment_generator(Ahat: np.ndarray, G: np.ndarray) -> np.ndarray:
    """Linear operator of d/dt vec(M) for ``dz = Ahat z dt + sum_i z_i Gbar_i dZ``."""
    d = Ahat.shape[0]
    eye = np.eye(d)
    return np.kron(Ahat, eye) + np.kron(eye, Ahat) + _noise_columns(G, d)


@dataclass(frozen=True)
class TickPropagator:
    """One tick of ``z = [x; c]`` with the constants ``c`` held: ``vec M(h) = Phi vec M(0)``,
    ``vec ∫_0^h M dt = Psi vec M(0)``."""
    Phi: np.ndarray
    Psi: np.ndarray


def _augmented(stage: Stage, n_const: int) -> np.ndarray:
    n, m = stage.B.shape
    d = n + n_const
    Ahat = np.zeros((d, d))
    Ahat[:n, :n] = stage.A
    Ahat[:n, n:n + m] = stage.B   # u is the first block of the constants
    return Ahat


def exact_tick(stage: Stage, n_const: int, h: float) -> TickPropagator:
    """The exact moment map of the SDE over one tick (Van Loan block exponential)."""
    gen = _moment_generator(_augmented(stage, n_const), stage.G)
    D = gen.shape[0]
    big = np.zeros((2 * D, 2 * D))
    big[:D, :D] = gen * h
    big[:D, D:] = np.eye(D) * h
    E = expm(big)
    return TickPropagator(E[:D, :D], E[:D, D:])


def euler_tick(stage: Stage, n_const: int, h: float, substeps: int) -> TickPropagator:
    """The moment map of the Monte Carlo plant scheme: `substeps` exponential Euler–Maruyama
    steps ``z+ = e^{Ahat dt} z + sum_i z_i Gbar_i dZ`` with a left-point cost rule."""
    dt = h / substeps
    Ahat = _augmented(stage, n_const)
    Ad = expm(Ahat * dt)
    d = Ahat.shape[0]
    step = np.kron(Ad, Ad) + dt * _noise_columns(stage.G, d)
    Phi = np.eye(d * d)
    Psi = np.zeros((d * d, d * d))
    for _ in range(substeps):
        Psi += dt * Phi
        Phi = step @ Phi
    return TickPropagator(Phi, Psi)


def _running_cost_matrix(stage: Stage, n: int, m: int, d: int, u_at: int) -> np.ndarray:
    """Symmetric matrix Lbar with ``E L(x,u) = tr(Lbar E zz')``; 1 is the last component."""
    Lb = np.zeros((d, d))
    xs, us = slice(0, n), slice(u_at, u_at + m)
    Lb[xs, xs] = stage.Q
    Lb[xs, us] = stage.S
    Lb[us, xs] = stage.S.T
    Lb[us, us] = stage.R
    Lb[xs, -1] = Lb[-1, xs] = stage.q
    Lb[us, -1] = Lb[-1, us] = stage.r
    Lb[-1, -1] = stage.rho
    return Lb


def _knot_terms(problem: Problem, k: int, M: np.ndarray, n: int):
    """Penalty expectation, mean, covariance and constrained output at knot k from E yy'."""
    mean = M[:n, -1].copy()
    Mxx = M[:n, :n]
    cov = Mxx - np.outer(mean, mean)
    knot = problem.knots[k]
    pen = 0.0
    if knot.penalty is not None:
        C, rho, w = knot.penalty.C, knot.penalty.target, knot.penalty.weight
        pen = w * (np.trace(C @ Mxx @ C.T) - 2 * rho @ C @ mean + rho @ rho)
    con = knot.constraint.C @ mean if knot.constraint is not None else np.zeros(0)
    return pen, mean, 0.5 * (cov + cov.T), con


def _latch_transform(n: int, P: int, Lam: np.ndarray, lam0: np.ndarray, d_old: int) -> np.ndarray:
    """Map ``y_old = [x; v_old; 1]`` to ``[x; Lam x + lam0; 1]``."""
    T = np.zeros((n + P + 1, d_old))
    T[:n, :n] = np.eye(n)
    T[n:n + P, :n] = Lam
    T[n:n + P, -1] = lam0
    T[-1, -1] = 1.0
    return T


def evaluate_table(problem: Problem, table: GainTable, *, propagator="exact",
                   substeps: int = 4, path: bool = True) -> Moments:
    """Exact moments of the controller as implemented: ZOH at the table's tick rate, with the
    table's (quantized) values, latched at each stage's first tick.

    Parameters
    ----------
    propagator : {"exact", "euler"}
        "exact" propagates the SDE exactly; "euler" reproduces the Monte Carlo plant scheme
        with `substeps` steps per tick, so the difference is the simulation bias.
    """
    n, m, P = table.dims
    h = 1.0 / table.tick_hz
    d_y, d_z = n + P + 1, n + m + P + 1
    x0 = problem.x0
    y0 = np.concatenate([x0, np.zeros(P), [1.0]])
    M = np.outer(y0, y0)
    J = 0.0
    means, covs, cons = [], [], []
    path_mean = [x0.copy()] if path else []
    keep = np.r_[0:n, n + m:d_z]           # z -> y: drop u
    for k in range(table.n_stages):
        stage = problem.stages[k]
        Lam = table.Lambda[k].astype(float)
        lam0 = table.lambda0[k].astype(float)
        T = _latch_transform(n, P, Lam, lam0, d_y)
        M = T @ M @ T.T
        prop = (exact_tick(stage, m + P + 1, h) if propagator == "exact"
                else euler_tick(stage, m + P + 1, h, substeps))
        cost_row = _running_cost_matrix(stage, n, m, d_z, n).ravel() @ prop.Psi
        for j in range(int(table.stage_start[k]), int(table.stage_start[k + 1])):
            F = np.zeros((m, d_y))
            F[:, :n] = -table.K[j]
            F[:, n:n + P] = -table.L[j]
            F[:, -1] = -table.k0[j]
            Tz = np.zeros((d_z, d_y))
            Tz[:n, :n] = np.eye(n)
            Tz[n:n + m] = F
            Tz[n + m:, n:] = np.eye(P + 1)
            Mz = Tz @ M @ Tz.T
            J += cost_row @ Mz.ravel()
            Mz = (prop.Phi @ Mz.ravel()).reshape(d_z, d_z)
            M = Mz[np.ix_(keep, keep)]
            if path:
                path_mean.append(M[:n, -1].copy())
        pen, mean, cov, con = _knot_terms(problem, k, M, n)
        J += pen
        means.append(mean); covs.append(cov); cons.append(con)
    path_t = problem.t0 + np.arange(table.n_ticks + 1) * h if path else np.zeros(0)
    return Moments(float(J), means, covs, cons, path_t, np.array(path_mean))


def evaluate_continuous(problem: Problem, design: ContinuousDesign, *, rtol: float = 1e-12,
                        atol: float = 1e-14, points_per_stage: int = 0) -> Moments:
    """Exact moments of a continuous design's latched law ``u = -K(t)x - k0(t) - L(t) v``
    applied to `problem`'s plant (which may differ from the plant it was designed for)."""
    n, m = problem.n, problem.m
    x0 = problem.x0
    J = 0.0
    means, covs, cons = [], [], []
    pts_t, pts_m = [], []
    M = None
    for k, st in enumerate(design.stages):
        stage = problem.stages[k]
        p = st.n_constraints
        d = n + p + 1
        if M is None:
            y0 = np.concatenate([x0, np.zeros(p), [1.0]])
            M_old, d_old = np.outer(y0, y0), d
        else:
            M_old, d_old = M, M.shape[0]
        M = (T := _latch_transform(n, p, st.Lambda, st.lambda0, d_old)) @ M_old @ T.T
        noise = _noise_columns(stage.G, d)
        Lb = _running_cost_matrix(stage, n, m, n + m + 1, n)
        base = np.zeros((d, d))
        base[:n, :n] = stage.A

        def rhs(t, y, st=st, stage=stage, p=p, d=d, noise=noise, Lb=Lb, base=base):
            Mt = y[:-1].reshape(d, d)
            K, k0, L = st.gains(np.array([t]))
            F = np.concatenate([-K[0], -L[0], -k0[0][:, None]], axis=1)   # u = F y
            Abar = base.copy()
            Abar[:n] += stage.B @ F
            AM = Abar @ Mt
            dM = AM + AM.T + (noise @ y[:-1]).reshape(d, d)
            Tw = np.zeros((n + m + 1, d))
            Tw[:n, :n] = np.eye(n)
            Tw[n:n + m] = F
            Tw[-1, -1] = 1.0
            dJ = np.sum((Tw.T @ Lb @ Tw) * Mt)
            return np.concatenate([dM.ravel(), [dJ]])

        t_eval = (np.linspace(st.t_start, st.t_end, points_per_stage)
                  if points_per_stage else None)
        res = solve_ivp(rhs, (st.t_start, st.t_end), np.concatenate([M.ravel(), [0.0]]),
                        method="DOP853", rtol=rtol, atol=atol, t_eval=t_eval)
        if res.status != 0:
            raise RuntimeError(f"moment integration failed on stage {k}: {res.message}")
        M = res.y[:-1, -1].reshape(d, d)
        M = 0.5 * (M + M.T)
        J += res.y[-1, -1]
        if points_per_stage:
            pts_t.append(res.t)
            pts_m.append(res.y[:-1].reshape(d, d, -1)[:n, -1, :].T)
        pen, mean, cov, con = _knot_terms(problem, k, M, n)
        J += pen
        means.append(mean); covs.append(cov); cons.append(con)
    path_t = np.concatenate(pts_t) if pts_t else np.zeros(0)
    path_mean = np.concatenate(pts_m) if pts_m else np.zeros((0, n))
    return Moments(float(J), means, covs, cons, path_t, path_mean)
