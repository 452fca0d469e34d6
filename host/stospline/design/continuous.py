"""Continuous-time stage-wise design (the paper's Proposition 3, corrected per docs/theory/math.md).

Backward on each stage ``[t_k, t_{k+1}]``, with ``K = R^-1 (P B + S)'`` and ``Acl = A - B K``::

    -P' = A'P + PA + Q + Pi(P) - (PB+S) R^-1 (PB+S)'      Pi(P)_kl = tr(G_k' P G_l)
    -p' = Acl' p + q - K' r
    -c' = rho - (B'p + r)' R^-1 (B'p + r)
    -N' = Acl' N                     N(t_{k+1}) = C2'
     W' = -N' B R^-1 B' N            W(t_{k+1}) = 0
     m' = N' B R^-1 (B'p + r)        m(t_{k+1}) = -zeta

At the stage start the controller latches ``v = W^-1 (N' x + m)`` and applies
``u = -K x - R^-1 (B'p + r) - R^-1 B' N v`` until the next stage start.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stospline.expm import require_finite
from stospline.design.latch import latch_groups
from stospline.errors import DesignError, ProblemError
from stospline.problem.model import Problem, Stage, ticks_per_stage

__all__ = ["DesignError", "StageSolution", "ContinuousDesign", "design_continuous",
           "noise_operator"]


def noise_operator(G: np.ndarray, P: np.ndarray) -> np.ndarray:
    """``Pi(P)_kl = tr(G_k' P G_l)``: the Ito correction of ``x'Px`` under ``sum x_i G_i dZ``."""
    return np.einsum("kai,ab,lbi->kl", G, P, G)


@dataclass
class StageSolution:
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
    P0: np.ndarray
    p0: np.ndarray
    c0: float
    N0: np.ndarray
    W0: np.ndarray
    m0: np.ndarray
    Lambda: np.ndarray
    lambda0: np.ndarray
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

    def riccati(self, t: np.ndarray):
        """P, p, c, N, W, m at times ``t`` (arrays with time as the last axis)."""
        return self._unpack(self._sol(np.atleast_1d(t)))

    def gains(self, t: np.ndarray):
        """Feedback ``K`` (T, m, n), feed-forward ``k0`` (T, m) and multiplier gain ``L`` (T, m, p).

        The control is ``u = -K x - k0 - L v``.
        """
        s = self.stage
        P, pv, _, N, _, _ = self.riccati(t)
        T = P.shape[-1]
        m, p = s.B.shape[1], N.shape[1]
        K, k0, L = np.empty((T, m, s.A.shape[0])), np.empty((T, m)), np.empty((T, m, p))
        for j, tj in enumerate(np.atleast_1d(t)):
            sj = s.at(tj)
            _, St, Rt = _effective_weights(sj, P[..., j], self.noise)
            Rinv = np.linalg.inv(Rt)
            K[j] = Rinv @ (P[..., j] @ sj.B + St).T
            k0[j] = Rinv @ (sj.B.T @ pv[:, j] + sj.r)
            L[j] = Rinv @ (sj.B.T @ N[..., j])
        return K, k0, L


class StageValues:
    """Cost-to-go and latch of a design whose ``stages`` carry the stage-start terms
    ``P0, p0, c0, N0, W0, m0, Lambda, lambda0`` (shared by the continuous and ZOH designs)."""
    problem: Problem
    stages: list

    @property
    def J0(self) -> float:
        """Predicted optimal expected cost from ``(t0, x0)`` (of the law at the design's rate)."""
        return self.cost_to_go(0, self.problem.x0)

    def cost_to_go(self, k: int, x: np.ndarray, v: np.ndarray | None = None) -> float:
        """Optimal expected cost from state `x` at the start of stage k.

        At a latching stage ``J_k(x) = x'Px + 2p'x + c + (N'x + m)' W^-1 (N'x + m)``; on a
        stage that keeps an earlier latch `v` it is ``x'Px + 2p'x + c + 2v'(N'x + m) - v'Wv``.
        """
        return _value(self.stages[k], np.asarray(x, dtype=float), v)

    def latch(self, k: int, x: np.ndarray) -> np.ndarray:
        """The multipliers latched at the start of stage k from state `x`."""
        st = self.stages[k]
        return st.Lambda @ x + st.lambda0

    def cost_from(self, x0: np.ndarray) -> float:
        """Optimal expected cost from a start state (the t0 latch re-plans from it)."""
        return self.cost_to_go(0, x0)

    def band_dual(self, *, exact: bool = False) -> None:
        """No band constraints: nothing for the firmware to re-solve at t0."""
        return None

    def summary_terms(self) -> dict:
        """Design-specific entries of the JSON summary (none without bands)."""
        return {}


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


def _value(st, x: np.ndarray, v) -> float:
    """Cost-to-go at a stage start from its P, p, c, N, W, m (shared by both designers)."""
    val = x @ st.P0 @ x + 2 * st.p0 @ x + st.c0
    if st.n_constraints:
        e = st.N0.T @ x + st.m0
        if st.Lambda.shape[0]:
            val += e @ np.linalg.solve(st.W0, e)
        elif v is None:
            raise ValueError(f"stage {st.index} keeps an earlier latch: pass v")
        else:
            val += 2 * v @ e - v @ st.W0 @ v
    return float(val)


def _effective_weights(stage: Stage, P: np.ndarray, noise: bool):
    """``Q + Pi_xx(P)``, ``S + Pi_xu(P)``, ``R + Pi_uu(P)`` with ``Pi_ab = tr(Gh_a' P Gh_b)`` over
    the noise multipliers ``[x; u]``: the Ito term of ``x'Px`` under the full diffusion."""
    if not noise:
        return stage.Q, stage.S, stage.R
    n = stage.A.shape[0]
    Pi = noise_operator(stage.noise_tensor, P)
    return stage.Q + Pi[:n, :n], stage.S + Pi[:n, n:], stage.R + Pi[n:, n:]


def _stage_rhs(stage: Stage, n: int, p: int, noise: bool):
    def rhs(t, y):
        st = stage.at(t)
        A, B, q, r, rho = st.A, st.B, st.q, st.r, st.rho
        i = 0
        P = y[i:i + n * n].reshape(n, n); i += n * n
        pv = y[i:i + n]; i += n
        i += 1
        N = y[i:i + n * p].reshape(n, p); i += n * p
        i += p * p
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
        dN = -(Acl.T @ N)
        BtN = B.T @ N
        dW = -(BtN.T @ Rinv @ BtN)
        dm = BtN.T @ Rinv @ g
        return np.concatenate([dP.ravel(), dp, [dc], dN.ravel(), dW.ravel(), dm])

    return rhs


def _check_latch(W: np.ndarray, C2: np.ndarray, k: int) -> None:
    """Reject a constraint that the stage cannot meet: W(t_k) singular or ill-conditioned.

    Two causes, told apart: rows of ``C2`` that are linearly dependent (then ``W = C2 X C2'``
    is singular whatever the dynamics), or a combination of the constrained outputs that the
    input cannot steer over the stage (``B`` zero, or not reaching that direction).
    """
    path = f"knots[{k}].constraint.C"
    p, n = C2.shape
    zero = np.flatnonzero(~C2.any(axis=1))
    if zero.size:
        raise DesignError(path, f"row {zero[0]} is zero, so it constrains nothing; remove it")
    _, sv, vt = np.linalg.svd(C2.T)          # vt (p x p): its last rows span {c : c' C2 = 0}
    if np.sum(sv > 1e-10 * sv.max()) < p:
        c = vt[-1] / vt[-1][np.argmax(np.abs(vt[-1]))]
        rows = np.flatnonzero(np.abs(c) > 1e-8).tolist()
        combo = " ".join(f"{c[i]:+.4g}*row {i}" for i in rows)
        more = f" ({p} rows but only n = {n} states)" if p > n else ""
        raise DesignError(path, f"rows {rows} are linearly dependent{more}: {combo} = 0; "
                                f"remove redundant rows")
    w, vecs = np.linalg.eigh(W)
    if w[-1] <= np.finfo(float).tiny:
        raise DesignError(path, f"cannot be met on stage {k}: the input has no effect on "
                                f"C x at knots[{k}].t over this stage (W = 0 at the stage "
                                f"start; is B zero on this stage?)")
    if w[0] <= 1e-10 * w[-1]:
        d = vecs[:, 0] / vecs[:, 0][np.argmax(np.abs(vecs[:, 0]))]
        rows = np.flatnonzero(np.abs(d) > 1e-8).tolist()
        combo = " ".join(f"{d[i]:+.4g}*row {i}" for i in rows)
        ratio = max(w[0] / w[-1], 0.0) + 0.0
        raise DesignError(path, f"cannot be met on stage {k}: W at the stage start is "
                                f"singular (eigenvalue ratio {ratio:.3g}); the input cannot "
                                f"steer the output combination {combo} of C x over this "
                                f"stage (rows {rows}: not controllable)")


def _check_group(W: np.ndarray, problem: Problem, g) -> None:
    """`_check_latch` for a latch group. A joint group stacks knots at different times, so
    only each knot's own rows can be dependent; W's rank decides the rest."""
    if len(g.knots) == 1:
        _check_latch(W, problem.knots[g.knots[0]].constraint.C, g.knots[0])
        return
    for k in g.knots:   # each knot alone: dependent rows are a problem whatever the dynamics
        C2 = problem.knots[k].constraint.C
        _check_latch(C2 @ C2.T, C2, k)
    w, vecs = np.linalg.eigh(W)
    if w[0] <= 1e-10 * max(w[-1], np.finfo(float).tiny):
        d = vecs[:, 0] / vecs[:, 0][np.argmax(np.abs(vecs[:, 0]))]
        names = []
        for k, o in zip(g.knots, g.offsets):
            for i in range(problem.knots[k].n_constraints):
                if abs(d[o + i]) > 1e-8:
                    names.append(f"{d[o + i]:+.4g}*knots[{k}] row {i}")
        raise DesignError("knots", f"the joint constraints cannot all be met from t0: W(t0) is "
                                   f"singular; the input cannot steer the combination "
                                   f"{' '.join(names)} of expected outputs")


def _knot_terminal(knot, P_next, p_next, c_next):
    """Value just before knot k: the next stage's cost-to-go plus the knot penalty."""
    PT, pT, cT = P_next.copy(), p_next.copy(), c_next
    if knot.penalty is not None:
        pen = knot.penalty
        PT += pen.weight * pen.C.T @ pen.C
        pT -= pen.weight * pen.C.T @ pen.target
        cT += pen.weight * pen.target @ pen.target
    return PT, pT, cT


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
        PT, pT, cT = _knot_terminal(knot, P_next, p_next, c_next)
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
        st = StageSolution(k, times[k], times[k + 1], p, stage, res.sol,
                           *([None] * 8), noise=noise)
        P0, p0, c0, N0, W0, m0 = st._unpack(res.y[:, -1])
        W0 = 0.5 * (W0 + W0.T)
        st.P0, st.p0, st.c0, st.N0, st.W0, st.m0 = 0.5 * (P0 + P0.T), p0, float(c0), N0, W0, m0
        P_next, p_next, c_next = st.P0.copy(), st.p0.copy(), st.c0
        if g is not None and g.latch_stage == k:
            _check_group(W0, problem, g)
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
