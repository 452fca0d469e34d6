"""Exact sampled-data design: the optimal latched law for a controller that updates ``u`` at
ticks of period ``h`` and holds it in between (stage-wise or joint multipliers).

Conditioned on the state at a tick, one tick maps ``zz'`` (``z = [x; u; 1]``) to the exact
second moment after it and to the exact expected running cost (`moments.exact_tick`), and
``E x+ = F z`` with ``F = [e^{Ah}, Gamma, 0]``. A value after the tick

    x'Px + 2p'x + c + 2 lambda'(N'x + m) - lambda'W lambda      (lambda: latched multipliers)

is therefore exactly, before it, ``z'Hz + 2 lambda'(N'F z + m e') - lambda'W lambda`` with
``H = mat(Phi' vec([[P, p], [p', c]] on x,1)) + mat(Psi' vec(Lbar))``. Minimising over ``u``
is a Riccati recursion over ticks with ``u = -K x - k0 - L lambda``. At a latching stage start
``lambda = W^-1 (N'x + m)`` is substituted, as in continuous time: for each fixed start state
the problem is convex in the policy and Lagrangian duality is exact.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scipy.linalg import expm

from .design import DesignError, _check_group, _knot_terminal, _value
from .moments import augmented_drift, exact_tick, running_cost_matrix
from .multipliers import latch_groups
from .problem import Problem, Stage
from .tables import GainTable, build_table, ticks_per_stage

__all__ = ["ZohStage", "ZohDesign", "design_zoh"]


@dataclass
class ZohStage:
    """Per-tick gains of one stage and its start-of-stage value data (see `design._value`)."""
    index: int
    K: np.ndarray        # (T, m, n)
    k0: np.ndarray       # (T, m)
    L: np.ndarray        # (T, m, p): p = width of the multiplier vector acting on the stage
    P0: np.ndarray
    p0: np.ndarray
    c0: float
    N0: np.ndarray
    W0: np.ndarray
    m0: np.ndarray
    Lambda: np.ndarray   # (p, n) if the stage latches, else (0, n)
    lambda0: np.ndarray

    @property
    def n_constraints(self) -> int:
        return self.L.shape[2]


@dataclass
class ZohDesign:
    """The optimal zero-order-hold law at `tick_hz` for a `Problem`."""
    problem: Problem
    tick_hz: int
    stages: list[ZohStage]
    noise_aware: bool
    mode: str = "stagewise"

    @property
    def J0(self) -> float:
        """Predicted optimal expected cost from ``(t0, x0)`` of the law at this tick rate."""
        return self.cost_to_go(0, self.problem.x0)

    def cost_to_go(self, k: int, x: np.ndarray, v: np.ndarray | None = None) -> float:
        """Optimal expected cost from `x` at the start of stage k (`v`: an earlier latch)."""
        return _value(self.stages[k], np.asarray(x, dtype=float), v)

    def table(self, *, quantize: bool = True) -> GainTable:
        return build_table(self.problem, self.tick_hz,
                           [(s.K, s.k0, s.L, s.Lambda, s.lambda0) for s in self.stages],
                           quantize=quantize)


def _sym(a: np.ndarray) -> np.ndarray:
    return 0.5 * (a + a.T)


@dataclass(frozen=True)
class _TickData:
    """Per-stage constants of the tick recursion (d = n + m + 1)."""
    A2: np.ndarray      # (d*d, (n+1)^2): vec([[P, p], [p', c]]) -> vec(H) before the tick
    Hc: np.ndarray      # (d, d): expected running cost over the tick, as a quadratic in z
    F: np.ndarray       # (n, d): E x+ = F z


def _tick_data(stage: Stage, h: float) -> _TickData:
    n, m = stage.B.shape
    d = n + m + 1
    prop = exact_tick(stage, m + 1, h)
    Hc = _sym((prop.Psi.T @ running_cost_matrix(stage, n, m, d, n).ravel()).reshape(d, d))
    xs1 = np.r_[0:n, d - 1]
    idx = (xs1[:, None] * d + xs1[None, :]).ravel()
    F = expm(augmented_drift(stage, m + 1) * h)[:n]
    return _TickData(np.ascontiguousarray(prop.Phi.T[:, idx]), Hc, F)


def _stage_key(stage: Stage, h: float) -> bytes:
    return b"".join(np.ascontiguousarray(a, float).tobytes() for a in
                    (stage.A, stage.B, stage.G, stage.Q, stage.S, stage.R, stage.q, stage.r,
                     np.array([stage.rho, h])))


def design_zoh(problem: Problem, tick_hz: int | None = None, *, noise: bool = True,
               mode: str = "stagewise") -> ZohDesign:
    """Solve the exact sampled-data design at `tick_hz` (default: the problem's).

    Parameters
    ----------
    problem : Problem
    tick_hz : int, optional
        Controller rate; must divide every stage length.
    noise : bool
        False designs as if the diffusion were absent (the paper's Remark 2).
    mode : {"stagewise", "joint"}
        See `multipliers`.

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
    d = n + m + 1
    us, rs = np.arange(n, n + m), np.r_[0:n, d - 1]
    _, group_of = latch_groups(problem, mode)
    cache: dict[bytes, _TickData] = {}
    V = np.zeros((n + 1, n + 1))          # [[P, p], [p', c]] after the current point
    N = W = mv = None                      # open multiplier group
    out: list[ZohStage | None] = [None] * len(problem.knots)
    for k in range(len(problem.knots) - 1, -1, -1):
        knot, g = problem.knots[k], group_of[k]
        stage = problem.stages[k] if noise else problem.stages[k].without_noise()
        PT, pT, cT = _knot_terminal(knot, V[:n, :n], V[:n, n], V[n, n])
        V = np.block([[PT, pT[:, None]], [pT[None, :], np.array([[cT]])]])
        q = 0 if g is None else g.size
        if g is not None:
            if N is None or N.shape[1] != q:     # a new group (an unconstrained stage
                # after it leaves zero-width arrays behind)
                N, W, mv = np.zeros((n, q)), np.zeros((q, q)), np.zeros(q)
            if knot.n_constraints:
                o = g.offset_of(k)
                N = N.copy(); mv = mv.copy()
                N[:, o:o + knot.n_constraints] += knot.constraint.C.T
                mv[o:o + knot.n_constraints] -= knot.constraint.value
        else:
            N, W, mv = np.zeros((n, 0)), np.zeros((0, 0)), np.zeros(0)
        key = _stage_key(stage, h)
        td = cache.get(key) or cache.setdefault(key, _tick_data(stage, h))
        T = int(counts[k])
        K = np.empty((T, m, n)); k0 = np.empty((T, m)); L = np.empty((T, m, q))
        for j in range(T - 1, -1, -1):
            H = (td.A2 @ V.ravel()).reshape(d, d)
            H = 0.5 * (H + H.T) + td.Hc
            Hl = N.T @ td.F                                  # (q, d)
            Hl[:, -1] += mv
            Huu = H[np.ix_(us, us)]
            Hur = H[np.ix_(us, rs)]
            Hlu = Hl[:, us]
            try:
                G = np.linalg.solve(Huu, np.hstack([Hur, Hlu.T]))
            except np.linalg.LinAlgError:
                raise DesignError(f"knots[{k}].t", f"the tick Riccati recursion of stage {k} "
                                                   f"lost positive definiteness") from None
            Gr, Gl = G[:, :n + 1], G[:, n + 1:]
            K[j], k0[j], L[j] = Gr[:, :n], Gr[:, n], Gl
            V = _sym(H[np.ix_(rs, rs)] - Hur.T @ Gr)
            Hlr = Hl[:, rs] - Hlu @ Gr
            N, mv = Hlr[:, :n].T, Hlr[:, n]
            W = _sym(W + Hlu @ Gl)
        if not (np.all(np.isfinite(V)) and np.all(np.isfinite(W))):
            raise DesignError(f"knots[{k}].t", f"the tick Riccati recursion of stage {k} has "
                                               f"no bounded solution in floating point")
        st = ZohStage(k, K, k0, L, V[:n, :n].copy(), V[:n, n].copy(), float(V[n, n]),
                      N, W, mv, np.zeros((0, n)), np.zeros(0))
        if g is not None and g.latch_stage == k:
            _check_group(W, problem, g)
            st.Lambda, st.lambda0 = np.linalg.solve(W, N.T), np.linalg.solve(W, mv)
            NL = N @ st.Lambda
            V = V.copy()
            V[:n, :n] += 0.5 * (NL + NL.T)
            V[:n, n] += N @ st.lambda0
            V[n, :n] = V[:n, n]
            V[n, n] += mv @ st.lambda0
            N = W = mv = None
        out[k] = st
    return ZohDesign(problem, tick_hz, out, noise, mode)
