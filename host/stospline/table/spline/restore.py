"""Spline tables for designs that latch the state: feasibility restored for the law as
implemented.

A joint design whose constraints are (mostly) inequality rows -- a region at every tick met by
the tick-grid QP (`robot_monotone`), bands beyond the 8 rows of a band dual
(`robot_narrow_corridor`) -- latches the state itself at t0 (``Lambda = I``, ``lambda0 = 0``,
``n_latch = n``): its feed-forward ``k0(t) + L(t) x0`` is the design's active set's affine map
of the start. There is no square system of multipliers to re-solve (`spline_latch`): the
active rows outnumber the latched values (monotone: 5 equality rows and 90 rows on their
bounds against 4 latched values). What is restored instead is the feed-forward:

* the spline's gains are fitted and evaluated as the firmware does (`spline._fit`);
* under those gains the mean from the design's x0 is ``m_j = a_j + M_j d`` at every tick, ``d``
  a correction of the stored ``k0`` coefficients (the tick's command changes by ``-N_j d``,
  ``N_j`` the B-spline basis at the tick), by the oracle's own mean maps
  (`spline_latch.stage_mean_maps`), tick by tick in float64;
* every constraint row (knot rows, region rows at every tick they constrain) is affine in
  ``d``; the rows the design holds on a bound (equality rows; inequality rows within
  `ACTIVE_TOLERANCE` of a bound for the design's own law in double precision) are put back
  on it, the others must stay inside; ``d`` is the correction of least mean-command energy
  ``sum_j h |N_j d|_R^2`` that does so (a least-norm solve of the active rows; an inactive row
  the correction pushes out joins them, at most `MAX_ROUNDS` rounds);
* the corrected coefficients are rounded to float32 on the entry's grid as the fit's are
  (`spline._coefficients`), and the table is the spline's evaluation.

The latch stays ``Lambda = I``, ``lambda0 = 0`` (4 values cannot meet 95 rows). The guarantee
is the per-tick table's: for the design's x0 (and for starts that keep the design's active
set, to first order) the expected constraints hold up to the float32 floor (`float32_floor`).
Since the design's active rows are the constraints' values at the optimum, restoring them
changes the cost only to second order in the correction.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stospline.errors import DesignError
from stospline.table.spline import fit as _spline
from stospline.table.spline.fit import (DEFAULT_MAX_SPANS, INITIAL_SPANS, SplineGains, _basis,
                                    _fit, evaluate)
from stospline.table.spline.latch import FIELD, mean_maps_by_stage

__all__ = ["is_state_latching", "restore", "constraint_rows", "mean_rows", "float32_floor",
           "Rows", "ACTIVE_TOLERANCE", "MAX_ROUNDS"]

# A row is on its bound for the design when its expected value is within this times
# max(1, |bound|) of it (as `stospline.refine.every_tick.TOLERANCE`: the design meets its rows to
# ~1e-13 of that scale).
ACTIVE_TOLERANCE = 1e-9
# Rounds of the active-set loop: each adds the inactive rows the correction pushed out.
MAX_ROUNDS = 10
# Relative residual of the least-norm solve above which the active rows are not met exactly by
# any correction of the stored k0 coefficients (refused).
SOLVE_TOLERANCE = 1e-9
_RIDGE = 1e-12      # of a stage's Gram matrix's largest eigenvalue: directions no tick reaches
EPS32 = 2.0 ** -24


def is_state_latching(table) -> bool:
    """A table that latches the state once, at t0 (``n_latch = n``, ``Lambda = I``,
    ``lambda0 = 0``, no other latch): the joint designs of every-tick regions and of bands
    beyond a band dual."""
    n, _, n_latch = table.dims
    lat = np.asarray(table.stage_n_latch, dtype=int)
    return (table.band_qp is None and n_latch == n and lat[0] == n and not np.any(lat[1:])
            and np.array_equal(np.asarray(table.Lambda[0], float), np.eye(n))
            and not np.any(np.asarray(table.lambda0[0], float)))


@dataclass
class Rows:
    """Every constraint row of a problem: ``lo <= c . E x(tick) <= hi`` (``lo == hi``: an
    equality); ``what``: ``("knot", k, i)`` or ``("region", index, i)``."""
    tick: np.ndarray      # (R,)
    C: np.ndarray         # (R, n)
    lo: np.ndarray
    hi: np.ndarray
    what: list

    def violation(self, y: np.ndarray) -> np.ndarray:
        """Distance outside ``[lo, hi]`` per row (0 inside; for an equality, |y - value|)."""
        return np.maximum(np.maximum(y - self.hi, self.lo - y), 0.0)


def constraint_rows(problem, table) -> Rows:
    """The knots' constraint rows at their ticks and every tick region's rows at each of its
    ticks (t0 itself, the start's, excluded: no law moves it)."""
    tick, C, lo, hi, what = [], [], [], [], []
    n = table.dims[0]
    for k, kn in enumerate(problem.knots):
        if kn.constraint is None:
            continue
        j = int(table.stage_start[k + 1])
        a, b = kn.constraint.bounds
        for i in range(kn.constraint.C.shape[0]):
            tick.append(j), C.append(kn.constraint.C[i, :n]), lo.append(a[i]), hi.append(b[i])
            what.append(("knot", k, i))
    for reg in problem.tick_regions:
        for j in reg.ticks(problem.t0, problem.tick_hz):
            if j == 0:
                continue
            for i in range(reg.C.shape[0]):
                tick.append(int(j)), C.append(reg.C[i]), lo.append(reg.lower[i])
                hi.append(reg.upper[i]), what.append(("region", reg.index, i))
    return Rows(np.asarray(tick, dtype=np.int64), np.asarray(C, float).reshape(-1, n),
                np.asarray(lo, float), np.asarray(hi, float), what)


def _maps(problem, table, varying_maps=None):
    """Per tick ``(Ad, Bd, fd)`` of the oracle's mean map (`mean_maps_by_stage`: stages with
    the same time-invariant data share one exponential, robot_narrow_corridor's 60)."""
    n, m, _ = table.dims
    out = []
    for s, F in enumerate(mean_maps_by_stage(problem, table, 1.0 / table.tick_hz,
                                             varying_maps)):
        per_tick = [(Fj[:, :n], Fj[:, n:n + m], Fj[:, -1]) for Fj in F]
        T = int(table.stage_start[s + 1] - table.stage_start[s])
        out.extend(per_tick[j if len(per_tick) > 1 else 0] for j in range(T))
    return out


@dataclass
class _Correction:
    """The correction's coordinates: every stored k0 entry's S + 3 coefficients, stage by
    stage, entry by entry (a stage's columns are contiguous).

    ``where`` (P,): each column's index in the spline's ``coef``; ``entry`` (P,): its entry's
    number among the corrected ones (for its peak); ``N`` (ticks, m, P): per tick the
    derivatives of the k0 values with respect to the columns (the float64 basis);
    ``blocks``: per stage with corrected entries ``(stage, first column, inputs of its
    entries, Gram matrix of the basis over its ticks)``."""
    where: np.ndarray
    entry: np.ndarray
    entries: list          # (stage, input) of each corrected entry
    N: np.ndarray
    blocks: list


def _k0_basis(spline: SplineGains, stage_start) -> _Correction:
    """`_Correction` of `spline`'s stored k0 entries. Stages with the same knots share one
    basis (robot_narrow_corridor's 60 stages of 2 ticks)."""
    nx = spline.nx
    stages, bases = [], {}
    P = 0
    for s in range(spline.n_stages):
        inputs, cols = spline.entries(s)
        mine = np.flatnonzero(cols == nx)
        if mine.size == 0:
            continue
        a = int(stage_start[s])
        T = int(stage_start[s + 1]) - a
        knots = spline.knots(s)
        key = (T, knots.tobytes())
        if key not in bases:
            nc = knots.size - 4
            sigma, N = _basis(knots.astype(float), np.arange(T, dtype=float))
            B = np.zeros((T, nc))
            B[np.arange(T)[:, None], sigma[:, None] + np.arange(4)] = np.stack(N, axis=1)
            bases[key] = B, B.T @ B
        stages.append((s, a, mine, inputs[mine], P) + bases[key])
        P += mine.size * (knots.size - 4)
    N = np.zeros((int(stage_start[-1]), spline.nu, P))
    where, entry, entries, blocks = [], [], [], []
    for s, a, mine, inputs, p0, B, gram in stages:
        T, nc = B.shape
        for k, (e, i) in enumerate(zip(mine, inputs)):
            N[a:a + T, i, p0 + k * nc:p0 + (k + 1) * nc] = B
            where.append(int(spline.coef_start[s]) + int(e) * nc + np.arange(nc))
            entry.append(np.full(nc, len(entries)))
            entries.append((s, int(i)))
        blocks.append((s, p0, inputs, gram))
    cat = (lambda x: np.concatenate(x)) if where else (lambda x: np.zeros(0, np.int64))
    return _Correction(cat(where), cat(entry), entries, N, blocks)


def _energy_inverse(problem, corr: _Correction, h: float):
    """The pseudo-inverse of the correction's command energy ``Q = sum_j h N_j' R N_j``, as
    blocks to apply (`_apply`). Q is block diagonal (a stage's coefficients move its own
    ticks only) and each block is ``h R_i ⊗ Gram`` (the entries' inputs' R, and the basis's
    Gram matrix, which every entry of the stage shares); its pseudo-inverse is ``R_i^-1 ⊗
    Gram^+ / h``. Directions of the Gram below `_RIDGE` of its largest eigenvalue (the
    coefficients no tick reaches: a 2-tick stage's 4) are dropped: the least-norm
    correction leaves them at 0, where a ridge would leave them to round-off amplified by
    its inverse."""
    by_size, seen = {}, {}
    for s, p0, inputs, gram in corr.blocks:
        R = np.asarray(problem.stages[s].R, float)[np.ix_(inputs, inputs)]
        key = (gram.tobytes(), R.tobytes(), gram.shape[0])   # stages that repeat, once
        if key not in seen:
            w, V = np.linalg.eigh(gram)
            keep = w > _RIDGE * w.max()
            Gp = (V[:, keep] / w[keep]) @ V[:, keep].T
            seen[key] = np.kron(np.linalg.inv(R), Gp) / h
        inv = seen[key]
        size = inv.shape[0]
        idx, mats = by_size.setdefault(size, ([], []))
        idx.append(p0 + np.arange(size))
        mats.append(inv)
    return [(np.array(idx), np.array(mats)) for idx, mats in by_size.values()]


def _apply(blocks, X: np.ndarray) -> np.ndarray:
    """The block-diagonal matrix of `_energy_inverse` times `X` (P, k), blocks of one size
    at once."""
    out = np.zeros_like(X)
    for idx, mats in blocks:
        out[idx] = np.matmul(mats, X[idx])
    return out


def mean_rows(problem, table, rows: Rows, v, *, N=None, varying_maps=None, maps=None):
    """``(y, A)``: the rows' expected values under `table`'s law from x0 with the latched
    vector `v`, and (with the per-tick correction matrices `N`) their derivatives with
    respect to the correction (``A`` (R, P); None without `N`). Float64, tick by tick.
    ``maps``: `_maps` of the problem when the caller has them already."""
    n, m, _ = table.dims
    K = np.asarray(table.K, float)
    ff = np.asarray(table.k0, float) + np.asarray(table.L, float) @ np.asarray(v, float)
    P = 0 if N is None else N.shape[2]
    M = np.zeros((n, 1 + P))
    M[:, 0] = problem.x0
    T = int(table.stage_start[-1])
    at = {}
    if maps is None:
        maps = _maps(problem, table, varying_maps)
    for j, (Ad, Bd, fd) in enumerate(maps):
        if j == 0:
            at[0] = M.copy()
        U = -K[j] @ M
        U[:, 0] -= ff[j]
        if P:
            U[:, 1:] -= N[j]
        M = Ad @ M + Bd @ U
        M[:, 0] += fd
        at[j + 1] = M
    Ms = np.stack([at[j] for j in range(T + 1)])
    G = np.einsum("rn,rnp->rp", rows.C, Ms[rows.tick])
    return G[:, 0], (G[:, 1:] if P else None)


def float32_floor(problem, table, rows: Rows, v, varying_maps=None) -> np.ndarray:
    """Per row, what one float32 rounding of every gain term moves its expected value by, at
    most: ``2^-24 sum_j |d y / d u_j| (|K_j| |m_j| + |k0_j| + |L_j| |v|)`` (the law's
    linearisation, the adjoint run backwards over the ticks). The per-tick table rounds each
    gain once; the spline's evaluation adds a few roundings (the coefficient grid, 7
    operations), so its rows sit within a small multiple of this."""
    n, m, _ = table.dims
    K = np.asarray(table.K, float)
    ff = np.asarray(table.k0, float) + np.asarray(table.L, float) @ np.asarray(v, float)
    maps = _maps(problem, table, varying_maps)
    T = len(maps)
    means = np.zeros((T + 1, n))
    means[0] = problem.x0
    for j, (Ad, Bd, fd) in enumerate(maps):
        means[j + 1] = Ad @ means[j] + Bd @ (-K[j] @ means[j] - ff[j]) + fd
    mag = (np.abs(K) @ np.abs(means[:-1])[:, :, None])[:, :, 0] + np.abs(table.k0) \
        + np.abs(np.asarray(table.L, float)) @ np.abs(np.asarray(v, float))
    lam = np.zeros((rows.tick.size, n))
    floor = np.zeros(rows.tick.size)
    for j in range(T - 1, -1, -1):
        Ad, Bd, _ = maps[j]
        on = rows.tick == j + 1
        lam[on] = rows.C[on]
        floor += np.abs(lam @ Bd) @ mag[j]
        lam = lam @ (Ad - Bd @ K[j])
    return EPS32 * floor


def _active(rows: Rows, y: np.ndarray) -> np.ndarray:
    """+1 on the upper bound, -1 on the lower, 0 inside (equalities: +1)."""
    tol = ACTIVE_TOLERANCE * np.maximum(1.0, np.maximum(np.abs(rows.lo), np.abs(rows.hi)))
    act = np.zeros(y.size, dtype=int)
    act[y <= rows.lo + tol] = -1
    act[y >= rows.hi - tol] = 1
    act[rows.lo == rows.hi] = 1
    return act


def restore(problem, exact, quantized, tolerance: float, *,
            max_spans: int = DEFAULT_MAX_SPANS, initial_spans: int = INITIAL_SPANS,
            correct: bool = True, varying_maps=None):
    """Fit, evaluate, restore the constraints for the design's x0 by correcting the stored
    k0 coefficients (module docstring), evaluate again.

    Returns ``(spline, K, k0, L, info)``: the float32 gains exactly `evaluate` of `spline`;
    ``info``: ``rows`` (R), ``active`` (rows restored onto a bound), ``rounds``, the
    correction's largest coefficient change relative to its entry's peak (``correction``).
    ``correct=False``: the plain fit (the restoration skipped; for tests and figures).

    Raises DesignError (``design.table``) when the active rows cannot be met by any correction
    of the stored k0 coefficients, or the loop does not settle in `MAX_ROUNDS` rounds; and for
    a region checked between ticks (not restored there) or a law designed for a delay.
    """
    if getattr(quantized, "delay_ticks", 0):
        raise DesignError(FIELD, "a table that latches the state is restored without a delay "
                                 "only (delay_ticks = 0)")
    if any(reg.between for reg in problem.tick_regions):
        raise DesignError(FIELD, "a region enforced between ticks (between_ticks = true) is "
                                 "not restored by a spline table: use table \"per-tick\"")
    spline, K, k0, L = _fit(exact, tolerance, max_spans, initial_spans)
    rows = constraint_rows(problem, quantized)
    info = {"rows": int(rows.tick.size), "active": 0, "rounds": 0, "correction": 0.0}
    if not correct or rows.tick.size == 0:
        return spline, K, k0, L, info
    v = np.asarray(problem.x0, float)          # the latch: Lambda = I, lambda0 = 0
    maps = _maps(problem, exact, varying_maps)
    y_design, _ = mean_rows(problem, exact, rows, v, maps=maps)
    act = _active(rows, y_design)
    start = np.asarray(exact.stage_start, dtype=np.int64)
    corr = _k0_basis(spline, start)
    if corr.where.size == 0:
        raise DesignError(FIELD, "the spline stores no k0 entry to restore the constraints with")
    table = quantized.with_arrays(K=K, k0=k0, L=L)
    y, A = mean_rows(problem, table, rows, v, N=corr.N, maps=maps)
    # The correction of least command energy sum_j h |N_j d|_R^2 (`_energy_inverse`).
    Qi = _energy_inverse(problem, corr, 1.0 / exact.tick_hz)
    target = np.where(act > 0, rows.hi, rows.lo)
    scale = np.maximum(1.0, np.maximum(np.abs(rows.lo), np.abs(rows.hi)))
    for rounds in range(1, MAX_ROUNDS + 1):
        on = np.flatnonzero(act != 0)
        Aa, b = A[on], target[on] - y[on]
        QiAt = _apply(Qi, Aa.T)
        lam = np.linalg.lstsq(Aa @ QiAt, b, rcond=1e-13)[0]
        d = QiAt @ lam
        miss = np.abs(Aa @ d - b) / scale[on]
        if miss.size and miss.max() > SOLVE_TOLERANCE:
            r = on[int(np.argmax(miss))]
            raise DesignError(FIELD, f"no correction of the spline's k0 coefficients puts row "
                                     f"{rows.what[r]} back on its bound (misses by "
                                     f"{miss.max():.3g}): no spline table for this tolerance")
        out = rows.violation(y + A @ d) / scale
        out[on] = 0.0
        new = np.flatnonzero(out > ACTIVE_TOLERANCE)
        if new.size == 0:
            break
        act[new] = np.where(y[new] + A[new] @ d > rows.hi[new], 1, -1)
        target = np.where(act > 0, rows.hi, rows.lo)
    else:
        raise DesignError(FIELD, f"the spline's constraint restoration did not settle in "
                                 f"{MAX_ROUNDS} rounds")
    # The corrected coefficients on the fit's grid (`spline._coefficients`): each entry's
    # float32 spacing at its largest |k0| over the stage in the design's law.
    peaks = np.array([np.abs(np.asarray(exact.k0[start[s]:start[s + 1], i], float)).max()
                      for s, i in corr.entries])
    peak = peaks[corr.entry]
    worst = float(np.max(np.abs(d) / np.where(peak > 0, peak, 1.0)))
    coef = spline.coef.astype(float)
    coef[corr.where] = _spline._coefficients((coef[corr.where] + d)[:, None], peak)[:, 0]
    spline = SplineGains(spline.knot_start, spline.knot, spline.row_start, spline.col,
                         spline.coef_start, coef.astype(np.float32), spline.nu, spline.nx,
                         spline.n_latch)
    K, k0, L = evaluate(spline, start)
    info.update(active=int(np.count_nonzero(act)), rounds=rounds, correction=worst)
    return spline, K, k0, L, info
