"""Spline tables: each stage's gains as cubic B-splines of the tick instead of one row per tick
(the format of ``spline_spec.md``, which the firmware implements; this is the host side).

`SplineGains` holds the arrays the firmware reads; `evaluate` computes the per-tick gains
exactly as the firmware does (binary32, one rounded operation at a time, the spec's order);
`fit_spline` compresses a design's exact per-tick gains to a given relative tolerance,
choosing each stage's integer breakpoints by refinement.

The arrays, concatenated over stages (S_s spans in stage s, E_s stored entries)::

    knot_start  uint32 (n_stages + 1,)   knot[knot_start[s]:knot_start[s+1]]: S_s + 7 knots
    knot        float32                  [0,0,0,0, b_1 .. b_{S-1}, T,T,T,T], ticks of the stage
    row_start   uint16 (n_stages*nu + 1,)  entries of (s, i): col[row_start[s*nu+i]:...+1]]
    col         uint8  (n_entries,)      j < nx: K[i][j]; nx: k0[i]; nx+1+c: L[i][c]
    coef_start  uint32 (n_stages + 1,)   coef[coef_start[s]:...]: E_s x (S_s + 3), entry-major
    coef        float32
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stospline.errors import DesignError
from stospline.table.format import positive_zeros
from stospline.table_options import MIN_SPLINE_TOLERANCE

__all__ = ["SplineGains", "SplineBudgetError", "evaluate", "command", "fit_spline",
           "max_relative_error",
           "gain_columns", "DEFAULT_MAX_SPANS", "INITIAL_SPANS", "MIN_TOLERANCE"]

DEFAULT_MAX_SPANS = 1024
# Below this the float32 coefficients and the float32 evaluation (a few roundings of values
# up to the entry's largest) cannot promise the tolerance, whatever the knots.
MIN_TOLERANCE = MIN_SPLINE_TOLERANCE
# Entries whose largest value over the stage is below this fraction of the largest of their
# kind (K, k0 or L) are round-off of exact zeros: not stored.
ZERO_FRACTION = 1e-12
FIELD = "design.spline_tolerance"
# The first fit: this many uniform spans (fewer refits than starting from one span, for
# about the same knots), fewer on short stages (16 ticks a span at least).
INITIAL_SPANS = 8
_INITIAL_TICKS_PER_SPAN = 16
# Splitting a span whose error is r times the tolerance into ceil(1.25 r^(1/4)) pieces: the
# error of a cubic fit falls like h^4; the margin saves a round of refits for most spans.
_SPLIT_MARGIN = 1.25
_DENSE_SOLVE_MAX = 400        # normal equations up to this size by numpy's dense solver
# Stages under _SHORT_SPAN ticks, or with _SHORT_RUN consecutive one-tick spans, are
# fitted by the minimum-norm least squares (`_min_norm`), whose singular values below _RCOND
# of the largest count as zero: k one-tick spans amplify the rounding by ~(2 + sqrt 3)^k, 1e4
# at k = 7.
_SHORT_SPAN = 4
_SHORT_RUN = 8
_RCOND = 1e-10
# Gain values of the stages fitted together (`_fit`), at most (512 KB of float64: a long
# stage is fitted alone, while its values are in the cache).
_WINDOW_VALUES = 1 << 16


class SplineBudgetError(DesignError):
    """The gains cannot be fitted to the tolerance within the spans allowed per stage (or the
    tolerance is finer than float32 coefficients can promise)."""


@dataclass(frozen=True)
class SplineGains:
    """One table's gains as cubic B-splines per stage (the arrays of the module docstring).

    ``nu`` inputs, ``nx`` states (the law's state: ``n + m`` with a delay), ``n_latch`` latched
    multipliers (the table's padded width). Entries not stored are exactly zero.
    """
    knot_start: np.ndarray
    knot: np.ndarray
    row_start: np.ndarray
    col: np.ndarray
    coef_start: np.ndarray
    coef: np.ndarray
    nu: int
    nx: int
    n_latch: int

    _DTYPES = {"knot_start": np.uint32, "knot": np.float32, "row_start": np.uint16,
               "col": np.uint8, "coef_start": np.uint32, "coef": np.float32}

    def __post_init__(self):
        for name, dtype in self._DTYPES.items():
            object.__setattr__(self, name,
                               positive_zeros(np.ascontiguousarray(getattr(self, name), dtype)))
        for name in ("nu", "nx", "n_latch"):
            object.__setattr__(self, name, int(getattr(self, name)))
        self._check()

    def _check(self) -> None:
        """The structural rules of the spec (the firmware refuses a table breaking them)."""
        ns = self.n_stages
        if ns < 1 or self.knot_start[0] != 0 or self.knot_start[-1] != self.knot.size:
            raise ValueError("knot_start must run from 0 to the number of knots")
        rows = self.row_start.astype(np.int64)
        if rows.shape != (ns * self.nu + 1,) or rows[0] != 0 or rows[-1] != self.col.size \
                or np.any(np.diff(rows) < 0):
            raise ValueError("row_start must be nondecreasing from 0 to the number of entries, "
                             "one row per (stage, input)")
        if self.coef_start.shape != (ns + 1,) or self.coef_start[0] != 0 \
                or self.coef_start[-1] != self.coef.size:
            raise ValueError("coef_start must run from 0 to the number of coefficients")
        if self.col.size and int(self.col.max()) > self.nx + self.n_latch:
            raise ValueError("an entry's column is beyond nx + 1 + n_latch")
        # Checked over all rows and stages at once (a table of 60 short stages has 120
        # rows): the first offending one is named.
        col = self.col.astype(np.int64)
        inside = np.ones(max(col.size - 1, 0), bool)    # consecutive entries of one row
        inside[rows[1:-1][(rows[1:-1] > 0) & (rows[1:-1] < col.size)] - 1] = False
        if np.any((np.diff(col) <= 0) & inside):
            raise ValueError("the columns of a (stage, input) row must increase")
        ks = self.knot_start.astype(np.int64)
        S = np.diff(ks) - 7
        U = self.knot.astype(float)
        bad = S < 1
        if not bad.any():
            last = U[ks[1:] - 1]
            four = np.arange(4)
            bad |= np.any(U[ks[:-1, None] + four] != 0, axis=1)
            bad |= np.any(U[ks[1:, None] - 1 - four] != last[:, None], axis=1)
            bad |= last >= 2 ** 24
            stage = np.repeat(np.arange(ns), np.diff(ks))
            pos = np.arange(U.size) - ks[stage]      # index within its stage's knots
            # Breakpoints U[3..S+3] increase: the pair (i, i+1) with 3 <= i < S + 3.
            pair = (pos[:-1] >= 3) & (pos[:-1] < S[stage[:-1]] + 3) \
                & (stage[:-1] == stage[1:])
            np.logical_or.at(bad, stage[:-1][pair & (np.diff(U) <= 0)], True)
            np.logical_or.at(bad, stage[U != np.rint(U)], True)
        if bad.any():
            s = int(np.flatnonzero(bad)[0])
            raise ValueError(f"stage {s}: the knots must be [0,0,0,0, b_1 < ... < b_(S-1), "
                             f"T,T,T,T] with integer breakpoints, 0 < b < T < 2^24")
        entries = rows[np.arange(ns + 1) * self.nu]
        need = np.diff(entries) * (S + 3)
        wrong = np.flatnonzero(np.diff(self.coef_start.astype(np.int64)) != need)
        if wrong.size:
            s = int(wrong[0])
            raise ValueError(f"stage {s}: {int(np.diff(entries)[s])} entries need "
                             f"{int(need[s])} coefficients")

    @property
    def n_stages(self) -> int:
        return len(self.knot_start) - 1

    @property
    def n_entries(self) -> int:
        return int(self.col.size)

    @property
    def nbytes(self) -> int:
        """Bytes of the six arrays (what the spline adds to flash, headers aside)."""
        return sum(getattr(self, name).nbytes for name in self._DTYPES)

    def spans(self, s: int) -> int:
        """Stage s's number of spans S_s."""
        return int(self.knot_start[s + 1] - self.knot_start[s]) - 7

    def knots(self, s: int) -> np.ndarray:
        """Stage s's clamped knot vector (float32, S_s + 7 values)."""
        return self.knot[self.knot_start[s]:self.knot_start[s + 1]]

    def entry_slice(self, s: int) -> slice:
        """Stage s's entries in `col` (all its inputs, row by row)."""
        return slice(int(self.row_start[s * self.nu]), int(self.row_start[(s + 1) * self.nu]))

    def entries(self, s: int) -> tuple[np.ndarray, np.ndarray]:
        """``(inputs, cols)`` of stage s's entries, in stored order: entry e is the gain of
        input ``inputs[e]`` on operand ``cols[e]``."""
        rows = self.row_start[s * self.nu:(s + 1) * self.nu + 1].astype(np.int64)
        return np.repeat(np.arange(self.nu), np.diff(rows)), self.col[self.entry_slice(s)]

    def coefficients(self, s: int) -> np.ndarray:
        """Stage s's coefficients, (entries, S_s + 3) float32."""
        c = self.coef[self.coef_start[s]:self.coef_start[s + 1]]
        return c.reshape(-1, self.spans(s) + 3)


def _basis(U: np.ndarray, tau: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
    """The span index sigma and the four nonzero cubic B-splines ``N[0..3]`` at each `tau`
    (The NURBS Book, A2.2), in the dtype of `U` and `tau`: in float32 every operation is one
    binary32 rounding in the spec's order (numpy never fuses a multiply and an add)."""
    S = U.size - 7
    # U[sigma + 3] <= tau < U[sigma + 4]; tau < T, so sigma <= S - 1.
    sigma = np.searchsorted(U[3:S + 3], tau, side="right") - 1
    i = sigma + 3
    left = [None] + [tau - U[i + 1 - j] for j in (1, 2, 3)]
    right = [None] + [U[i + j] - tau for j in (1, 2, 3)]
    N = [np.ones_like(tau), None, None, None]
    for j in (1, 2, 3):
        saved = np.zeros_like(tau)
        for r in range(j):
            temp = N[r] / (right[r + 1] + left[j - r])
            N[r] = saved + right[r + 1] * temp
            saved = left[j - r] * temp
        N[j] = saved
    return sigma, N


def _combine(sigma: np.ndarray, N: list[np.ndarray], C: np.ndarray) -> np.ndarray:
    """``g = N0 c[sigma]; g += N1 c[sigma+1]; ...`` for every entry: (ticks, entries), in the
    dtype of N and C (C is (entries, S + 3))."""
    Ct = C.T
    g = N[0][:, None] * np.take(Ct, sigma, axis=0)
    for r in (1, 2, 3):
        g = g + N[r][:, None] * np.take(Ct, sigma + r, axis=0)
    return g


def _stage_values(knots: np.ndarray, C: np.ndarray, T: int, bases: dict | None = None
                  ) -> np.ndarray:
    """A stage's entries at its ticks 0..T-1 as the firmware evaluates them (float32).
    ``bases``: a dict the caller keeps across stages, the float32 basis of each knot vector
    computed once (robot_narrow_corridor's 60 stages share one)."""
    knots = np.asarray(knots, np.float32)
    key = (T, knots.tobytes())
    hit = None if bases is None else bases.get(key)
    if hit is None:
        hit = _basis(knots, np.arange(T, dtype=np.float32))
        if bases is not None:
            bases[key] = hit
    sigma, N = hit
    return _combine(sigma, N, np.asarray(C, np.float32))


def evaluate(spline: SplineGains, stage_start: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The per-tick gains the firmware computes from `spline`, bit for bit.

    Parameters
    ----------
    spline : SplineGains
    stage_start : ndarray
        The table's first tick of each stage, then the number of ticks.

    Returns
    -------
    K, k0, L : ndarray
        float32, shapes (ticks, nu, nx), (ticks, nu), (ticks, nu, n_latch); 0 where no entry
        is stored.
    """
    start = np.asarray(stage_start, dtype=np.int64)
    if start.size != spline.n_stages + 1:
        raise ValueError(f"{start.size - 1} stages in the table, {spline.n_stages} in the spline")
    nx, nu = spline.nx, spline.nu
    Z = np.zeros((int(start[-1]), nu, nx + 1 + spline.n_latch), dtype=np.float32)
    bases = {}
    for s in range(spline.n_stages):
        a, b = int(start[s]), int(start[s + 1])
        U = spline.knots(s)
        if float(U[-1]) != b - a:
            raise ValueError(f"stage {s}: the spline spans {float(U[-1]):g} ticks, the table "
                             f"{b - a}")
        inputs, cols = spline.entries(s)
        if cols.size:
            Z[a:b, inputs, cols] = _stage_values(U, spline.coefficients(s), b - a, bases)
    return Z[:, :, :nx].copy(), Z[:, :, nx].copy(), Z[:, :, nx + 1:].copy()


def command(spline: SplineGains, stage_start: np.ndarray, tick: int, x: np.ndarray,
            v: np.ndarray) -> np.ndarray:
    """The command ``u = -(K x + k0 + L v)`` the firmware computes at `tick` from state `x` and
    latch `v`, bit for bit (float32). Per input: ``k0[i] + L[i] v`` is folded into one spline,
    coefficient by coefficient ``f = ((+0 - c_1 z_1) - c_2 z_2) - ...`` over the input's entries
    beyond x in stored order (``z`` = 1 for k0, ``v[c]`` for L), once per span; its value at
    tick starts the command, from which each gain of x times its state entry is subtracted in
    stored order. (The gains of `evaluate` are K, k0, L themselves; this folded order is the
    command's rounding, not the oracle's law.)"""
    start = np.asarray(stage_start, dtype=np.int64)
    s = int(np.searchsorted(start[1:], tick, side="right"))
    nx = spline.nx
    x = np.asarray(x, np.float32)
    z = np.concatenate([x, [np.float32(1)], np.asarray(v, np.float32)]).astype(np.float32)
    U = spline.knots(s)
    sigma, N = _basis(np.asarray(U, np.float32), np.array([tick - start[s]], np.float32))
    sg = int(sigma[0])
    N = [n[0] for n in N]
    C = spline.coefficients(s)[:, sg:sg + 4]
    inputs, cols = spline.entries(s)

    def value(c):
        g = np.float32(N[0] * c[0])
        for r in (1, 2, 3):
            g = np.float32(g + np.float32(N[r] * c[r]))
        return g

    u = np.zeros(spline.nu, dtype=np.float32)
    for i in range(spline.nu):
        fold = np.zeros(4, dtype=np.float32)
        for e in np.flatnonzero((inputs == i) & (cols >= nx)):
            fold = (fold - C[e] * z[cols[e]]).astype(np.float32)
        acc = value(fold)
        for e in np.flatnonzero((inputs == i) & (cols < nx)):
            acc = np.float32(acc - np.float32(value(C[e]) * z[cols[e]]))
        u[i] = acc
    return u


def gain_columns(table) -> np.ndarray:
    """A table's gains side by side per tick, in the spline's column order: (ticks, m,
    n + 1 + n_latch) = ``[K, k0, L]``."""
    return _side_by_side(table.K, table.k0, table.L)


def _side_by_side(K: np.ndarray, k0: np.ndarray, L: np.ndarray) -> np.ndarray:
    return np.concatenate([K, k0[:, :, None], L], axis=2)


def _column_peaks(g: np.ndarray) -> np.ndarray:
    """``max |g|`` over the rows (ticks) of `g` (ticks, k), 64 rows at a time: numpy reduces
    the first axis of a few columns in a short loop per row (8x slower on a 6000-tick
    stage), of 64 k columns in long ones."""
    x = np.abs(g)
    T, k = x.shape
    if k == 0:                                # no column (a law without multipliers)
        return np.zeros(0)
    q = T - T % 64
    top = x[:q].reshape(-1, 64 * k).max(axis=0, initial=0.0).reshape(64, k).max(axis=0)
    return np.maximum(top, x[q:].max(axis=0, initial=0.0))


def _stage_entries(table, a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
    """The stored entries of the stage of ticks ``a..b-1``: the mask (m, cols) of the
    (input, column) entries not identically zero over the stage (round-off of zeros, below
    `ZERO_FRACTION` of the largest of their kind, aside) and their values (entries, ticks)
    float64, in `col` order."""
    T, m = b - a, table.K.shape[1]
    kinds = [np.asarray(g, dtype=float).reshape(T, m, -1)
             for g in (table.K[a:b], table.k0[a:b], table.L[a:b])]
    keep = []
    for g in kinds:
        peak = _column_peaks(g.reshape(T, -1)).reshape(g.shape[1:])
        top = peak.max(initial=0.0)
        keep.append(peak > ZERO_FRACTION * top if top > 0 else np.zeros(peak.shape, bool))
    # Gathered kind by kind, input by input, then transposed once: concatenating the (ticks,
    # m, cols) arrays first is slow (numpy works row by row on rows of a few values).
    values = [g[:, i, kept[i]] for i in range(m) for g, kept in zip(kinds, keep)]
    keep = np.concatenate(keep, axis=1)
    return keep, np.ascontiguousarray(np.concatenate(values, axis=1).T)


def _clamped(breaks: np.ndarray) -> np.ndarray:
    return np.concatenate([[0.0] * 3, breaks, [float(breaks[-1])] * 3])


def _normal_band(breaks: np.ndarray, N: list[np.ndarray]) -> np.ndarray:
    """The upper band of the normal matrix ``B'B`` of the basis `N` (float64) at ticks
    0..T-1: ``band[d, j] = (B'B)[j, j + d]``. Ticks of one span are consecutive, so their
    sums are `numpy.add.reduceat` over the span starts."""
    S = breaks.size - 1
    starts = breaks[:-1]
    band = np.zeros((4, S + 3))
    for a in range(4):
        for b in range(a, 4):
            band[b - a, a:a + S] += np.add.reduceat(N[a] * N[b], starts)
    # A basis function that no tick reaches (a last span one tick long) would make the
    # system singular; the ridge puts its coefficient at 0, which no tick evaluates.
    band[0] += 1e-13 * band[0].max()
    return band


def _normal_rhs(breaks: np.ndarray, N: list[np.ndarray], YT: np.ndarray) -> np.ndarray:
    """``B'y`` of every row of `YT` (entries, ticks): (entries, S + 3), row by row (the same
    bits whichever rows share the call)."""
    S = breaks.size - 1
    starts = breaks[:-1]
    rhs = np.zeros((YT.shape[0], S + 3))
    for a in range(4):
        rhs[:, a:a + S] += np.add.reduceat(YT * N[a], starts, axis=1)
    return rhs


def _lsq(breaks: np.ndarray, N: list[np.ndarray], YT: np.ndarray,
         band: np.ndarray | None = None) -> np.ndarray:
    """Least-squares B-spline coefficients (entries, S + 3) of the rows of `YT` (entries,
    ticks) at ticks 0..T-1, by the banded normal equations (float64); `band` is
    ``_normal_band(breaks, N)`` when the caller has it already."""
    if band is None:
        band = _normal_band(breaks, N)
    return _solve_banded(band, _normal_rhs(breaks, N, YT).T).T


def _ill_conditioned(breaks: np.ndarray) -> bool:
    """A stage the normal equations fit badly (`_min_norm`): under `_SHORT_SPAN` ticks, more
    coefficients than ticks (one-tick spans up to its end: a null space, coupled_axes' last
    stage), or a run of `_SHORT_RUN` consecutive one-tick spans."""
    short = np.diff(breaks) == 1
    if int(breaks[-1]) < _SHORT_SPAN or breaks.size + 2 > int(breaks[-1]):
        return True
    run = 0
    for flag in short:
        run = run + 1 if flag else 0
        if run >= _SHORT_RUN:
            return True
    return False


def _min_norm(breaks: np.ndarray, sigma: np.ndarray, N64: list[np.ndarray],
              YT: np.ndarray) -> np.ndarray:
    """Least squares of minimum norm (SVD, dense, singular values below `_RCOND` of the
    largest dropped), for stages with spans shorter than `_SHORT_SPAN` ticks. Their ticks
    may not determine every coefficient (a stage under 4 ticks), or barely: k one-tick spans
    have their ticks on the knots, where the basis is ``[1/6, 2/3, 1/6]`` shifted by one, a
    triangular system whose inverse grows like ``(2 + sqrt 3)^k`` (22 of them at the start
    of robot_monotone: a singular value 6e-13 of the largest). The normal equations' ridge
    leaves that direction to their rounding, amplified up to 1e-5 of a coefficient and moving
    with the design's last bits (and the float32 coefficients with it); here it gets 0, which
    changes the values at the ticks by that singular value's fraction only."""
    T, nb = int(breaks[-1]), breaks.size + 2
    B = np.zeros((T, nb))
    rows = np.arange(T)
    for r in range(4):
        B[rows, sigma + r] = N64[r]
    return np.linalg.lstsq(B, YT.T, rcond=_RCOND)[0].T


def _dense_normal(band: np.ndarray) -> np.ndarray:
    """The symmetric matrix of an upper band (``band[d, j] = A[j, j + d]``), dense."""
    w, nb = band.shape
    A = np.zeros((nb, nb))
    flat = A.reshape(-1)                      # diagonal d from (0, d) and from (d, 0)
    for d in range(w):
        flat[d:(nb - d) * nb:nb + 1] = band[d, :nb - d]
        flat[d * nb::nb + 1] = band[d, :nb - d]
    return A


def _solve_banded(band: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve ``A x = rhs`` for the symmetric positive definite A given by its upper band
    (``band[d, j] = A[j, j + d]``): dense for small systems (numpy's LAPACK), else a banded
    LDL' in a loop (no scipy.linalg: importing it costs more than the compression)."""
    w, nb = band.shape
    if nb <= _DENSE_SOLVE_MAX:
        return np.linalg.solve(_dense_normal(band), rhs)
    # A = L D L' with unit lower L of bandwidth w - 1: lw[d][j] = L[j + d, j].
    a = band.tolist()
    Dg = [0.0] * nb
    lw = [[0.0] * nb for _ in range(w)]
    for j in range(nb):
        dj = a[0][j] - sum(lw[j - k][k] ** 2 * Dg[k] for k in range(max(0, j - w + 1), j))
        Dg[j] = dj
        for d in range(1, min(w, nb - j)):
            acc = a[d][j]
            for k in range(max(0, j + d - w + 1), j):
                acc -= lw[j + d - k][k] * lw[j - k][k] * Dg[k]
            lw[d][j] = acc / dj
    x = np.array(rhs, dtype=float)
    for j in range(nb):                       # L y = rhs
        for d in range(1, min(w, nb - j)):
            x[j + d] -= lw[d][j] * x[j]
    x /= np.array(Dg)[:, None]
    for j in range(nb - 1, -1, -1):           # L' x = y / D
        for d in range(1, min(w, nb - j)):
            x[j] -= lw[d][j] * x[j + d]
    return x


def _span_excess(G: np.ndarray, YT: np.ndarray, scale: np.ndarray, breaks: np.ndarray
                 ) -> np.ndarray:
    """Per entry and span (entries, S), the largest ``|G - Y| * scale`` over the span's
    ticks: `G` (ticks, entries) float32, `YT` (entries, ticks), `scale` per entry. The maxima
    are taken on the (entries, ticks) layout, whose rows are contiguous, before scaling:
    scaling by a positive number is monotonic in floating point too, so this is the scaled
    errors' maximum."""
    D = G.T - YT
    np.abs(D, out=D)
    worst = np.maximum.reduceat(D, breaks[:-1], axis=1)
    worst *= scale[:, None]
    return worst


class _Bases:
    """The float32 basis at a stage's ticks for given breakpoints, its float64 copy and its
    normal matrix, kept for the next stage: stages of equal length start from the same
    breakpoints and often refine to the same (the 60 s patrol: 4 bases for 20 fits).

    At most `KEEP_TICKS` ticks of bases are kept (56 bytes a tick), the least recently used
    dropped first: long stages, which rarely repeat, cost no more memory than without."""
    KEEP_TICKS = 1 << 19

    def __init__(self):
        self._cache: dict[tuple[int, bytes], tuple] = {}

    def get(self, T: int, breaks: np.ndarray):
        key = (T, breaks.tobytes())
        hit = self._cache.pop(key, None)
        if hit is None:
            tau = np.arange(T, dtype=np.float32)
            # The least squares on the firmware's own (float32) basis: the fit is best for
            # the values it will evaluate.
            sigma, N = _basis(_clamped(breaks.astype(float)).astype(np.float32), tau)
            N64 = [b.astype(float) for b in N]
            hit = sigma, N, N64, _normal_band(breaks, N64)
        if T <= self.KEEP_TICKS:
            while sum(k[0] for k in self._cache) + T > self.KEEP_TICKS:
                del self._cache[next(iter(self._cache))]
            self._cache[key] = hit                # the most recent last
        return hit


def _distinct(a: np.ndarray) -> np.ndarray:
    """``numpy.unique`` of integers: its first call imports ``numpy.ma`` (15 ms of a cold
    run; nothing else of ``stospline design`` needs it)."""
    a = np.sort(a)
    return a[np.r_[True, a[1:] != a[:-1]]]


def _refined(breaks: np.ndarray, excess: np.ndarray) -> np.ndarray:
    """`breaks` with the spans whose worst error is `excess` (> 1: over the tolerance) split
    into about ``excess^(1/4)`` integer pieces; the same array if none can be split.

    A one-tick span that misses cannot be split: its error comes from the coefficients it
    shares with the spans around it (a cubic's basis reaches three spans each way), so
    those are halved instead. The last span keeps two ticks at least: its last basis
    function is zero at the span's first tick and the stage's end T is no tick, so in a
    one-tick last span no tick reaches it (and its neighbour barely): the least squares would
    be singular there but for the ridge, its coefficients amplifying the last bits of the
    gains a billion times (the Schoenberg-Whitney condition; a design for a one-tick delay
    ends its stages on a jump that refines the last spans down to single ticks).
    """
    return _refined_rows(breaks, excess[None])[0]


def _refined_rows(breaks: np.ndarray, excess: np.ndarray) -> list[np.ndarray]:
    """`_refined` of stages at the same `breaks`, one row of `excess` (stages, S) each: the
    pieces of every row at once, each distinct row's breakpoints computed once (coupled_axes'
    20 stages refine alike)."""
    length = np.diff(breaks)
    most = length.copy()                       # pieces a span may be split into
    most[-1] = max(1, length[-1] // 2)         # the last one's of two ticks at least
    pieces = np.zeros(excess.shape, dtype=np.int64)
    over = excess > 1
    split = over & (most > 1)
    pieces[split] = np.maximum(2, np.ceil(_SPLIT_MARGIN * excess[split] ** 0.25))
    for r, s in zip(*np.nonzero(over & (most <= 1))):   # every update a max: in any order
        near = slice(max(0, s - 3), s + 4)
        pieces[r, near] = np.maximum(pieces[r, near], 2)
    pieces = np.minimum(pieces, most)
    out, seen = [], {}
    for row in pieces:
        key = row.tobytes()
        if key not in seen:
            seen[key] = _split(breaks, row)
        out.append(seen[key])
    return out


def _split(breaks: np.ndarray, pieces: np.ndarray) -> np.ndarray:
    """`breaks` with span s split into ``pieces[s]`` (0 or 1: kept) integer pieces."""
    # The inner points of ``numpy.linspace(b_s, b_s+1, pieces + 1)`` for every split span at
    # once, in its arithmetic (k * (delta / pieces) + b_s): one call instead of one a span.
    split = np.flatnonzero(pieces > 1)
    inner = pieces[split] - 1
    k = (np.arange(inner.sum()) - np.repeat(np.cumsum(inner) - inner, inner) + 1).astype(float)
    step = (breaks[split + 1] - breaks[split]).astype(float) / pieces[split]
    new = k * np.repeat(step, inner) + np.repeat(breaks[split].astype(float), inner)
    return _distinct(np.concatenate([breaks, np.rint(new).astype(np.int64)]))


def _coefficients(C: np.ndarray, peak: np.ndarray) -> np.ndarray:
    """The float32 coefficients of a least-squares fit `C` (entries, S + 3): each entry's
    rounded to a multiple of the float32 spacing at its largest gain `peak` (the spacing of
    the binade of `peak`), not to its own float32 neighbours. The tolerance is relative to
    the peak, so nothing is lost; but a coefficient far below the peak (a gain that tends to
    zero at the plan's end) keeps no digits that the last bits of the gains reach: rounded
    to its own float32 neighbours, its value would move with the design's round-off."""
    Q = np.ldexp(1.0, np.frexp(peak)[1] - 24)[:, None]
    return positive_zeros((np.rint(C / Q) * Q).astype(np.float32))


def _fit_stage(YT: np.ndarray, tolerance: float, max_spans: int, initial_spans: int, s: int,
               bases: _Bases | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One stage: breakpoints, float32 coefficients (entries, S + 3) and the values the
    firmware evaluates (ticks, entries), every entry of `YT` (entries, ticks) within
    `tolerance` of its largest."""
    out = _fit_stages([YT], [s], tolerance, max_spans, initial_spans, bases or _Bases())[s]
    if isinstance(out, Exception):
        raise out
    return out


def _solve_stages(band: np.ndarray, rhs: np.ndarray, rows: np.ndarray) -> list[np.ndarray]:
    """`_solve_banded` of each stage's rows ``rhs[rows[k]:rows[k + 1]]`` (entries, S + 3),
    separately: the dense ones of equally many entries in one batched call of numpy's
    solver, which makes the same LAPACK call per stage as a call of its own."""
    nb = band.shape[1]
    spans = list(zip(rows[:-1], rows[1:]))
    if nb > _DENSE_SOLVE_MAX or len(spans) == 1:
        return [_solve_banded(band, rhs[a:b].T).T for a, b in spans]
    A = _dense_normal(band)
    out = [None] * len(spans)
    sizes = np.diff(rows)
    for size in _distinct(sizes):
        mine = np.flatnonzero(sizes == size)
        idx = rows[mine][:, None] + np.arange(size)               # (stages, entries)
        X = np.linalg.solve(A, rhs[idx].transpose(0, 2, 1))       # (stages, nb, entries)
        for k, x in zip(mine, X):
            out[k] = x.T
    return out


def _fit_stages(YTs: list[np.ndarray], stages: list[int], tolerance: float, max_spans: int,
                initial_spans: int, bases: _Bases) -> dict:
    """`_fit_stage` of several stages, stage s's result (or the SplineBudgetError it raises)
    under its number. Stages of one length that are at the same breakpoints are fitted
    together, row by row as alone (the normal equations' right-hand sides, the float32
    coefficients, their evaluation and the errors are computed per entry; only the solve
    is per stage, so that each stage's coefficients are the bits of a fit of its own):
    coupled_axes' 20 stages of 25 ticks take 3 rounds of batched steps instead of 60."""
    out = {}
    live = {}                         # stage -> (YT, peak, scale, breaks)
    for YT, s in zip(YTs, stages):
        E, T = YT.shape
        S0 = max(1, min(initial_spans, T // _INITIAL_TICKS_PER_SPAN, max_spans))
        breaks = _distinct(np.rint(np.linspace(0, T, S0 + 1)).astype(np.int64))
        if E == 0:
            out[s] = (breaks[[0, -1]], np.zeros((0, 4), np.float32),
                      np.zeros((T, 0), np.float32))
            continue
        YT = np.ascontiguousarray(YT, dtype=float)
        peak = np.abs(YT).max(axis=1)
        live[s] = (YT, peak, 1.0 / (tolerance * peak), breaks)
    while live:
        together = {}
        for s, (YT, _, _, breaks) in live.items():
            together.setdefault((YT.shape[1], breaks.tobytes()), []).append(s)
        for (T, _), group in together.items():
            breaks = live[group[0]][3]
            sigma, N, N64, band = bases.get(T, breaks)
            YT = np.concatenate([live[s][0] for s in group]) if len(group) > 1 \
                else live[group[0]][0]
            rows = np.cumsum([0] + [live[s][0].shape[0] for s in group])
            if not _ill_conditioned(breaks):
                C = _solve_stages(band, _normal_rhs(breaks, N64, YT), rows)
            else:
                C = [_min_norm(breaks, sigma, N64, YT[a:b]) for a, b in zip(rows, rows[1:])]
            C = _coefficients(np.concatenate(C), np.concatenate([live[s][1] for s in group]))
            G = _combine(sigma, N, C)
            excess = _span_excess(G, YT, np.concatenate([live[s][2] for s in group]), breaks)
            worst = np.maximum.reduceat(excess, rows[:-1], axis=0)
            done = worst.max(axis=1) <= 1.0
            finer_rows = iter(_refined_rows(breaks, worst[~done]) if not done.all() else [])
            for k, s in enumerate(group):
                a, b = rows[k], rows[k + 1]
                if done[k]:
                    out[s] = (breaks, C[a:b], G[:, a:b])
                    del live[s]
                    continue
                finer = next(finer_rows)
                if finer.size == breaks.size:
                    out[s] = SplineBudgetError(
                        FIELD, f"stage {s}: the float32 spline misses the tolerance "
                               f"{tolerance:g} by {worst[k].max():.3g}x even with one-tick "
                               f"spans around the miss")
                elif finer.size - 1 > max_spans:
                    out[s] = SplineBudgetError(
                        FIELD, f"stage {s}: the gains need more than {max_spans} spans for "
                               f"the tolerance {tolerance:g} (raise the tolerance or the "
                               f"span limit)")
                else:
                    live[s] = live[s][:3] + (finer,)
                    continue
                del live[s]
    return out


def _windows(exact, start: np.ndarray, per_tick: int):
    """The stages in order as windows of ``(stage, keep, YT)`` (`_stage_entries`), each of at
    most `_WINDOW_VALUES` gain values (`per_tick` a tick) but one stage at least."""
    window, held = [], 0
    for s in range(exact.n_stages):
        size = int(start[s + 1] - start[s]) * per_tick
        if window and held + size > _WINDOW_VALUES:
            yield window
            window, held = [], 0
        window.append((s,) + _stage_entries(exact, int(start[s]), int(start[s + 1])))
        held += size
    if window:
        yield window


def fit_spline(exact, tolerance: float, *, max_spans: int = DEFAULT_MAX_SPANS,
               initial_spans: int = INITIAL_SPANS) -> SplineGains:
    """Compress a table's per-tick gains to cubic B-splines, one knot vector per stage.

    Parameters
    ----------
    exact : GainTable
        The design's own per-tick law, ``table_of(design, quantize=False)`` (float64).
    tolerance : float
        Every stored entry, evaluated as the firmware does (`evaluate`), is within
        ``tolerance * max |g|`` of the exact value at every tick, ``max |g|`` the entry's
        largest magnitude over the stage.
    max_spans : int
        Spans allowed per stage.
    initial_spans : int
        Uniform spans of the first fit (fewer on stages under 16 ticks a span); the fit only
        ever adds knots, so a coarse tolerance may keep them all.

    Returns
    -------
    SplineGains

    Raises
    ------
    SplineBudgetError
        (field ``design.spline_tolerance``) The tolerance is below what float32 coefficients
        can promise (`MIN_TOLERANCE`), or some stage needs more than `max_spans` spans.

    Notes
    -----
    Each stage starts from a few uniform spans, is least-squares fitted at its ticks (all
    entries at once, coefficients rounded to float32), and the spans where some entry misses
    are split, until every entry meets the tolerance. Entries that are identically zero over
    the stage are not stored.
    """
    return _fit(exact, tolerance, max_spans, initial_spans)[0]


def _fit(exact, tolerance: float, max_spans: int, initial_spans: int = INITIAL_SPANS
         ) -> tuple[SplineGains, np.ndarray, np.ndarray, np.ndarray]:
    """`fit_spline` and the per-tick gains K, k0, L it evaluated, float32 in the table's
    shapes (the same as `evaluate` of the result, computed once)."""
    tolerance = float(tolerance)
    if not np.isfinite(tolerance) or not MIN_TOLERANCE <= tolerance < 1:
        raise SplineBudgetError(FIELD, f"the tolerance must lie in [{MIN_TOLERANCE:.3g}, 1) "
                                       f"(float32 coefficients), not {tolerance:g}")
    if int(max_spans) < 1 or int(initial_spans) < 1:
        raise ValueError(f"max_spans and initial_spans must be at least 1, not {max_spans} "
                         f"and {initial_spans}")
    n, m, n_latch = exact.dims
    if n + n_latch > 255:
        raise ValueError("a spline table addresses at most 256 gain columns (uint8)")
    start = np.asarray(exact.stage_start, dtype=np.int64)
    if np.any(np.diff(start) >= 2 ** 24):
        raise ValueError("a stage of 2^24 ticks or more has knots float32 cannot hold")
    ticks = int(start[-1])
    # Filled in place, kind by kind: one (ticks, m, n + 1 + n_latch) array split afterwards
    # writes every value twice (the split's copies), several times slower on long tables.
    K = np.zeros((ticks, m, n), np.float32)
    k0 = np.zeros((ticks, m), np.float32)
    L = np.zeros((ticks, m, n_latch), np.float32)
    flat = (K.reshape(ticks, m * n), k0, L.reshape(ticks, m * n_latch))
    knots, counts, cols, coefs = [], [], [], []
    bases = _Bases()
    for window in _windows(exact, start, m * (n + 1 + n_latch)):
        # A window's stages fitted together (`_fit_stages`); a failing stage raises, the
        # first first.
        fitted = _fit_stages([YT for _, _, YT in window], [w for w, _, _ in window],
                             tolerance, int(max_spans), int(initial_spans), bases)
        failed = [w for w, _, _ in window if isinstance(fitted[w], Exception)]
        if failed:
            raise fitted[failed[0]]
        for s, keep, _ in window:
            a, b = int(start[s]), int(start[s + 1])
            breaks, C, G = fitted[s]
            inputs, col = np.nonzero(keep)              # the entries of G, in order
            for kind, (first, width) in enumerate(((0, n), (n, 1), (n + 1, n_latch))):
                mine = (col >= first) & (col < first + width)
                flat[kind][a:b, inputs[mine] * width + col[mine] - first] = G[:, mine]
            knots.append(_clamped(breaks.astype(float)))
            counts.extend(keep.sum(axis=1))
            cols.extend(np.flatnonzero(row) for row in keep)
            coefs.append(C.ravel())
    if sum(counts) > np.iinfo(np.uint16).max:
        raise ValueError(f"{sum(counts)} stored entries: row_start (uint16) holds 65535")
    spline = SplineGains(
        knot_start=np.concatenate([[0], np.cumsum([k.size for k in knots])]),
        knot=np.concatenate(knots),
        row_start=np.concatenate([[0], np.cumsum(counts)]),
        col=np.concatenate(cols),
        coef_start=np.concatenate([[0], np.cumsum([c.size for c in coefs])]),
        coef=np.concatenate(coefs), nu=m, nx=n, n_latch=n_latch)
    return spline, K, k0, L


def max_relative_error(spline: SplineGains, exact) -> float:
    """The largest error of `spline`'s stored entries, evaluated as the firmware does, against
    `exact`'s per-tick gains, each relative to the entry's largest magnitude over the stage
    (what `fit_spline`'s tolerance bounds)."""
    start = np.asarray(exact.stage_start, dtype=np.int64)
    fitted = _side_by_side(*evaluate(spline, start)).astype(float)
    Z = gain_columns(exact).astype(float)
    worst = 0.0
    for s in range(spline.n_stages):
        Y, G = Z[start[s]:start[s + 1]], fitted[start[s]:start[s + 1]]
        inputs, cols = spline.entries(s)
        err = np.abs(G[:, inputs, cols] - Y[:, inputs, cols]).max(axis=0, initial=0.0)
        peak = np.abs(Y[:, inputs, cols]).max(axis=0, initial=0.0)
        worst = max(worst, float((err / peak).max(initial=0.0)))
    return worst
