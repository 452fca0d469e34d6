"""Exact sampled-data design: the optimal stage-wise latched law for a controller that updates
``u`` at ticks of period ``h`` and holds it in between.

Conditioned on the state at a tick, one tick maps ``zz'`` (``z = [x; u; lambda; 1]``, the
multiplier ``lambda`` a constant of the stage) to the exact second moment after the tick and
to the exact expected running cost (`moments.exact_tick`). A quadratic value ``y' V y`` of
``y = [x; lambda; 1]`` after the tick is therefore exactly the quadratic ``z' H z`` before it,

    H = mat(Phi' vec(E' V E)) + mat(Psi' vec(Lbar)),

and minimising over ``u`` is a Riccati recursion over ticks: ``u = -Huu^-1 Hur y`` and
``V = Hrr - Hru Huu^-1 Hur``. The stage's terminal value adds ``2 lambda'(C2 x - zeta)``; at the
stage start ``V = [[P, N, p], [N', -W, m], [p', m', c]]`` and the maximising multiplier is
``lambda = W^-1 (N' x + m)``, exactly as in continuous time (Lagrangian duality holds for each
fixed start state because the problem is convex in the policy).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .design import DesignError, _check_latch, _knot_terminal
from .moments import exact_tick, running_cost_matrix
from .problem import Problem
from .tables import GainTable, build_table, ticks_per_stage

__all__ = ["ZohStage", "ZohDesign", "design_zoh"]


@dataclass
class ZohStage:
    """Per-tick gains of one stage and its start-of-stage value data."""
    K: np.ndarray        # (T, m, n)
    k0: np.ndarray       # (T, m)
    L: np.ndarray        # (T, m, p)
    P0: np.ndarray
    p0: np.ndarray
    c0: float
    N0: np.ndarray
    W0: np.ndarray
    m0: np.ndarray
    Lambda: np.ndarray
    lambda0: np.ndarray

    @property
    def n_constraints(self) -> int:
        return self.Lambda.shape[0]


@dataclass
class ZohDesign:
    """The optimal zero-order-hold law at `tick_hz` for a `Problem`."""
    problem: Problem
    tick_hz: int
    stages: list[ZohStage]
    noise_aware: bool

    @property
    def J0(self) -> float:
        """Predicted optimal expected cost from ``(t0, x0)`` of the law at this tick rate."""
        return self.cost_to_go(0, self.problem.x0)

    def cost_to_go(self, k: int, x: np.ndarray) -> float:
        st = self.stages[k]
        x = np.asarray(x, dtype=float)
        val = x @ st.P0 @ x + 2 * st.p0 @ x + st.c0
        if st.n_constraints:
            e = st.N0.T @ x + st.m0
            val += e @ np.linalg.solve(st.W0, e)
        return float(val)

    def table(self, *, quantize: bool = True) -> GainTable:
        return build_table(self.problem, self.tick_hz,
                           [(s.K, s.k0, s.L, s.Lambda, s.lambda0) for s in self.stages],
                           quantize=quantize)


def _sym(a: np.ndarray) -> np.ndarray:
    return 0.5 * (a + a.T)


def design_zoh(problem: Problem, tick_hz: int | None = None, *,
               noise: bool = True) -> ZohDesign:
    """Solve the exact sampled-data stage-wise design at `tick_hz` (default: the problem's).

    Parameters
    ----------
    problem : Problem
    tick_hz : int, optional
        Controller rate; must divide every stage length.
    noise : bool
        False designs as if the diffusion were absent (the paper's Remark 2).

    Returns
    -------
    ZohDesign
    """
    tick_hz = problem.tick_hz if tick_hz is None else int(tick_hz)
    try:
        counts = ticks_per_stage(problem, tick_hz)
    except ValueError as exc:
        raise DesignError("tick_hz", str(exc)) from None
    h = 1.0 / tick_hz
    n, m = problem.n, problem.m
    P_next, p_next, c_next = np.zeros((n, n)), np.zeros(n), 0.0
    out: list[ZohStage | None] = [None] * len(problem.knots)
    for k in range(len(problem.knots) - 1, -1, -1):
        knot = problem.knots[k]
        stage = problem.stages[k] if noise else problem.stages[k].without_noise()
        p = knot.n_constraints
        dy, dz = n + p + 1, n + m + p + 1
        PT, pT, cT = _knot_terminal(knot, P_next, p_next, c_next)
        V = np.zeros((dy, dy))
        V[:n, :n], V[:n, -1], V[-1, :n], V[-1, -1] = PT, pT, pT, cT
        if p:
            C2, zeta = knot.constraint.C, knot.constraint.value
            V[:n, n:n + p], V[n:n + p, :n] = C2.T, C2
            V[n:n + p, -1] = V[-1, n:n + p] = -zeta
        prop = exact_tick(stage, m + p + 1, h)
        PhiT, cost_H = prop.Phi.T, (prop.Psi.T @ running_cost_matrix(stage, n, m, dz, n).ravel())
        cost_H = _sym(cost_H.reshape(dz, dz))
        us = np.arange(n, n + m)
        rs = np.r_[0:n, n + m:dz]            # y = [x; lambda; 1] inside z
        T = int(counts[k])
        K = np.zeros((T, m, n)); k0 = np.zeros((T, m)); L = np.zeros((T, m, p))
        Vz = np.zeros((dz, dz))
        for j in range(T - 1, -1, -1):
            Vz[np.ix_(rs, rs)] = V
            H = _sym((PhiT @ Vz.ravel()).reshape(dz, dz)) + cost_H
            Huu = H[np.ix_(us, us)]
            Hur = H[np.ix_(us, rs)]
            try:
                G = np.linalg.solve(Huu, Hur)
            except np.linalg.LinAlgError:
                raise DesignError(f"knots[{k}].t", f"the tick Riccati recursion of stage {k} "
                                                   f"lost positive definiteness") from None
            V = _sym(H[np.ix_(rs, rs)] - Hur.T @ G)
            K[j], L[j], k0[j] = G[:, :n], G[:, n:n + p], G[:, -1]
            if not np.all(np.isfinite(V)):
                raise DesignError(f"knots[{k}].t", f"the tick Riccati recursion of stage {k} "
                                                   f"has no bounded solution")
        P0, N0, p0 = V[:n, :n], V[:n, n:n + p], V[:n, -1]
        W0, m0, c0 = -V[n:n + p, n:n + p], V[n:n + p, -1], V[-1, -1]
        if p:
            _check_latch(W0, knot.constraint.C, k)
            Lam, lam0 = np.linalg.solve(W0, N0.T), np.linalg.solve(W0, m0)
        else:
            Lam, lam0 = np.zeros((0, n)), np.zeros(0)
        out[k] = ZohStage(K, k0, L, P0, p0, float(c0), N0, W0, m0, Lam, lam0)
        P_next, p_next, c_next = P0.copy(), p0.copy(), float(c0)
        if p:
            P_next, p_next, c_next = _sym(P0 + N0 @ Lam), p0 + N0 @ lam0, c0 + m0 @ lam0
    return ZohDesign(problem, tick_hz, out, noise)
