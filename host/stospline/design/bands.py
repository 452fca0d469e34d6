"""Band constraints ``lower <= E{C2 X(t_k)} <= upper`` (the paper's Section 4, Proposition 4).

Only the joint design is exact here: one multiplier vector for every constrained knot, fixed
at t0. (Stage-wise re-planning would make the next stage's cost-to-go piecewise quadratic in
the state, so the paper's quadratic dynamic programming no longer applies; a stage-wise band
is rejected.) Lagrangian duality: with the joint design solved for zero targets (which gives
``N, W, m~`` at t0 and per-tick gains that do not depend on the targets),

    g(mu) = x0'P x0 + 2p'x0 + c + 2 lam'e - lam'W lam - 2 mu_hi'upper + 2 mu_lo'lower,
    lam = mu_hi - mu_lo,  e = N'x0 + m~,  mu_hi, mu_lo >= 0,

is a concave quadratic; its maximum is the optimal cost (the primal problem is a convex QP in
the policy), and the expected outputs of the optimal law are ``y = e - W lam``. The dual is
solved with OSQP and then refined exactly on its active set.

With at most ``BANDQP_MAX`` rows the table carries the dual (`BandQP`) and the firmware solves
it for the measured x0 at the t0 latch (``stsp_bandqp.c``), so a trajectory started from
another state still meets its bands. Otherwise it latches ``v = Lambda x0 + lambda0``, the
affine map of the optimal active set: exact for the design's x0 and for every x0 with the same
active set.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from stospline.design.zoh import ZohDesign, design_zoh
from stospline.errors import DesignError
from stospline.precision import round_to_scale
from stospline.problem.model import Constraint, Problem
from stospline.limits import BANDQP_MAX

if TYPE_CHECKING:
    from stospline.design.continuous import ContinuousDesign
    from stospline.table.format import BandQP

__all__ = ["BandSolution", "BandDesign", "solve_band_dual", "enumerate_active_sets",
           "design_bands", "has_bands"]

# Significant digits, of each array's largest entry, of the band dual (Nt, mt, W) in the tables:
# between machines those arrays agree to ~1e-15 of that entry, and the firmware solves the dual
# for a float32 latch, so 10 digits keep all it resolves and none that differ.
BANDQP_DIGITS = 10


def has_bands(problem: Problem) -> bool:
    """Any band knot, or a region at every tick (which the design meets with band knots)."""
    return bool(problem.tick_regions) or any(kn.constraint is not None and kn.constraint.is_band
                                             for kn in problem.knots)


@dataclass
class BandSolution:
    """Optimal multipliers of the band dual at one start state."""
    lam: np.ndarray            # lam = mu_hi - mu_lo, one per stacked constraint row
    expected: np.ndarray       # predicted E{C2 x(t_k)}, stacked
    active: np.ndarray         # per row: -1 at lower, +1 at upper, 0 inactive
    value: float               # dual value without the x0'Px0 + 2p'x0 + c part
    iterations: int = 0


def _dual_value(lam, e, W, lo, hi) -> float:
    return float(2 * lam @ e - lam @ W @ lam - 2 * np.maximum(lam, 0) @ hi
                 + 2 * np.maximum(-lam, 0) @ lo)


def _refine(e, W, lo, hi, active) -> np.ndarray:
    """Exact multipliers for an active set: rows at a bound meet it, the others have lam 0."""
    lam = np.zeros_like(e)
    A = np.flatnonzero(active)
    if A.size:
        b = np.where(active[A] > 0, hi[A], lo[A])
        lam[A] = np.linalg.solve(W[np.ix_(A, A)], e[A] - b)
    return lam


def solve_band_dual(e: np.ndarray, W: np.ndarray, lo: np.ndarray, hi: np.ndarray, *,
                    tol: float = 1e-9) -> BandSolution:
    """Maximise the concave dual with OSQP, then refine exactly on the active set.

    Variables: a free ``lam_i`` for every equality row (lower = upper) and ``mu_hi, mu_lo >= 0``
    for every band row, ``lam = T [lam_eq; mu_hi; mu_lo]``. (Splitting an equality row too
    would leave the objective flat along ``mu_hi = mu_lo + c``.)
    """
    import osqp
    from scipy import sparse

    q = len(e)
    eq = np.flatnonzero(lo == hi)
    band = np.flatnonzero(lo != hi)
    if band.size == 0:   # equalities only: one linear solve (and no QP solver chatter)
        lam = np.linalg.solve(W, e - hi)
        active = np.where(lam >= 0, 1, -1)
        return BandSolution(lam, e - W @ lam, active, _dual_value(lam, e, W, lo, hi))
    nv = len(eq) + 2 * len(band)
    T = np.zeros((q, nv))
    T[eq, np.arange(len(eq))] = 1.0
    T[band, len(eq) + np.arange(len(band))] = 1.0
    T[band, len(eq) + len(band) + np.arange(len(band))] = -1.0
    Wd = 0.5 * (W + W.T)
    P2 = 2 * T.T @ Wd @ T
    lin = -2 * T.T @ e
    lin[:len(eq)] += 2 * hi[eq]                                  # -2 lam'zeta for equalities
    lin[len(eq):len(eq) + len(band)] += 2 * hi[band]
    lin[len(eq) + len(band):] -= 2 * lo[band]
    lower_bound = np.concatenate([np.full(len(eq), -np.inf), np.zeros(2 * len(band))])
    solver = osqp.OSQP()
    solver.setup(sparse.csc_matrix(P2 + 1e-14 * np.eye(nv)), lin,
                 sparse.identity(nv, format="csc"), lower_bound, np.full(nv, np.inf),
                 verbose=False, eps_abs=1e-12, eps_rel=1e-12, max_iter=200000,
                 polishing=True)
    res = solver.solve(raise_error=False)
    if res.info.status_val not in (1, 2):   # solved, solved inaccurate
        raise DesignError("knots", f"the band dual QP was not solved: {res.info.status}")
    lam = T @ res.x
    y = e - W @ lam
    scale = max(1.0, float(np.abs(np.concatenate([lo, hi])).max()))
    active = np.where(y >= hi - tol * scale, 1, 0)
    active = np.where(y <= lo + tol * scale, -1, active)
    active[eq] = np.where(lam[eq] >= 0, 1, -1)
    lam, active = _settle(e, W, lo, hi, active, tol * scale)
    y = e - W @ lam
    return BandSolution(lam, y, active, _dual_value(lam, e, W, lo, hi), int(res.info.iter))


def _settle(e, W, lo, hi, active, tol, rounds: int = 50):
    """Refine on `active`, then correct the set until the refined point is a KKT point:
    rows beyond their bands join it, band rows whose multiplier has the wrong sign leave it
    (a primal-dual active-set step). OSQP's set is usually right, and then nothing changes;
    with many nearly dependent rows (bands at neighbouring ticks) it can miss a row by more
    than `tol`."""
    band = lo != hi
    for _ in range(rounds):
        lam = _refine(e, W, lo, hi, active)
        y = e - W @ lam
        new = active.copy()
        new[band & (y > hi + tol)] = 1
        new[band & (y < lo - tol)] = -1
        new[band & (new > 0) & (lam < 0) & (y <= hi + tol)] = 0
        new[band & (new < 0) & (lam > 0) & (y >= lo - tol)] = 0
        if np.array_equal(new, active):
            return lam, active
        active = new
    return lam, active


def enumerate_active_sets(e, W, lo, hi, *, tol: float = 1e-9) -> BandSolution:
    """Brute force over all 3^q active sets, each an equality-constrained solve; the best
    primal-feasible one. The primal cost of an active set is ``(e_A - b_A)' W_AA^-1 (e_A - b_A)``
    plus the x0 part; inactive rows must end inside their bands."""
    q = len(e)
    best = None
    scale = max(1.0, float(np.abs(np.concatenate([lo, hi])).max()))
    for pattern in itertools.product((-1, 0, 1), repeat=q):
        act = np.array(pattern)
        if np.any((lo == hi) & (act == 0)):
            continue
        try:
            lam = _refine(e, W, lo, hi, act)
        except np.linalg.LinAlgError:
            continue
        y = e - W @ lam
        if np.any(y < lo - tol * scale) or np.any(y > hi + tol * scale):
            continue
        A = np.flatnonzero(act)
        d = e[A] - np.where(act[A] > 0, hi[A], lo[A])
        primal = float(d @ lam[A])   # (e_A - b_A)' W_AA^-1 (e_A - b_A)
        if best is None or primal < best.value - 1e-15:
            best = BandSolution(lam, y, act, primal)
    if best is None:
        raise DesignError("knots", "no active set is feasible: the bands cannot all be met")
    return best


@dataclass
class BandDesign:
    """A joint design for a problem with bands; `base` was solved for zero targets."""
    problem: Problem
    base: ContinuousDesign | ZohDesign
    solution: BandSolution
    J0: float
    rows: list[tuple[int, int]]      # (knot, row) of each stacked constraint row
    lower: np.ndarray
    upper: np.ndarray
    mode: str = "joint"

    @property
    def noise_aware(self) -> bool:
        return self.base.noise_aware

    @property
    def stages(self):
        return self.base.stages

    def band_dual(self, *, exact: bool = False) -> tuple | None:
        """``(Nt, mt, W, lower, upper)``: the dual the firmware re-solves from the measured x0
        at the t0 latch (`stospline.table.format.BandQP`), when it has at most BANDQP_MAX rows
        (else None: the table latches the affine map of the design's active set, exact only
        while that set stays optimal). As the tables store it, at BANDQP_DIGITS (the digits
        beyond differ between machines); ``exact=True``: the design's own doubles."""
        if len(self.lower) > BANDQP_MAX:
            return None
        st0 = self.base.stages[0]
        Nt, mt, W = st0.N0.T, st0.m0, st0.W0
        if not exact:
            Nt, mt, W = (round_to_scale(a, BANDQP_DIGITS) for a in (Nt, mt, 0.5 * (W + W.T)))
        return Nt, mt, W, self.lower, self.upper

    def tick_gains(self, tick_hz: int | None = None) -> tuple[int, list[tuple]]:
        """The base design's per-stage tick gains (`stospline.table.format.TickGains`)."""
        return self.base.tick_gains(tick_hz)

    def cost_from(self, x0: np.ndarray) -> float:
        """Optimal expected cost from another start state: the same zero-target design, the
        band dual solved at that state (what the firmware's t0 re-solve achieves)."""
        st0 = self.base.stages[0]
        x = np.asarray(x0, dtype=float)
        sol = solve_band_dual(st0.N0.T @ x + st0.m0, st0.W0, self.lower, self.upper)
        return st0.quadratic_value(x) + sol.value

    def summary_terms(self) -> dict:
        """The JSON summary's band entries: where each row sits and its multiplier."""
        return {"active_set": self.active_set()}

    def active_set(self) -> list[dict]:
        """Per constraint row: knot, row, where it sits and its multiplier."""
        names = {-1: "lower", 0: "inactive", 1: "upper"}
        eq = self.lower == self.upper
        return [{"knot": k, "row": i, "at": "equality" if eq[j] else names[int(a)],
                 "multiplier": float(l), "expected": float(y)}
                for j, ((k, i), a, l, y) in enumerate(zip(self.rows, self.solution.active,
                                                          self.solution.lam,
                                                          self.solution.expected))]


def _zero_targets(problem: Problem) -> Problem:
    knots = tuple(kn if kn.constraint is None else
                  replace(kn, constraint=Constraint(kn.constraint.C,
                                                    np.zeros(kn.constraint.C.shape[0])))
                  for kn in problem.knots)
    return replace(problem, knots=knots)


def design_bands(problem: Problem, *, discretization: str = "exact-zoh", noise: bool = True,
                 tick_hz: int | None = None) -> BandDesign:
    """Joint design with band (and equality) constraints at the knots."""
    zero = _zero_targets(problem)
    if discretization == "exact-zoh":
        base = design_zoh(zero, tick_hz, noise=noise, mode="joint")
    else:
        from stospline.design.continuous import design_continuous
        base = design_continuous(zero, noise=noise, mode="joint")
    st0 = base.stages[0]
    x0 = problem.x0
    e = st0.N0.T @ x0 + st0.m0
    rows = [(k, i) for k, kn in enumerate(problem.knots) if kn.constraint is not None
            for i in range(kn.n_constraints)]
    lo = np.concatenate([problem.knots[k].constraint.bounds[0] for k in
                         sorted({k for k, _ in rows})])
    hi = np.concatenate([problem.knots[k].constraint.bounds[1] for k in
                         sorted({k for k, _ in rows})])
    sol = solve_band_dual(e, st0.W0, lo, hi)
    J0 = st0.quadratic_value(x0) + sol.value
    # Latch map of the optimal active set (exact at x0 and wherever that set stays optimal).
    Lam = np.zeros_like(st0.Lambda)
    lam0 = np.zeros_like(st0.lambda0)
    A = np.flatnonzero(sol.active)
    if A.size:
        WA = st0.W0[np.ix_(A, A)]
        b = np.where(sol.active[A] > 0, hi[A], lo[A])
        Lam[A] = np.linalg.solve(WA, st0.N0[:, A].T)
        lam0[A] = np.linalg.solve(WA, st0.m0[A] - b)
    stages = list(base.stages)
    stages[0] = replace(st0, Lambda=Lam, lambda0=lam0)
    base = replace(base, stages=stages, problem=problem)
    return BandDesign(problem, base, sol, J0, rows, lo, hi)
