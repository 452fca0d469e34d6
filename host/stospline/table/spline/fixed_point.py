"""Fixed-point (Q15/Q31) spline tables: each stage's gains, in the per-tick Q table's own
scaling (`stospline.table.qformat`), as uniform cubic B-splines with integer coefficients,
evaluated by the firmware in exact integer arithmetic (the compressed format for the
fixed-point arithmetics; the float32 format is `stospline.table.spline.fit`).

Format, per stage s of T_s ticks (concatenated over stages as the float32 spline's arrays)::

    span_log2  uint8  (n_stages,)        k_s: every span of stage s is D = 2^k_s ticks
                                          (0 <= k_s <= 9), S_s = ceil(T_s / D) spans
    row_start  uint16 (n_stages*nu + 1,) entries of (s, i): col[row_start[s*nu+i]:...+1]]
    col        uint8  (n_entries,)       j < nx: K[i][j]; nx: k0[i]; nx+1+c: L[i][c]
    shift      uint8  (n_entries,)       the entry's coefficient scale s_e (1 <= s_e <= 30)
    coef_start uint32 (n_stages + 1,)    coef[coef_start[s]:...]: E_s x (S_s + 3), entry-major
    coef       int16 (Q15) / int32 (Q31)

The gain of entry e at tick tau of its stage (sigma = tau >> k, d = tau & (D - 1)) is the
stored (negated, scaled) Q gain of the per-tick format, computed exactly in integers::

    P0 = (D - d)^3     P1 = 4 D^3 - 3 d^2 (2 D - d)     P3 = d^3     P2 = 6 D^3 - P0 - P1 - P3
    acc = c[sigma] P0 + c[sigma+1] P1 + c[sigma+2] P2 + c[sigma+3] P3          (int64, exact)
    g = (acc + 2^(3k + s_e - 1)) >> (3k + s_e)                                  (round half up)

``P_r / (6 D^3)`` are the uniform cubic B-splines at ``t = d / D`` (they sum to 1), so ``g`` is
the exact B-spline with coefficients ``6 c / 2^s_e`` LSB, rounded half up: no intermediate
rounding, any evaluation order gives the same bits. Bounds: ``P_r <= 4 D^3 <= 2^29`` (uint32),
``|acc| <= 6 D^3 max|c| < 2^61`` (int64). The gains then feed the fixed-point law of the
per-tick table unchanged (`qformat.law_q`), with the table's own latch maps (re-solved for
these gains, `spline_latch.resolve_latch`) and its error bound computed from these gains.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stospline.errors import DesignError
from stospline.firmware_interface import FRAC_BITS
from stospline.table.kernels import qspline_stage
from stospline.table.spline.fit import _lsq, _normal_band, _column_peaks

__all__ = ["QSplineGains", "basis_numerators", "evaluate_q", "fit_q_spline", "q_spline_table",
           "dequantized", "q_spline_bytes", "MAX_SPAN_LOG2", "COEF_BITS"]

MAX_SPAN_LOG2 = 9                   # D <= 512 ticks: 4 D^3 <= 2^29 fits uint32
MAX_SHIFT = 30
COEF_BITS = {"q15": 16, "q31": 32}
_COEF_DTYPE = {"q15": np.int16, "q31": np.int32}
FIELD = "design.spline_tolerance"
# The coefficient scale leaves this much room above the entry's largest value: least-squares
# coefficients overshoot the values a little (a refit with s_e - 1 follows if they still do).
_COEF_HEADROOM = 1.25
# Weight of the curvature penalty of the least squares (`_curvature_band`), against normal
# equations whose diagonal is about (span length) / 3 per coefficient.
CURVATURE = 1e-6


@dataclass(frozen=True)
class QSplineGains:
    """One fixed-point table's gains as uniform cubic B-splines per stage (the module
    docstring's arrays). Entries not stored are exactly zero."""
    span_log2: np.ndarray
    row_start: np.ndarray
    col: np.ndarray
    shift: np.ndarray
    coef_start: np.ndarray
    coef: np.ndarray
    arith: str
    nu: int
    nx: int
    n_latch: int

    _DTYPES = {"span_log2": np.uint8, "row_start": np.uint16, "col": np.uint8,
               "shift": np.uint8, "coef_start": np.uint32}

    def __post_init__(self):
        for name, dtype in self._DTYPES.items():
            object.__setattr__(self, name, np.ascontiguousarray(getattr(self, name), dtype))
        if self.arith not in _COEF_DTYPE:
            raise ValueError(f"arith must be q15 or q31, not {self.arith!r}")
        c = np.asarray(self.coef)
        info = np.iinfo(_COEF_DTYPE[self.arith])
        if c.size and (c.min() < info.min or c.max() > info.max):
            raise ValueError(f"a coefficient is beyond {_COEF_DTYPE[self.arith].__name__}")
        object.__setattr__(self, "coef", np.ascontiguousarray(c, _COEF_DTYPE[self.arith]))
        for name in ("nu", "nx", "n_latch"):
            object.__setattr__(self, name, int(getattr(self, name)))
        if np.any(self.span_log2 > MAX_SPAN_LOG2):
            raise ValueError(f"span_log2 must be at most {MAX_SPAN_LOG2}")
        if self.shift.size and (self.shift.min() < 1 or self.shift.max() > MAX_SHIFT):
            raise ValueError(f"shift must lie in [1, {MAX_SHIFT}]")
        if self.shift.shape != self.col.shape:
            raise ValueError("one shift per entry")

    @property
    def n_stages(self) -> int:
        return int(self.span_log2.size)

    @property
    def n_entries(self) -> int:
        return int(self.col.size)

    @property
    def nbytes(self) -> int:
        return sum(getattr(self, n).nbytes for n in (*self._DTYPES, "coef"))

    def spans(self, s: int, ticks: int) -> int:
        return -(-int(ticks) // (1 << int(self.span_log2[s])))

    def entry_slice(self, s: int) -> slice:
        return slice(int(self.row_start[s * self.nu]), int(self.row_start[(s + 1) * self.nu]))

    def entries(self, s: int) -> tuple[np.ndarray, np.ndarray]:
        rows = self.row_start[s * self.nu:(s + 1) * self.nu + 1].astype(np.int64)
        return np.repeat(np.arange(self.nu), np.diff(rows)), self.col[self.entry_slice(s)]

    def coefficients(self, s: int, ticks: int) -> np.ndarray:
        c = self.coef[self.coef_start[s]:self.coef_start[s + 1]]
        return c.reshape(-1, self.spans(s, ticks) + 3)


def basis_numerators(k: int, tau: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
    """The span index and ``P_0..P_3`` (int64, exact) at ticks `tau` of a stage whose spans are
    ``2^k`` ticks long (the module docstring)."""
    tau = np.asarray(tau, dtype=np.int64)
    D = np.int64(1) << np.int64(k)
    sigma = tau >> np.int64(k)
    d = tau & (D - 1)
    P0 = (D - d) ** 3
    P1 = 4 * D ** 3 - 3 * d * d * (2 * D - d)
    P3 = d ** 3
    P2 = 6 * D ** 3 - P0 - P1 - P3
    return sigma, [P0, P1, P2, P3]


def _stage_gains(k: int, C: np.ndarray, shift: np.ndarray, T: int, numerators=None
                 ) -> np.ndarray:
    """A stage's entries at its ticks 0..T-1 as the firmware computes them: (T, entries) int64;
    `C` (entries, S + 3) integers, `shift` (entries,); `numerators`: ``basis_numerators(k,
    arange(T))`` when the caller has them."""
    sigma, P = numerators if numerators is not None else basis_numerators(k, np.arange(T))
    Ct = np.asarray(C, dtype=np.int64).T
    acc = np.zeros((T, Ct.shape[1]), dtype=np.int64)
    for r in range(4):
        acc += P[r][:, None] * np.take(Ct, sigma + r, axis=0)
    sh = 3 * int(k) + np.asarray(shift, dtype=np.int64)
    return (acc + (np.int64(1) << (sh - 1))[None, :]) >> sh[None, :]


def evaluate_q(spline: QSplineGains, stage_start) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The per-tick integer gains (as stored in a per-tick Q table: negated and scaled) that
    the firmware evaluates from `spline`: K (ticks, nu, nx), k0 (ticks, nu), L (ticks, nu,
    n_latch), int64; 0 where no entry is stored."""
    start = np.asarray(stage_start, dtype=np.int64)
    nx, nu = spline.nx, spline.nu
    Z = np.zeros((int(start[-1]), nu, nx + 1 + spline.n_latch), dtype=np.int64)
    for s in range(spline.n_stages):
        a, b = int(start[s]), int(start[s + 1])
        inputs, cols = spline.entries(s)
        if cols.size:
            Z[a:b, inputs, cols] = _stage_gains(int(spline.span_log2[s]),
                                                spline.coefficients(s, b - a),
                                                spline.shift[spline.entry_slice(s)], b - a)
    return Z[:, :, :nx].copy(), Z[:, :, nx].copy(), Z[:, :, nx + 1:].copy()


def _float_basis(k: int, T: int, numerators=None
                 ) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """Breakpoints (0, D, 2D, ..., T: the last span may be partial), the span index and the
    basis ``P_r / (6 D^3)`` in float64 at ticks 0..T-1 (for the least squares);
    `numerators`: ``basis_numerators(k, arange(T))`` when the caller has them."""
    D = 1 << k
    sigma, P = numerators if numerators is not None else basis_numerators(k, np.arange(T))
    breaks = np.r_[np.arange(0, T, D), T].astype(np.int64)
    return breaks, sigma, [p.astype(float) / (6.0 * D ** 3) for p in P]


def _curvature_band(nb: int) -> np.ndarray:
    """A light penalty on the coefficients' second differences, ``CURVATURE * D2'D2`` as an
    upper band (4, nb): the basis functions that the stage's last, partial span barely reaches
    (a stage of 25 ticks in spans of 16 leaves 7 ticks of the second span) get no huge
    coefficients from the least squares, which the integer format could not hold; the others
    move by about CURVATURE relative (the fit is checked against its tolerance anyway)."""
    band = np.zeros((4, nb))
    if nb >= 3:
        D2 = np.zeros((nb - 2, nb))
        idx = np.arange(nb - 2)
        D2[idx, idx], D2[idx, idx + 1], D2[idx, idx + 2] = 1.0, -2.0, 1.0
        M = D2.T @ D2
        for d in range(3):
            band[d, :nb - d] = np.diagonal(M, d)
    return CURVATURE * band


def _shifts(peak: np.ndarray, bits: int, k: int) -> np.ndarray:
    """Per entry the largest s_e whose coefficients (6 c / 2^s_e = values up to `peak`, with
    headroom) fit a signed `bits` integer, within [1, MAX_SHIFT] and 3k + s_e <= 62."""
    top = float(2 ** (bits - 1) - 1)
    with np.errstate(divide="ignore"):
        s = np.floor(np.log2(top * 6.0 / (_COEF_HEADROOM * np.maximum(peak, 1e-300))))
    return np.clip(s, 1, min(MAX_SHIFT, 62 - 3 * k)).astype(np.int64)


_KEEP_TICKS = 1 << 19     # longer stages keep no basis (80 bytes a tick), as `spline._Bases`


def _uniform_basis(k: int, T: int, bases: dict | None):
    """``(breaks, N, band, numerators)`` of spans of 2^k ticks over T ticks (`_float_basis`,
    its normal band with the curvature penalty, `basis_numerators`), kept in `bases` for the
    next stage of the same length (the 60 s patrol's ten)."""
    hit = None if bases is None else bases.get((k, T))
    if hit is None:
        numerators = basis_numerators(k, np.arange(T))
        breaks, _, N = _float_basis(k, T, numerators)
        band = _normal_band(breaks, N) + _curvature_band(breaks.size + 2)
        hit = breaks, N, band, numerators
        if bases is not None and T <= _KEEP_TICKS:
            bases[(k, T)] = hit
    return hit


def _fit_uniform(YT: np.ndarray, k: int, bits: int, peak: np.ndarray, bases=None):
    """Least squares on spans of 2^k ticks, coefficients rounded to their integer grid; a
    coefficient beyond `bits` lowers its entry's shift and refits. Returns (C, shift), or
    None when a coefficient exceeds `bits` even at shift 1 (a last, partial span that its
    basis functions barely reach can ask for that). `bases`: `_uniform_basis`'s store."""
    E, T = YT.shape
    breaks, N, band, _ = _uniform_basis(k, T, bases)
    Cf = _lsq(breaks, N, YT, band)                      # (E, S + 3), in LSB
    shift = _shifts(peak, bits, k)
    top = 2 ** (bits - 1) - 1
    while True:
        C = np.floor(Cf * (np.ldexp(1.0, shift) / 6.0)[:, None] + 0.5)
        over = np.abs(C).max(axis=1, initial=0.0) > top
        if not over.any():
            break
        if np.any(shift[over] <= 1):
            return None                 # not with spans this long: the caller tries shorter
        shift = np.where(over, shift - 1, shift)
    return C.astype(np.int64), shift


def _evaluated(k: int, C: np.ndarray, shift: np.ndarray, YT: np.ndarray, bases,
               allowed: np.ndarray | None = None):
    """The stage's gains as the firmware evaluates them, G (T, entries) int64, and each
    entry's worst ``|G - y|`` against the values fitted `YT` (entries, T): the table kernel
    (`kernels.qspline_stage`; `tools/bench/table_kernel.py` times it), else numpy
    (`_stage_gains`), the same bits. With `allowed`: None when an entry's error exceeds it
    (the kernel stops there)."""
    out = qspline_stage(k, C, shift, YT, allowed)
    if out is None:
        numerators = _uniform_basis(k, YT.shape[1], bases)[3]
        G = _stage_gains(k, C, shift, YT.shape[1], numerators)
        out = G, np.abs(G.T - YT).max(axis=1, initial=0.0)
        if allowed is not None and not np.all(out[1] <= allowed):
            out = False
    return out or None


def _fit_stage(YT: np.ndarray, tolerance: float, bits: int, max_spans: int, s: int,
               bases: dict | None = None):
    """One stage: the largest span length 2^k whose integer spline meets, for every entry,
    ``|g - y| <= tolerance * peak + 3 / 2^s_e + 1/2`` (the fit's budget, the coefficient grid's
    half step and the gain's rounding). Returns (k, C, shift, G)."""
    E, T = YT.shape
    peak = np.abs(YT).max(axis=1, initial=0.0)
    top_k = min(MAX_SPAN_LOG2, max(0, int(np.floor(np.log2(max(T, 1))))))
    if E == 0:
        return top_k, np.zeros((0, 4), np.int64), np.zeros(0, np.int64), np.zeros((T, 0))
    bases = {} if bases is None else bases
    missed = []
    for k in range(top_k, -1, -1):
        if -(-T // (1 << k)) > max_spans:
            break
        fit = _fit_uniform(YT, k, bits, peak, bases)
        if fit is None:
            continue
        C, shift = fit
        allowed = tolerance * peak + 3.0 / np.ldexp(1.0, shift) + 0.5
        within = _evaluated(k, C, shift, YT, bases, allowed)
        if within is not None:
            return k, C, shift, within[0]
        missed.append((k, C, shift, allowed))
    # No span length: by how much the closest missed (evaluated in full, for the message).
    worst = max((float((_evaluated(k, C, shift, YT, bases)[1] / allowed).max())
                 for k, C, shift, allowed in missed), default=None)
    shortest = max(1, -(-T // max_spans))
    if worst is None:
        raise DesignError(FIELD, f"stage {s}: the fixed-point spline's coefficients exceed "
                                 f"the integer format with spans of {shortest} ticks or more")
    raise DesignError(FIELD, f"stage {s}: the fixed-point spline misses the tolerance "
                             f"{tolerance:g} by {worst:.3g}x or more with spans of "
                             f"{shortest} ticks or more")


def fit_q_spline(scaled: tuple[np.ndarray, np.ndarray, np.ndarray], stage_start, arith: str,
                 tolerance: float, *, max_spans: int = 1024) -> QSplineGains:
    """Fit the scaled, negated gains of a per-tick Q table before rounding (``Ks, k0s, Ls``
    of `qformat.quantize_table`: (ticks, m, n), (ticks, m), (ticks, m, n_latch), float64, in
    the command's LSB) with integer splines (the module docstring).

    Every stored entry is within ``tolerance * peak + 3 / 2^s_e + 1/2`` LSB of its exact value
    at every tick (peak: its largest magnitude over the stage); entries whose magnitude stays
    below 1/2 LSB over a stage (which a per-tick table rounds to 0) are not stored."""
    return _fit_q(scaled, stage_start, arith, tolerance, max_spans)[0]


def _fit_q(scaled, stage_start, arith: str, tolerance: float, max_spans: int):
    """`fit_q_spline` and the integer gains K, k0, L it evaluated at every tick (int64, the
    table's shapes: `evaluate_q` of the result, computed once)."""
    if arith not in COEF_BITS:
        raise ValueError(f"arith must be q15 or q31, not {arith!r}")
    Ks, k0s, Ls = (np.asarray(a, dtype=float) for a in scaled)
    _, m, n = Ks.shape
    n_latch = Ls.shape[2]
    if n + n_latch > 255:
        raise ValueError("a spline table addresses at most 256 gain columns (uint8)")
    # Kind by kind (the columns j < n of K, n of k0, n + 1 + c of L), never concatenated: numpy
    # copies (ticks, m, cols) arrays row by row, rows of a few values.
    kinds = (Ks, k0s[:, :, None], Ls)
    out = tuple(np.zeros(g.shape, dtype=np.int64) for g in kinds)
    first = (0, n, n + 1)
    start = np.asarray(stage_start, dtype=np.int64)
    bases = {}                          # (k, T) -> `_uniform_basis`: equal stages share it
    logs, counts, cols, shifts, coefs = [], [], [], [], []
    for s in range(start.size - 1):
        a, b = int(start[s]), int(start[s + 1])
        keep = [_column_peaks(g[a:b].reshape(b - a, -1)).reshape(m, -1) >= 0.5 for g in kinds]
        # Entries input by input, columns ascending: the format's order.
        rows = [(g, i, np.flatnonzero(kept[i]), j0) for i in range(m)
                for g, kept, j0 in zip(kinds, keep, first)]
        YT = np.ascontiguousarray(
            np.concatenate([g[a:b, i, sel] for g, i, sel, _ in rows], axis=1).T)
        k, C, shift, G = _fit_stage(YT, float(tolerance), COEF_BITS[arith], max_spans, s,
                                    bases)
        e = 0
        for (g, i, sel, _), o in zip(rows, out * m):
            o[a:b, i, sel] = G[:, e:e + sel.size]
            e += sel.size
        logs.append(k)
        counts.extend(sum(int(kept[i].sum()) for kept in keep) for i in range(m))
        cols.append(np.concatenate([sel + j0 for _, _, sel, j0 in rows]))
        shifts.append(shift)
        coefs.append(C.ravel())
    if sum(counts) > np.iinfo(np.uint16).max:
        raise ValueError(f"{sum(counts)} stored entries: row_start (uint16) holds 65535")
    spline = QSplineGains(
        span_log2=np.array(logs), row_start=np.concatenate([[0], np.cumsum(counts)]),
        col=np.concatenate(cols), shift=np.concatenate(shifts),
        coef_start=np.concatenate([[0], np.cumsum([c.size for c in coefs])]),
        coef=np.concatenate(coefs), arith=arith, nu=m, nx=n, n_latch=n_latch)
    return spline, out[0], out[1].reshape(-1, m), out[2]


_PTR = 4
_Q_SPLINE_HEADER = 2 * 4 + 6 * _PTR      # n_entries, n_coef; six array pointers


def q_spline_bytes(spline: QSplineGains) -> int:
    """Bytes of a Q spline's gains on a 32-bit target: its six arrays (one element at least
    each) and a header of two counts and six pointers."""
    return sum(max(getattr(spline, n).size, 1) * getattr(spline, n).itemsize
               for n in ("span_log2", "row_start", "col", "shift", "coef_start", "coef")) \
        + _Q_SPLINE_HEADER


def dequantized(ft):
    """The real-valued law of fixed-point table `ft` (a `qformat.FixedPointTable`): its integer
    gains and latch maps in real units (exact in float64), as a float64 `GainTable` the moment
    oracle and the latch re-solve read; the command's final rounding, which is not linear, is
    the error bound's."""
    return _real_law(ft.source, ft.name, ft.frac_bits, (ft.x_exp, ft.u_exp, ft.v_exp),
                     (ft.K, ft.k0, ft.L, ft.Lambda, ft.lambda0))


def _real_law(source, name: str, F: int, exponents, q_entries):
    """`dequantized` of the integer entries ``Kq, k0q, Lq, Lamq, lam0q`` in the scales
    ``x_exp, u_exp, v_exp``, without assembling their table (the re-solve reads the law
    only)."""
    from dataclasses import replace
    x_exp, u_exp, v_exp = (np.asarray(e, dtype=int) for e in exponents)
    Kq, k0q, Lq, Lamq, lam0q = q_entries
    # Integers times minus a power of two (exact): cast, then scaled in place.
    K, k0, L = (np.asarray(a).astype(float) for a in (Kq, k0q, Lq))
    K *= -np.ldexp(1.0, u_exp[None, :, None] - x_exp[None, None, :] - F)
    k0 *= -np.ldexp(1.0, u_exp[None, :] - F)
    L *= -np.ldexp(1.0, u_exp[None, :, None] - v_exp[None, None, :] - F)
    Lam = np.asarray(Lamq, float) * np.ldexp(1.0, v_exp[None, :, None]
                                             - x_exp[None, None, :] - F)
    lam0 = np.asarray(lam0q, float) * np.ldexp(1.0, v_exp[None, :] - F)
    return replace(source, name=name, K=K, k0=k0, L=L, Lambda=Lam, lambda0=lam0, spline=None)


def q_spline_table(problem, exact, arith: str, x_range, tolerance: float, *,
                   name: str | None = None, max_spans: int = 1024, resolve: bool = True,
                   varying_maps=None):
    """The Q15/Q31 spline table of a design: a `qformat.FixedPointTable` whose ``spline`` is
    the `QSplineGains` the firmware stores and whose K, k0, L are their evaluation, tick by
    tick (`evaluate_q`), with the latch maps re-solved for those gains and then rounded, and
    the error bound of every tick against the design's double law computed from the gains as
    evaluated (`qformat.assemble`).

    Parameters
    ----------
    problem : Problem
    exact : GainTable
        The design's law in double precision, ``table_of(design, quantize=False)``.
    arith : {"q15", "q31"}
    x_range : array_like (n,)
        The state ranges the scales cover (`qformat.quantize_table`).
    tolerance : float
        The fit's budget per entry, relative to its largest magnitude in the stage
        (`fit_q_spline`).
    resolve : bool
        Re-solve the latch maps for the spline's gains (`spline_latch.resolve_latch`); False
        keeps the design's.
    varying_maps : callable, optional
        The per-tick mean maps of time-varying stage data (`spline_latch.resolve_latch`).

    Raises
    ------
    DesignError
        ``design.spline_tolerance`` when a stage cannot meet the tolerance, ``design.table``
        when the latch cannot be re-solved (as for float32 spline tables) or the row sums
        cannot be kept within the format.
    ValueError
        As `qformat.quantize_table` (scales beyond the firmware's exponents).
    """
    from stospline.table.qformat import (_rhu, assemble, row_sums, scale_exponents,
                                         scaled_entries, EXP_MAX)
    from stospline.table.spline.latch import resolve_latch
    # The per-tick Q table's scales (`qformat.quantize_table`), without quantizing it.
    x_exp, u_exp, v_exp = (np.asarray(e, dtype=int).copy()
                           for e in scale_exponents(exact, arith, x_range))
    F = FRAC_BITS[arith]
    qmax = (1 << F) - 1
    start = np.asarray(exact.stage_start, dtype=np.int64)
    for _ in range(8):
        scaled = scaled_entries(exact, F, x_exp, u_exp, v_exp)
        spline, Kq, k0q, Lq = _fit_q(scaled[:3], start, arith, tolerance, max_spans)
        if resolve:
            law = _real_law(exact, f"{exact.name}_{arith}", F, (x_exp, u_exp, v_exp),
                            (Kq, k0q, Lq, _rhu(scaled[3]), _rhu(scaled[4])))
            Lam, lam0 = resolve_latch(problem, law, varying_maps=varying_maps)
            Lamq = _rhu(Lam * np.ldexp(1.0, x_exp[None, None, :] - v_exp[None, :, None] + F))
            lam0q = _rhu(lam0 * np.ldexp(1.0, F - v_exp[None, :]))
        else:
            Lamq, lam0q = _rhu(scaled[3]), _rhu(scaled[4])
        law_rows, latch_rows = row_sums(Kq, k0q, Lq, Lamq, lam0q)
        over_u = law_rows.max(axis=0, initial=0) > qmax
        over_v = latch_rows.max(axis=0, initial=0) > qmax if latch_rows.size else \
            np.zeros(v_exp.size, bool)
        if not over_u.any() and not over_v.any():
            break
        # A row the spline (or the re-solved latch) pushed past 2^F - 1: one more bit of
        # scale for that input or multiplier, and fit again.
        u_exp = u_exp + over_u
        v_exp = v_exp + over_v
        if max(np.abs(u_exp).max(initial=0), np.abs(v_exp).max(initial=0)) > EXP_MAX:
            break
    else:
        over_u = np.ones(1, bool)
    if over_u.any() or over_v.any():
        raise DesignError("design.table", f"the {arith} spline's gains or latch maps exceed "
                                          f"the format's row sums whatever the scales")
    ft = assemble(exact, arith, x_range, (x_exp, u_exp, v_exp), (Kq, k0q, Lq, Lamq, lam0q),
                  scaled, name=name or f"{exact.name}_{arith}_spline")
    object.__setattr__(ft, "spline", spline)
    return ft
