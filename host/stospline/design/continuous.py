"""Continuous-time stage-wise design (the paper's Proposition 3, corrected per docs/theory/math.md).

Backward on each stage ``[t_k, t_{k+1}]``, with ``K = R^-1 (P B + S)'`` and ``Acl = A - B K``
(drift ``A x + B u + f``)::

    -P' = A'P + PA + Q + Pi(P) - (PB+S) R^-1 (PB+S)'      Pi(P)_kl = tr(G_k' P G_l)
    -p' = Acl' p + q - K' r + P f
    -c' = rho - (B'p + r)' R^-1 (B'p + r) + 2 p'f
    -N' = Acl' N                     N(t_{k+1}) = C2'
     W' = -N' B R^-1 B' N            W(t_{k+1}) = 0
     m' = N' B R^-1 (B'p + r) - N'f  m(t_{k+1}) = -zeta

At the stage start the controller latches ``v = W^-1 (N' x + m)`` and applies
``u = -K x - R^-1 (B'p + r) - R^-1 B' N v`` until the next stage start.

A stage whose data are constant and whose equations carry no noise is solved exactly from the
exponential of its Hamiltonian (`HamiltonianSolution`); the others are integrated with DOP853.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from stospline.expm import require_finite
from stospline.design.latch import latch_groups
from stospline.design.stage_values import (StageStart, StageValues, check_group,
                                           knot_terminal)
from stospline.errors import DesignError, ProblemError
from stospline.problem.model import Problem, Stage, ticks_per_stage

__all__ = ["DesignError", "StageSolution", "ContinuousDesign", "HamiltonianSolution",
           "design_continuous", "noise_operator"]


def noise_operator(G: np.ndarray, P: np.ndarray) -> np.ndarray:
    """``Pi(P)_kl = tr(G_k' P G_l)``: the Ito correction of ``x'Px`` under ``sum x_i G_i dZ``.

    Only the multipliers with a nonzero ``G_k`` contribute (none: zeros, no product), and those
    column by column as matrix products, ``sum_i G[:, :, i] P G[:, :, i]'``: O(mz na n (n +
    na)) for na live multipliers instead of a four-index loop over all of them."""
    out = np.zeros((G.shape[0], G.shape[0]))
    live = np.flatnonzero(G.any(axis=(1, 2)))
    if live.size:
        Gl = np.moveaxis(G[live], 2, 0)                   # (mz, na, n)
        out[np.ix_(live, live)] = (Gl @ P @ np.swapaxes(Gl, 1, 2)).sum(axis=0)
    return out


@dataclass
class StageSolution(StageStart):
    """Solution of the backward equations on one stage.

    ``n_constraints`` is the width of the multiplier vector acting on this stage. If the stage
    latches, ``Lambda`` (p x n) and ``lambda0`` (p) form the latch map
    ``v = Lambda x + lambda0``; otherwise they are empty and the earlier latch is kept.
    """
    index: int
    t_start: float
    t_end: float
    n_constraints: int
    stage: Stage
    _sol: object
    latches: bool = False
    noise: bool = True       # the design accounts for the diffusion (False: Remark 2)

    def _unpack(self, y: np.ndarray):
        n, p = self.stage.A.shape[0], self.n_constraints
        i = 0
        P = y[i:i + n * n].reshape((n, n) + y.shape[1:]); i += n * n
        pv = y[i:i + n]; i += n
        c = y[i]; i += 1
        N = y[i:i + n * p].reshape((n, p) + y.shape[1:]); i += n * p
        W = y[i:i + p * p].reshape((p, p) + y.shape[1:]); i += p * p
        m = y[i:i + p]
        return P, pv, c, N, W, m

    def gains_at(self, t: float):
        """``K`` (m, n), ``k0`` (m,) and ``L`` (m, p) at one time ``t``: what the oracle's
        right-hand side asks for at every step of its integrator, so the stage's fixed weights
        and ``R^-1`` are computed once (`_fixed_weights`) and the dense output is evaluated at
        a scalar (no stacks)."""
        if isinstance(self._sol, HamiltonianSolution):     # u = -Ka [x; 1; v]
            Ka = self._sol.feedback(t)
            n = self.stage.A.shape[0]
            return Ka[:, :n], Ka[:, n], Ka[:, n + 1:]
        P, pv, _, N, _, _ = self._unpack(self._sol(t))
        fixed = self._fixed_weights
        if fixed is not None:
            s, St, Rinv = self.stage, fixed[0], fixed[1]
        else:
            s = self.stage.at(t)
            _, St, Rt = _effective_weights(s, P, self.noise)
            Rinv = np.linalg.inv(Rt)
        return Rinv @ (P @ s.B + St).T, Rinv @ (s.B.T @ pv + s.r), Rinv @ (s.B.T @ N)

    @functools.cached_property
    def _fixed_weights(self):
        """``(S, R^-1)`` when they are the same at every time (constant data, and no noise the
        design accounts for: the Ito term then adds exact zeros), else None."""
        s = self.stage
        if s.varying is not None or (self.noise and s.noise_tensor.any()):
            return None
        return s.S, np.linalg.inv(s.R)

    def riccati(self, t: np.ndarray):
        """P, p, c, N, W, m at times ``t`` (arrays with time as the last axis)."""
        return self._unpack(self._sol(np.atleast_1d(t)))

    def gains(self, t: np.ndarray):
        """Feedback ``K`` (T, m, n), feed-forward ``k0`` (T, m) and multiplier gain ``L`` (T, m, p).

        The control is ``u = -K x - k0 - L v``.
        """
        if np.size(t) == 1:               # one time: no stacks
            return tuple(g[None] for g in self.gains_at(float(np.ravel(t)[0])))
        P, pv, _, N, _, _ = self.riccati(t)
        P, pv, N = np.moveaxis(P, -1, 0), pv.T, np.moveaxis(N, -1, 0)   # time first
        d = _stacked_data(self.stage, np.atleast_1d(t))
        n = P.shape[1]
        St, Rt = d["S"], d["R"]
        if self.noise:
            Pi = _noise_operator_many(np.concatenate(
                [d["G"], d["H"] if d["H"] is not None else
                 np.zeros(d["R"].shape[:2] + d["G"].shape[2:])], axis=1), P)
            St, Rt = St + Pi[:, :n, n:], Rt + Pi[:, n:, n:]
        Rinv = np.linalg.inv(Rt)
        Bt = np.swapaxes(d["B"], 1, 2)
        K = Rinv @ np.swapaxes(P @ d["B"] + St, 1, 2)
        k0 = (Rinv @ (Bt @ pv[:, :, None] + d["r"][:, :, None]))[:, :, 0]
        L = Rinv @ (Bt @ N)
        return K, k0, L


@dataclass
class ContinuousDesign(StageValues):
    """The optimal continuous-time law for a `Problem`, stage by stage."""
    problem: Problem
    stages: list[StageSolution]
    noise_aware: bool
    mode: str = "stagewise"

    def gains(self, k: int, t):
        return self.stages[k].gains(t)

    def tick_gains(self, tick_hz: int | None = None) -> tuple[int, list[tuple]]:
        """Per-stage ``(K, k0, L, Lambda, lambda0)`` sampled at the tick starts (the table
        holds each for one tick), at `tick_hz` (None: the problem's): the
        `stospline.table.format.TickGains` interface."""
        prob = self.problem
        tick_hz = prob.tick_hz if tick_hz is None else int(tick_hz)
        counts = ticks_per_stage(prob, tick_hz)
        return tick_hz, [(*st.gains(prob.times[k] + np.arange(counts[k]) / tick_hz),
                          st.Lambda, st.lambda0) for k, st in enumerate(self.stages)]


def _stacked_data(stage: Stage, t: np.ndarray) -> dict:
    """The stage's B, S, R, r, G, H at the times `t` on a first axis (`Stage.samples`), or, for
    a stage whose data do not vary, once on an axis of length 1 that the products broadcast."""
    if stage.varying is not None:
        return stage.samples(t)
    return {k: None if getattr(stage, k) is None else np.asarray(getattr(stage, k), float)[None]
            for k in ("B", "S", "R", "r", "G", "H")}


def _noise_operator_many(G: np.ndarray, P: np.ndarray) -> np.ndarray:
    """`noise_operator` at every time of a stack: G (T or 1, k, n, mz), P (T, n, n) -> (T, k,
    k)."""
    k = G.shape[1]
    out = np.zeros((P.shape[0], k, k))
    live = np.flatnonzero(G.any(axis=(0, 2, 3)))
    if live.size:
        Gl = np.moveaxis(G[:, live], 3, 1)                # (T or 1, mz, na, n)
        prod = (Gl @ P[:, None] @ np.swapaxes(Gl, 2, 3)).sum(axis=1)
        out[:, live[:, None], live[None, :]] = prod
    return out


def _effective_weights(stage: Stage, P: np.ndarray, noise: bool):
    """``Q + Pi_xx(P)``, ``S + Pi_xu(P)``, ``R + Pi_uu(P)`` with ``Pi_ab = tr(Gh_a' P Gh_b)`` over
    the noise multipliers ``[x; u]``: the Ito term of ``x'Px`` under the full diffusion."""
    if not noise:
        return stage.Q, stage.S, stage.R
    n = stage.A.shape[0]
    Pi = noise_operator(stage.noise_tensor, P)
    return stage.Q + Pi[:n, :n], stage.S + Pi[:n, n:], stage.R + Pi[n:, n:]


def _stage_rhs(stage: Stage, n: int, p: int, noise: bool):
    # Without noise and with constant data the weights, and so R^-1, are the same at every call.
    fixed = stage.varying is None and not (noise and stage.noise_tensor.any())
    Rinv_fixed = np.linalg.inv(stage.R) if fixed else None

    def rhs(t, y):
        st = stage.at(t)
        A, B, q, r, rho = st.A, st.B, st.q, st.r, st.rho
        i = 0
        P = y[i:i + n * n].reshape(n, n); i += n * n
        pv = y[i:i + n]; i += n
        i += 1
        N = y[i:i + n * p].reshape(n, p); i += n * p
        i += p * p
        if fixed:
            Qt, St, Rinv = st.Q, st.S, Rinv_fixed
        else:
            Qt, St, Rt = _effective_weights(st, P, noise)
            Rinv = np.linalg.inv(Rt)
        PBS = P @ B + St
        K = Rinv @ PBS.T
        Acl = A - B @ K
        dP = A.T @ P + P @ A + Qt - PBS @ K
        dP = -0.5 * (dP + dP.T)
        g = B.T @ pv + r
        dp = -(Acl.T @ pv + q - K.T @ r)
        dc = -(rho - g @ Rinv @ g)
        if st.f is not None:          # the drift f: E d(x'Px + 2p'x) gains 2(Px + p)'f dt
            dp -= P @ st.f
            dc -= 2.0 * (pv @ st.f)
        dN = -(Acl.T @ N)
        BtN = B.T @ N
        dW = -(BtN.T @ Rinv @ BtN)
        dm = BtN.T @ Rinv @ g
        if st.f is not None:          # ... and E d(N'x) gains N'f dt
            dm = dm - N.T @ st.f
        return np.concatenate([dP.ravel(), dp, [dc], dN.ravel(), dW.ravel(), dm])

    return rhs


_MAX_PER = 64      # ticks between a HamiltonianSolution's nodes, at most


class HamiltonianSolution:
    """The backward equations of one stage with constant data and no noise the design accounts
    for, solved exactly instead of integrated: a callable ``y(t)`` with the layout of
    `_stage_rhs`'s state (as `solve_ivp`'s dense output).

    On the augmented state ``a = [x; 1; v]`` the equations are one Riccati equation (drift
    ``[[A, f, 0], 0, 0]``, input ``[B; 0; 0]``, weights ``[[Q, q, 0], [q', rho, 0], 0]``, cross
    weight ``[S; r'; 0]``) whose solution is ``Pa = [[P, p, N], [p', c, m'], [N', m, -W]]``.
    With the Hamiltonian ``Hm`` of that equation, ``[X; Y](t) = exp(Hm (t - s)) [I; Pa(s)]``
    gives ``Pa(t) = Y X^-1`` exactly, and ``X(t)`` is the closed loop's transition of ``a``
    from ``s`` to ``t``. The solution is kept at nodes a whole number of ticks apart, at most
    ``0.5 / |Hm|_1`` s (each step's exponential is then well conditioned); between nodes the
    exponential at a multiple of the tick is a power of the tick's. A stage stiff for one tick
    (``|Hm|_1 h > 2``) is not solved (`usable` False): the design integrates it."""

    def __init__(self, stage: Stage, n: int, p: int, Pa_end: np.ndarray, t0: float, t1: float,
                 tick_hz: int):
        from stospline.expm import expm
        m = stage.B.shape[1]
        na = n + 1 + p
        Aa, Ba = np.zeros((na, na)), np.zeros((na, m))
        Aa[:n, :n], Ba[:n] = stage.A, stage.B
        if stage.f is not None:
            Aa[:n, n] = stage.f
        Qa, Sa = np.zeros((na, na)), np.zeros((na, m))
        Qa[:n, :n], Qa[:n, n], Qa[n, :n], Qa[n, n] = stage.Q, stage.q, stage.q, stage.rho
        Sa[:n], Sa[n] = stage.S, stage.r
        Rinv = np.linalg.inv(stage.R)
        At = Aa - Ba @ Rinv @ Sa.T
        Hm = np.block([[At, -Ba @ Rinv @ Ba.T], [-(Qa - Sa @ Rinv @ Sa.T), -At.T]])
        self.n, self.p, self.na, self.Hm = n, p, na, Hm
        self.norm = float(np.abs(Hm).sum(axis=0).max())
        self.stage, self.Aa, self.Ba, self.Qa, self.Sa, self.Rinv = stage, Aa, Ba, Qa, Sa, Rinv
        h = 1.0 / tick_hz
        # Stiff for one tick (|Hm| h > 2): the step's exponential would amplify rounding;
        # the caller integrates instead.
        self.usable = self.norm * h <= 2.0
        if not self.usable:
            return
        ticks = max(1, int(round((t1 - t0) * tick_hz)))
        per = max(1, min(ticks, _MAX_PER, int(0.5 / max(self.norm * h, 1e-300))))
        node_ticks = np.unique(np.r_[0:ticks:per, ticks])
        self.t0, self.h, self.node_ticks = t0, h, node_ticks
        self.nodes = t0 + node_ticks * h
        self.nodes[-1] = t1
        # exp(-Hm l h) for l = 0 .. per: the steps between nodes and the points between them.
        step = expm(-Hm * h)
        powers = [np.eye(2 * na), step]
        for _ in range(per - 1):
            powers.append(step @ powers[-1])
        self.powers = np.array(powers)
        # Between ticks (at most half a tick from one): exp(-Hm s) Z = sum_k s^k Hk Z with
        # Hk = (-Hm)^k / k!, as many terms as reach 1e-17 at |Hm| h / 2.
        terms, bound, norm = [np.eye(2 * na)], 1.0, self.norm * h / 2
        while len(terms) < 30 and bound > 1e-17:
            terms.append(-Hm @ terms[-1] / len(terms))
            bound *= norm / len(terms)
        self.taylor = np.vstack(terms)
        Pa = np.empty((len(node_ticks), na, na))
        Pa[-1] = Pa_end
        with np.errstate(over="ignore", invalid="ignore"):
            for i in range(len(node_ticks) - 2, -1, -1):
                Pa[i] = self._back(self.powers[node_ticks[i + 1] - node_ticks[i]], Pa[i + 1])
        self.Pa = Pa

    def _back(self, E: np.ndarray, P: np.ndarray) -> np.ndarray:
        """``Pa`` earlier by the steps ``E = exp(-Hm tau)`` from ``P`` (stacks: (..., 2na, 2na)
        and (..., na, na))."""
        na = self.na
        X = E[..., :na, :na] + E[..., :na, na:] @ P
        Y = E[..., na:, :na] + E[..., na:, na:] @ P
        out = np.linalg.solve(np.swapaxes(X, -1, -2), np.swapaxes(Y, -1, -2))  # (Y X^-1)'
        return 0.5 * (out + np.swapaxes(out, -1, -2))

    def feedback(self, t: float) -> np.ndarray:
        """``Ka = R^-1 (Ba' Pa + Sa')`` at one time: the law ``u = -Ka [x; 1; v]``."""
        X, Y = self._flow(t)
        # Ka = R^-1 (Ba' Y + Sa' X) X^-1
        return self.Rinv @ np.linalg.solve(X.T, (self.Ba.T @ Y + self.Sa.T @ X).T).T

    def _flow(self, t: float):
        """``[X; Y] = exp(-Hm tau) [I; Pa(s)]`` from the node ``s`` at or after one time ``t``
        (``tau = s - t``): a power of the tick's exponential to the nearest tick, then the
        Taylor series of the rest (at most half a tick)."""
        import bisect
        j = min(bisect.bisect_left(self.nodes, t), len(self.nodes) - 1)
        na, tau = self.na, self.nodes[j] - t
        whole = min(max(round(tau / self.h), 0), len(self.powers) - 1)
        rest = tau - whole * self.h
        E = self.powers[whole]
        Z = E[:, :na] + E[:, na:] @ self.Pa[j]
        if rest != 0.0:
            if abs(rest) * self.norm > 0.5:             # outside the stage (extrapolation)
                from stospline.expm import expm
                Z = expm(-self.Hm * rest) @ Z
            else:
                k = self.taylor.shape[0] // (2 * na)
                Z = np.tensordot(rest ** np.arange(k),
                                 (self.taylor @ Z).reshape(k, 2 * na, na), 1)
        return Z[:na], Z[na:]

    def augmented(self, t) -> np.ndarray:
        """``Pa`` at the times `t` (T, na, na)."""
        if np.ndim(t) == 0 or np.size(t) == 1:          # one time
            X, Y = self._flow(float(np.ravel(t)[0]))
            out = np.linalg.solve(X.T, Y.T)
            return 0.5 * (out + out.T)[None]
        t = np.atleast_1d(np.asarray(t, dtype=float))
        j = np.clip(np.searchsorted(self.nodes, t, side="left"), 0, len(self.nodes) - 1)
        lag = (self.nodes[j] - t) / self.h              # ticks before the node, >= 0
        whole = np.rint(lag).astype(int)
        exact = ((np.abs(lag - whole) <= 1e-9 * np.maximum(1.0, lag)) & (whole >= 0)
                 & (whole < len(self.powers)))
        out = self._back(self.powers[np.where(exact, whole, 0)], self.Pa[j])
        for i in np.flatnonzero(~exact):                 # between ticks
            out[i] = self.augmented(t[i])[0]
        return out

    def closed_loop(self, Ma: np.ndarray):
        """The second moment of ``a = [x; 1; v]`` at the stage's end from `Ma` at its start,
        and the expected running cost over the stage, under this solution's law ``u = -Ka(t)
        a``, ``Ka = R^-1 (Ba' Pa + Sa')``, on the stage's own noise-free plant: between nodes
        ``a(s_i+1) = X^-1 a(s_i)`` with ``X = [I, 0] exp(-Hm tau) [I; Pa(s_i+1)]``, and the cost
        ``<Z' C Z, E a a'>`` with ``Z = [I; Pa(s_i+1)]`` and ``C = ∫_0^tau exp(-Hm's) Lz
        exp(-Hm s) ds`` (Van Loan), ``Lz`` the running cost of ``[a; u]`` as a quadratic in
        ``Z``."""
        from stospline.expm import expm
        na = self.na
        La = np.block([[self.Qa, self.Sa], [self.Sa.T, self.stage.R]])
        Mz = np.block([[np.eye(na), np.zeros((na, na))],
                       [-self.Rinv @ self.Sa.T, -self.Rinv @ self.Ba.T]])
        Lz = Mz.T @ La @ Mz
        cost = {}
        J = 0.0
        for i in range(len(self.node_ticks) - 1):
            ticks = int(self.node_ticks[i + 1] - self.node_ticks[i])
            E = self.powers[ticks]
            if ticks not in cost:
                tau = ticks * self.h
                big = np.block([[self.Hm.T * tau, Lz * tau],
                                [np.zeros((2 * na, 2 * na)), -self.Hm * tau]])
                F = expm(big)
                cost[ticks] = F[2 * na:, 2 * na:].T @ F[:2 * na, 2 * na:]
            P = self.Pa[i + 1]
            X = E[:na, :na] + E[:na, na:] @ P
            Y = np.linalg.solve(X, Ma)
            Ma = np.linalg.solve(X, Y.T)
            Ma = 0.5 * (Ma + Ma.T)
            Z = np.vstack([np.eye(na), P])
            J += float(np.sum((Z.T @ cost[ticks] @ Z) * Ma))
        return Ma, J

    def __call__(self, t):
        Pa = self.augmented(t)
        n, p = self.n, self.p
        x, v = slice(0, n), slice(n + 1, n + 1 + p)
        T = Pa.shape[0]
        y = np.concatenate([Pa[:, x, x].reshape(T, -1), Pa[:, x, n], Pa[:, n, n][:, None],
                            Pa[:, x, v].reshape(T, -1), -Pa[:, v, v].reshape(T, -1),
                            Pa[:, n, v]], axis=1).T
        return y[:, 0] if np.ndim(t) == 0 else y


def _solved_exactly(stage: Stage, noise: bool) -> bool:
    """Constant data and no noise in the equations: `HamiltonianSolution` solves the stage."""
    return stage.varying is None and not (noise and stage.noise_tensor.any())


def _augmented_end(PT, pT, cT, NT, WT, mT) -> np.ndarray:
    """``Pa = [[P, p, N], [p', c, m'], [N', m, -W]]`` (`HamiltonianSolution`) at a stage's end."""
    return np.block([[PT, pT[:, None], NT], [pT[None], np.array([[cT]]), mT[None]],
                     [NT.T, mT[:, None], -WT]])


def _solve_exactly(stage: Stage, n: int, p: int, Pa_end: np.ndarray, t0: float, t1: float,
                   tick_hz: int):
    """`_Solved` by a `HamiltonianSolution`, or None: stiff for one tick, or numbers that are
    not finite (the integration then reports the overflow)."""
    try:
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            sol = HamiltonianSolution(stage, n, p, Pa_end, t0, t1, tick_hz)
            if not sol.usable:
                return None
            y0 = sol(t0)
    except np.linalg.LinAlgError:
        return None
    return _Solved(sol, y0) if np.all(np.isfinite(y0)) else None


@dataclass
class _Solved:
    """`solve_ivp`'s result as the design reads it, for a `HamiltonianSolution`."""
    sol: HamiltonianSolution
    y_start: np.ndarray
    status: int = 0
    message: str = "solved exactly"

    @property
    def y(self) -> np.ndarray:
        return self.y_start[:, None]


def design_continuous(problem: Problem, *, noise: bool = True, mode: str = "stagewise",
                      rtol: float = 1e-12, atol: float = 1e-13) -> ContinuousDesign:
    """Solve the continuous-time design by integrating the backward equations per stage.

    Parameters
    ----------
    problem : Problem
    noise : bool
        False designs as if the diffusion were absent (the paper's Remark 2).
    mode : {"stagewise", "joint"}
        Stage-wise latched multipliers (re-planned at every stage start), or one multiplier
        vector for all knots latched at t0 (the constraints exactly as problem (1) states).
    rtol, atol : float
        Tolerances of the DOP853 integration of the backward equations (a stage solved
        exactly, `HamiltonianSolution`, has none).

    Returns
    -------
    ContinuousDesign
    """
    n = problem.n
    times = problem.times
    N_st = len(problem.knots)
    _, group_of = latch_groups(problem, mode)
    sols: list[StageSolution | None] = [None] * N_st
    # Cost-to-go data after knot k+1 (before its penalty): quadratic, linear, constant, and
    # the open group's multiplier terms N, W, m.
    P_next, p_next, c_next = np.zeros((n, n)), np.zeros(n), 0.0
    N_open = W_open = m_open = None
    for k in range(N_st - 1, -1, -1):
        knot = problem.knots[k]
        stage = problem.stages[k]
        PT, pT, cT = knot_terminal(knot, P_next, p_next, c_next)
        g = group_of[k]
        p = 0 if g is None else g.size
        if g is None:
            NT, WT, mT = np.zeros((n, 0)), np.zeros((0, 0)), np.zeros(0)
        else:
            if N_open is None:
                N_open, W_open, m_open = np.zeros((n, p)), np.zeros((p, p)), np.zeros(p)
            NT, WT, mT = N_open.copy(), W_open.copy(), m_open.copy()
            if knot.n_constraints:
                o = g.offset_of(k)
                sl = slice(o, o + knot.n_constraints)
                NT[:, sl] += knot.constraint.C.T
                mT[sl] -= knot.constraint.value
        y_end = require_finite(np.concatenate([PT.ravel(), pT, [cT], NT.ravel(), WT.ravel(),
                                               mT]))
        res = (_solve_exactly(stage, n, p, _augmented_end(PT, pT, cT, NT, WT, mT), times[k],
                              times[k + 1], problem.tick_hz)
               if _solved_exactly(stage, noise) else None)
        if res is None:            # integrated (and overflow reported) as any other stage
            from scipy.integrate import solve_ivp   # lazy: a slow import the CLI rarely needs
            with np.errstate(over="ignore", invalid="ignore"):  # overflow is reported below
                res = solve_ivp(_stage_rhs(stage, n, p, noise), (times[k + 1], times[k]),
                                y_end, method="DOP853", rtol=rtol, atol=atol,
                                dense_output=True)
        if res.status != 0 or not np.all(np.isfinite(res.y[:, -1])):
            # With [[Q, S], [S', R]] >= 0 (checked by the parser) P is squeezed between 0 and
            # the cost of any fixed linear law, which solves a linear ODE: no true finite
            # escape. What fails is float range: exponential growth the input cannot counter.
            raise DesignError(f"knots[{k}].t", f"the Riccati equation of stage {k} (t = "
                                               f"{times[k]:g} to {times[k + 1]:g}) has no "
                                               f"bounded solution in floating point "
                                               f"({res.message}): it grows beyond "
                                               f"floating-point range through a mode the input "
                                               f"cannot stabilise (unstable A that B does not "
                                               f"reach, or too much noise) or huge weights; "
                                               f"shorten the stage or reduce them")
        st = StageSolution(k, times[k], times[k + 1], p, stage, res.sol, noise=noise,
                           **dict.fromkeys(("P0", "p0", "c0", "N0", "W0", "m0", "Lambda",
                                            "lambda0")))
        P0, p0, c0, N0, W0, m0 = st._unpack(res.y[:, -1])
        W0 = 0.5 * (W0 + W0.T)
        st.P0, st.p0, st.c0, st.N0, st.W0, st.m0 = 0.5 * (P0 + P0.T), p0, float(c0), N0, W0, m0
        P_next, p_next, c_next = st.P0.copy(), st.p0.copy(), st.c0
        if g is not None and g.latch_stage == k:
            check_group(W0, problem, g)
            st.Lambda = np.linalg.solve(W0, N0.T)
            st.lambda0 = np.linalg.solve(W0, m0)
            # The maximised multiplier term joins the cost-to-go of the previous stage.
            NL = N0 @ st.Lambda
            P_next = P_next + 0.5 * (NL + NL.T)
            p_next = p_next + N0 @ st.lambda0
            c_next = c_next + m0 @ st.lambda0
            N_open = W_open = m_open = None
        else:
            st.Lambda, st.lambda0 = np.zeros((0, n)), np.zeros(0)
            if g is not None:
                N_open, W_open, m_open = N0, W0, m0
        st.latches = g is not None and g.latch_stage == k
        sols[k] = st
    return ContinuousDesign(problem, sols, noise, mode)
