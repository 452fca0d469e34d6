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

__all__ = ["DesignError", "StageSolution", "ContinuousDesign", "design_continuous",
           "noise_operator"]


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
        Tolerances of the DOP853 integration of the backward equations.

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
        y_end = np.concatenate([PT.ravel(), pT, [cT], NT.ravel(), WT.ravel(), mT])
        with np.errstate(over="ignore", invalid="ignore"):  # overflow is reported below
            from scipy.integrate import solve_ivp   # lazy: a slow import the CLI rarely needs
            res = solve_ivp(_stage_rhs(stage, n, p, noise), (times[k + 1], times[k]),
                            require_finite(y_end),
                            method="DOP853", rtol=rtol, atol=atol, dense_output=True)
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
