"""The band dual of a joint band design re-solved for a law as implemented (a spline's
evaluated gains): the data the firmware's stage-0 latch solves, exact for that law.

A joint design latches all its knots' multipliers ``v`` once, at stage 0. Under the table's
gains (`spline_latch._stage_map`, the affine mean map of each stage) the expected outputs at
the constrained knots are affine in ``(x0, v)``::

    y = C2 Phi x0 + C2 psi + C2 Gamma v = Nt' x0 + mt' - W' v,   W' = -C2 Gamma.

For the design's own law ``W'`` is the dual's SPD ``W``; under the spline's gains it differs by
about the spline's tolerance and is in general not symmetric. The multipliers the firmware
must latch are then the solution of the (mixed, box) linear complementarity problem

    lam_i >= 0 where y_i = hi_i,  lam_i <= 0 where y_i = lo_i,  lo <= y <= hi elsewhere,
    equality rows (lo == hi) always at their value,

which no longer is the optimality condition of a concave dual (W' is not symmetric), but is
what makes the law as implemented meet its bands in expectation with multipliers of the right
sign. When ``W'`` is a P-matrix (every principal minor positive) the problem has exactly one
solution for every ``e = Nt' x0 + mt'`` (the box LCP of a P-matrix is uniquely solvable; the
equality rows' block is a P-matrix, hence nonsingular, and its Schur complement is again a
P-matrix), every candidate active set's ``W'_AA`` is nonsingular, and the firmware's
enumeration of the active sets (``stsp_bandqp.c``, Gaussian elimination for a non-symmetric
``W``) finds it. The table is refused (``design.table``) when ``W'`` is not a P-matrix.
"""
from __future__ import annotations

import itertools

import numpy as np

from stospline.errors import DesignError
from stospline.limits import BANDQP_MAX
from stospline.precision import round_to_scale
from stospline.table.spline.latch import (FIELD, _refuse_unsupported, _stage_map,
                                          latch_groups_of_table)

__all__ = ["resolve_band", "band_rows", "solve_band_lcp", "is_p_matrix", "BANDQP_DIGITS"]

# As the per-tick tables' band dual (`stospline.design.bands.BANDQP_DIGITS`): the digits that
# agree between machines (products of ~10^4 tick maps differ there at ~1e-15).
BANDQP_DIGITS = 10
# A principal minor counts as positive when it exceeds this fraction of the product of its
# rows' norms (Hadamard's bound of its magnitude): a P-matrix with a margin that double
# precision resolves.
P_MARGIN = 1e-10


def band_rows(problem, table, spline=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(Nt', mt', W')`` in float64, unrounded: the expected constrained outputs at the knots
    ``y = Nt' x0 + mt' - W' v`` under `table`'s gains (only the entries `spline` stores, when
    given), v the multipliers latched at stage 0."""
    groups = latch_groups_of_table(problem, table)
    if len(groups) != 1 or groups[0][0] != 0:
        raise DesignError(FIELD, "a band table latches its multipliers once, at stage 0; this "
                                 f"one latches at stages {[g[0] for g in groups]}")
    n = table.dims[0]
    h = 1.0 / table.tick_hz
    knots = groups[0][1]
    width = int(table.stage_n_latch[0])
    M = np.eye(n, n + width + 1)                 # m = M [x; v; 1], from the latch tick
    rows = []
    for s in range(knots[-1] + 1):
        P = _stage_map(problem.stages[s], table, s, width, h, spline)
        M = P[:, :n] @ M
        M[:, n:] += P[:, n:]
        if s in knots:
            rows.append(problem.knots[s].constraint.C @ M)
    CM = np.vstack(rows)
    return CM[:, :n], CM[:, -1].copy(), -CM[:, n:n + width]


def is_p_matrix(W: np.ndarray) -> tuple[bool, tuple[int, ...], float]:
    """Every principal minor of W positive (by `P_MARGIN` of Hadamard's bound): ``(ok, the
    worst principal submatrix's rows, its minor over the bound)``; 2^q - 1 determinants."""
    q = W.shape[0]
    worst, where = np.inf, ()
    for size in range(1, q + 1):
        for rows in itertools.combinations(range(q), size):
            sub = W[np.ix_(rows, rows)]
            bound = float(np.prod(np.linalg.norm(sub, axis=1)))
            ratio = float(np.linalg.det(sub)) / bound if bound > 0 else -np.inf
            if ratio < worst:
                worst, where = ratio, rows
    return bool(worst > P_MARGIN), where, worst


def solve_band_lcp(e: np.ndarray, W: np.ndarray, lo: np.ndarray, hi: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """``(lam, active)`` of the box LCP above, by the firmware's enumeration (the band rows'
    states as a ternary counter, row 0 least significant: inactive, lower, upper), its
    conditions and tolerance (``stsp_bandqp.c``): the first candidate that meets them. For a
    P-matrix W that candidate is the unique solution. Raises DesignError (``design.table``)
    when none does (W not a P-matrix)."""
    e, W, lo, hi = (np.asarray(a, dtype=float) for a in (e, W, lo, hi))
    q = e.size
    eq = lo == hi
    band = np.flatnonzero(~eq)
    tol = 1e-12 * (1.0 + np.abs(hi))
    for digits in itertools.product((0, -1, 1), repeat=band.size):
        active = np.where(eq, 1, 0)
        active[band] = digits[::-1]              # the last digit varies fastest
        A = np.flatnonzero(active)
        lam = np.zeros(q)
        if A.size:
            b = np.where(active[A] > 0, hi[A], lo[A])
            try:
                lam[A] = np.linalg.solve(W[np.ix_(A, A)], e[A] - b)
            except np.linalg.LinAlgError:
                continue
        y = e - W @ lam
        ok = (np.all(lam[(active > 0) & ~eq] >= 0) and np.all(lam[(active < 0) & ~eq] <= 0)
              and np.all((y <= hi + tol)[active == 0]) and np.all((y >= lo - tol)[active == 0]))
        if ok:
            return lam, active
    raise DesignError(FIELD, "no active set meets the band conditions for the law as "
                             "implemented (its W is not a P-matrix)")


def resolve_band(problem, table, spline=None):
    """The band dual of `table`'s law (`stospline.table.format.BandQP`, at `BANDQP_DIGITS`, W'
    possibly non-symmetric) and the stage-0 latch maps ``Lambda, lambda0`` of the design x0's
    active set under it (the firmware's fallback when its solve fails, as a per-tick band
    table's), float64, the table's shapes.

    Raises DesignError (field ``design.table``) for what has no exact band re-solve: a table
    without a band dual (more than `BANDQP_MAX` rows), fixed-point, delayed or time-varying
    tables (`spline_latch._refuse_unsupported`), or a W' that is not a P-matrix.
    """
    from stospline.table.format import BandQP
    base = table.band_qp
    if base is None:
        raise DesignError(FIELD, f"a band table with more than {BANDQP_MAX} constraint rows "
                                 f"carries no band dual (it latches the affine map of one "
                                 f"active set): no exact spline re-solve")
    _refuse_unsupported(problem, table, band=True)
    if getattr(table, "delay_ticks", 0) or any(st.varying is not None for st in problem.stages):
        raise DesignError(FIELD, "the band dual is re-solved for time-invariant stage data "
                                 "without a delay only")
    Nt, mt, W = band_rows(problem, table, spline)
    if Nt.shape[0] != base.q:
        raise DesignError(FIELD, f"the knots' constraints have {Nt.shape[0]} rows, the band "
                                 f"dual {base.q}")
    Nt, mt, W = (round_to_scale(a, BANDQP_DIGITS) for a in (Nt, mt, W))
    ok, rows, worst = is_p_matrix(W)
    if not ok:
        raise DesignError(FIELD, f"the band dual re-solved for the spline's gains is not a "
                                 f"P-matrix (principal minor of rows {list(rows)}: {worst:.3g} "
                                 f"of its Hadamard bound): the firmware's latch would not be "
                                 f"unique")
    qp = BandQP(Nt, mt, W, base.lo, base.hi)
    Lam = np.array(table.Lambda, dtype=float)
    lam0 = np.array(table.lambda0, dtype=float)
    lam, active = solve_band_lcp(qp.e(problem.x0), W, qp.lo, qp.hi)
    A = np.flatnonzero(active)
    Lam[0], lam0[0] = 0.0, 0.0
    if A.size:
        WA = W[np.ix_(A, A)]
        b = np.where(active[A] > 0, qp.hi[A], qp.lo[A])
        Lam[0, A] = np.linalg.solve(WA, Nt[A])
        lam0[0, A] = np.linalg.solve(WA, mt[A] - b)
    return qp, Lam, lam0
