"""What every design's stages share: the stage-start value terms ``P0, p0, c0, N0, W0, m0``
and the latch map ``v = Lambda x + lambda0`` (`StageStart`), the cost-to-go and latch built on
them (`StageValues`), the value just before a knot, and the checks that a latch can be met."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stospline.errors import DesignError
from stospline.problem.model import Problem

__all__ = ["StageStart", "StageValues", "cost_at_start", "knot_terminal", "check_latch",
           "check_group"]


@dataclass(kw_only=True)
class StageStart:
    """Value terms at a stage's start, ``J(x) = x'P0x + 2p0'x + c0 + ...`` with the constraint
    terms ``N0, W0, m0``, and the latch map (``Lambda`` (p, n), ``lambda0`` (p); empty when
    the stage keeps an earlier latch)."""
    P0: np.ndarray
    p0: np.ndarray
    c0: float
    N0: np.ndarray
    W0: np.ndarray
    m0: np.ndarray
    Lambda: np.ndarray
    lambda0: np.ndarray

    def quadratic_value(self, x: np.ndarray) -> float:
        """``x'P0x + 2p0'x + c0``: the cost-to-go without the constraint terms."""
        return float(x @ self.P0 @ x + 2 * self.p0 @ x + self.c0)


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
        return cost_at_start(self.stages[k], np.asarray(x, dtype=float), v)

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


def cost_at_start(st, x: np.ndarray, v) -> float:
    """Cost-to-go at a stage start from its P, p, c, N, W, m (every design's stages carry them)."""
    val = st.quadratic_value(x)
    if st.n_constraints:
        e = st.N0.T @ x + st.m0
        if st.Lambda.shape[0]:
            val += e @ np.linalg.solve(st.W0, e)
        elif v is None:
            raise ValueError(f"stage {st.index} keeps an earlier latch: pass v")
        else:
            val += 2 * v @ e - v @ st.W0 @ v
    return float(val)


def check_rows(C2: np.ndarray, k: int) -> None:
    """Reject a knot's constraint rows that are zero or linearly dependent: no input meets
    them (W = C2 X C2' is singular whatever the dynamics)."""
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


def check_latch(W: np.ndarray, C2: np.ndarray, k: int) -> None:
    """Reject a constraint that the stage cannot meet: W(t_k) singular or ill-conditioned.

    Two causes, told apart: rows of ``C2`` that are linearly dependent (then ``W = C2 X C2'``
    is singular whatever the dynamics), or a combination of the constrained outputs that the
    input cannot steer over the stage (``B`` zero, or not reaching that direction).
    """
    path = f"knots[{k}].constraint.C"
    check_rows(C2, k)
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


def check_group(W: np.ndarray, problem: Problem, g) -> None:
    """`check_latch` for a latch group. A joint group stacks knots at different times, so
    only each knot's own rows can be dependent; W's rank decides the rest."""
    if len(g.knots) == 1:
        check_latch(W, problem.knots[g.knots[0]].constraint.C, g.knots[0])
        return
    for k in g.knots:   # each knot alone: dependent rows are a problem whatever the dynamics
        C2 = problem.knots[k].constraint.C
        check_latch(C2 @ C2.T, C2, k)
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


def knot_terminal(knot, P_next, p_next, c_next):
    """Value just before knot k: the next stage's cost-to-go plus the knot penalty."""
    PT, pT, cT = P_next.copy(), p_next.copy(), c_next
    if knot.penalty is not None:
        pen = knot.penalty
        PT += pen.weight * pen.C.T @ pen.C
        pT -= pen.weight * pen.C.T @ pen.target
        cT += pen.weight * pen.target @ pen.target
    return PT, pT, cT
