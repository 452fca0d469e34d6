"""Fixed-point (Q15/Q31) gain tables: scaling, quantization, error bound, reference law.

The firmware's fixed-point variants (``STSP_ARITH_Q15``/``STSP_ARITH_Q31``) take the state as
integers ``x_q[j]`` with a per-state power-of-two scale and return integer commands::

    x[j] = x_q[j] 2^(x_exp[j] - F),   u[i] = u_q[i] 2^(u_exp[i] - F),   v[c] = v_q[c] 2^(v_exp[c] - F)

with ``F`` = 15 (Q15, int16) or 31 (Q31, int32) fractional bits and every integer in
``[-2^F, 2^F - 1]``. The gains carry the scales and are stored negated (so that a tick is a
plain sum of products: one multiply-accumulate instruction per term)::

    K_q[t][i][j] = rhu(-K_ij(t) 2^(x_exp[j] - u_exp[i] + F))   k0_q[t][i] = rhu(-k0_i(t) 2^(F - u_exp[i]))
    L_q[t][i][c] = rhu(-L_ic(t) 2^(v_exp[c] - u_exp[i] + F))
    Lambda_q[s][c][j] = rhu(Lambda_cj 2^(x_exp[j] - v_exp[c] + F))   lambda0_q[s][c] = rhu(lambda0_c 2^(F - v_exp[c]))

where ``rhu(y) = floor(y + 1/2)`` (round half up). Per tick the firmware computes, exactly in a
wide accumulator, ``u_q[i] = rhu((k0_q 2^F + sum K_q x_q + sum L_q v_q) / 2^F)`` and the latch
``v_q[c] = rhu((lambda0_q 2^F + sum Lambda_q x_q) / 2^F)`` (`law_q`, `latch_q` reproduce it bit
for bit).

Scales (`quantize_table`). ``x_exp[j] = ceil(log2(range_j))`` from the state range the caller
gives (`state_range`: ``max_t |E x_j(t)| + sigmas * std x_j(t)`` over the plan, from the exact
moment oracle, ``sigmas`` = 6 by default). ``v_exp[c]`` and ``u_exp[i]`` are the smallest
exponents for which every row's absolute sum, after rounding, is at most ``2^F - 1``::

    |lambda0_q| + sum_j |Lambda_q|  <= 2^F - 1     (every stage, every latched c)
    |k0_q| + sum_j |K_q| + sum_c |L_q| <= 2^F - 1  (every tick, every input)

which is exactly what the firmware's ``stsp_init`` requires: then no sum overflows its
accumulator and no ``u_q``/``v_q`` leaves the Q range for any integer state, and the command
range covers the worst corner of the state box (no saturation for in-range states).

Error bound (`FixedPointTable.bound`, derived in docs/guide/firmware.md). For every integer state (any
``x_q``, i.e. every state within the range) and latch state, in units of the command's LSB
``2^(u_exp[i] - F)``::

    |u_fixed - u_double| <= 1/2 + dk0 + sum_j dK_j + sum_c (dL_c + |L~_c| / 2^F * eps_c)
    eps_c = 1/2 + dlambda0_c + sum_j dLambda_cj               (latch error, v's LSB units)

with ``d*`` the actual rounding error of each stored entry (at most 1/2) and ``L~`` the
unrounded scaled gain; ``u_double`` is the design's law in double precision at the same real
state (``x = x_q 2^(x_exp - F)``) and the same latch state.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from decimal import Decimal, localcontext

import numpy as np

from stospline import limits
from stospline.firmware_interface import ARITHS, FRAC_BITS, SCALAR_KIND
from stospline.precision import RoundedUp, ceil_significant
from stospline.table.format import F32_MAX, GainTable, TableShape
from stospline.table_options import DEFAULT_SIGMAS

__all__ = ["FixedPointTable", "quantize_table", "scale_exponents", "scaled_entries",
           "row_sums", "assemble",
           "state_range", "law_q", "latch_q", "law_double",
           "ARITHS", "FRAC_BITS", "SCALAR_KIND", "EXP_MAX", "DEFAULT_SIGMAS"]

EXP_MAX = limits.Q_EXP_MAX  # the firmware refuses scale exponents beyond +-60
_EXP_SPAN = 24          # a state whose range is tiny gets at least 2^-24 of the largest one
# The bound as written (summary JSON, generated header): rounded UP to BOUND_DIGITS significant
# digits after adding a margin of 3 GAIN_AGREEMENT 2^F LSB. Why: the bound adds the rounding
# residuals |G_q - G~| of gains scaled by up to 2^F, and the last bits of the double gains differ
# between machines by a relative d (measured: 1.5e-14). A residual moves by at most |dG~| (also
# when G~ crosses a rounding boundary: it is 1/2 on both sides), so a row's bound moves by at most
# d times its sums of |G~| (law and latch rows, each at most 2^F - 1 + terms / 2): below
# d (2 2^F + 2n + 2P + 4) (docs/guide/firmware.md, "Error bound"). GAIN_AGREEMENT = 1e-12 is 70 times
# the measured d: a margin of 6.4e-3 LSB in Q31, 1e-7 LSB in Q15, so the written bound holds for
# every machine's double law. At 3 digits a new design's written bound differs between machines
# with a probability below 1e-3 per input (the robot's moved by 2.5e-7 LSB in Q31).
BOUND_DIGITS = 3
GAIN_AGREEMENT = 1e-12


def _rhu(y: np.ndarray) -> np.ndarray:
    """Round half up to int64 (exact: y is a float64 times a power of two, |y| < 2^52)."""
    return np.floor(np.asarray(y, dtype=float) + 0.5).astype(np.int64)


@dataclass(frozen=True)
class FixedPointTable(TableShape):
    """A Q15/Q31 table as the firmware stores it (integers in int64 arrays), with its scales,
    the double-precision table it came from, and the per-tick error bound.

    Same shapes and layout as `GainTable` (the law's gains stored negated, see the module
    docstring). ``bound[t, i]`` is the bound on ``|u_fixed - u_double|`` of input i at tick t,
    in the command's real units; ``bound_lsb`` the same in units of ``2^(u_exp[i] - F)``.
    """
    name: str
    arith: str
    tick_hz: int
    t0: float
    stage_start: np.ndarray
    stage_n_latch: np.ndarray
    K: np.ndarray
    k0: np.ndarray
    L: np.ndarray
    Lambda: np.ndarray
    lambda0: np.ndarray
    u_min: np.ndarray
    u_max: np.ndarray
    u_hold: np.ndarray
    x_exp: np.ndarray
    u_exp: np.ndarray
    v_exp: np.ndarray
    problem_sha256: str
    source: GainTable = field(repr=False)
    x_range: np.ndarray = field(repr=False)
    bound_lsb: np.ndarray = field(repr=False)
    # A fixed-point spline table (`stospline.table.spline.fixed_point.QSplineGains`): K, k0, L are then
    # its evaluation, tick by tick, exactly as the firmware computes it.
    spline: object | None = field(default=None, repr=False)

    @property
    def frac_bits(self) -> int:
        return FRAC_BITS[self.arith]

    @property
    def scalar_kind(self) -> int:
        return SCALAR_KIND[self.arith]

    @property
    def u_lsb(self) -> np.ndarray:
        """Real value of one command unit, per input: 2^(u_exp - F)."""
        return np.ldexp(1.0, self.u_exp.astype(int) - self.frac_bits)

    @property
    def x_lsb(self) -> np.ndarray:
        return np.ldexp(1.0, self.x_exp.astype(int) - self.frac_bits)

    @property
    def bound(self) -> np.ndarray:
        return self.bound_lsb * self.u_lsb

    @property
    def limited(self) -> bool:
        one = 1 << self.frac_bits
        return bool(np.any(self.u_min > -one) or np.any(self.u_max < one - 1))

    def stage_of_tick(self, j) -> np.ndarray:
        return np.searchsorted(self.stage_start, j, side="right") - 1

    def latch_stage(self, stage) -> np.ndarray:
        """The stage whose latch a tick of `stage` uses: the last one at or before it that
        latches (stage_n_latch > 0); -1 when none does (v = 0)."""
        latching = np.where(self.stage_n_latch > 0, np.arange(self.n_stages), -1)
        return np.maximum.accumulate(latching)[np.asarray(stage)]

    def summary(self) -> dict:
        """The scales and the error bound, for the JSON summary."""
        return {
            "arith": self.arith, "frac_bits": self.frac_bits,
            "x_exp": self.x_exp.tolist(), "u_exp": self.u_exp.tolist(),
            "v_exp": self.v_exp.tolist(),
            "x_range": np.ldexp(1.0, self.x_exp.astype(int)).tolist(),
            "x_range_predicted": self.x_range.tolist(),
            "u_lsb": self.u_lsb.tolist(),
            "u_error_bound": self.written_bound(),
            "u_error_bound_lsb": self.written_bound_lsb(),
        }

    def written_bound_lsb(self) -> list[RoundedUp]:
        """Per input, the bound (max over ticks) in LSBs as written: at most 3 significant
        digits, rounded up with a margin over the last bits of the gains (see BOUND_DIGITS)."""
        margin = Decimal(3 * GAIN_AGREEMENT * 2.0 ** self.frac_bits)
        with localcontext(prec=100):  # exact: no sum or product below is rounded
            return [ceil_significant(Decimal(b) + margin, BOUND_DIGITS)
                    for b in self.bound_lsb.max(axis=0)]

    def written_bound(self) -> list[RoundedUp]:
        """`written_bound_lsb` in the command's units, rounded up again to 3 digits."""
        with localcontext(prec=100):
            return [ceil_significant(Decimal(repr(b)) * Decimal(lsb), BOUND_DIGITS)
                    for b, lsb in zip(self.written_bound_lsb(), self.u_lsb)]


def scalable_ranges(r: np.ndarray) -> np.ndarray:
    """State ranges with each zero (a state never driven, without noise) replaced by the
    smallest range `quantize_table` allows (2^-_EXP_SPAN of the largest): it still needs a
    scale."""
    r = np.asarray(r, dtype=float)
    top = float(r.max()) if r.size and r.max() > 0 else 1.0
    return np.where(r > 0, r, top * 2.0 ** -_EXP_SPAN)


def _exponent(r: np.ndarray, terms: int, F: int) -> np.ndarray:
    """Smallest e with r 2^(F - e) + terms / 2 <= 2^F - 1 (rounding of `terms` entries can add
    1/2 each); 0 where r = 0."""
    room = (2.0 ** F - 1) - terms / 2.0
    with np.errstate(divide="ignore"):
        e = np.ceil(np.log2(np.where(r > 0, r, 1.0) * 2.0 ** F / room))
    return np.where(r > 0, e, 0).astype(int)


def _abs_times(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``|A| @ x`` over the last axis, summed left to right elementwise: a stacked product
    with a vector costs numpy a call per matrix (60 000 on the 60 s patrol)."""
    acc = np.abs(A[..., 0]) * x[0]
    for j in range(1, A.shape[-1]):
        acc += np.abs(A[..., j]) * x[j]
    return acc


def scale_exponents(table: GainTable, arith: str, x_range
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``x_exp, u_exp, v_exp``: the scales `quantize_table` gives `table` (the module
    docstring), without quantizing it (a spline table starts from them). Raises ValueError
    as `quantize_table`."""
    if arith not in FRAC_BITS:
        raise ValueError(f"arith must be one of {list(FRAC_BITS)}, got {arith!r}")
    F = FRAC_BITS[arith]
    n, _, n_latch = table.dims
    x_range = np.asarray(x_range, dtype=float).reshape(-1)
    if x_range.shape != (n,) or not np.all(np.isfinite(x_range)) or np.any(x_range <= 0):
        raise ValueError(f"x_range must hold {n} positive finite magnitudes")
    x_exp = np.ceil(np.log2(x_range)).astype(int)
    x_exp = np.maximum(x_exp, x_exp.max() - _EXP_SPAN)
    K, k0, L = (np.asarray(a, dtype=float) for a in (table.K, table.k0, table.L))
    Lam, lam0 = np.asarray(table.Lambda, dtype=float), np.asarray(table.lambda0, dtype=float)
    sx = np.ldexp(1.0, x_exp)

    # v scale: one exponent per column over the whole plan (v keeps its meaning across stages).
    r_v = (np.abs(lam0) + _abs_times(Lam, sx)).max(axis=0) if n_latch else np.zeros(0)
    v_exp = _exponent(r_v, n + 1, F)
    sv = np.ldexp(1.0, v_exp)
    # (A column's maximum over the ticks by `_column_peaks`: numpy reduces the first axis of
    # a few columns row by row, 8x slower on the 60 s patrol.)
    from stospline.table.spline.fit import _column_peaks   # the fitter: not for float32
    r_u = _column_peaks(np.abs(k0) + _abs_times(K, sx)
                        + (_abs_times(L, sv) if n_latch else 0.0))
    # The safe command must be representable too (a hover thrust may exceed every command).
    r_u = np.maximum(r_u, 2.0 * np.abs(np.asarray(table.u_hold, dtype=float)))
    u_exp = _exponent(r_u, n + n_latch + 1, F)
    for what, e in (("state", x_exp), ("command", u_exp), ("multiplier", v_exp)):
        if e.size and np.abs(e).max() > EXP_MAX:
            worst = int(e[np.argmax(np.abs(e))])
            raise ValueError(f"a {what} scale exponent would be {worst}, beyond the firmware's "
                             f"+-{EXP_MAX} (STSP_Q_EXP_MAX): gains or state range too extreme "
                             f"for the fixed-point format")
    return x_exp, u_exp, v_exp


def quantize_table(table: GainTable, arith: str, x_range, *, name: str | None = None
                   ) -> FixedPointTable:
    """Quantize a double-precision table (``build_table(..., quantize=False)``) to Q15/Q31.

    Parameters
    ----------
    table : GainTable
        The design's gains in double precision.
    arith : {"q15", "q31"}
    x_range : array_like, shape (n,)
        Positive state magnitudes the scales must cover (e.g. `state_range`); the
        representable range of state j is ``[-2^x_exp[j], 2^x_exp[j])`` with
        ``x_exp[j] = ceil(log2(x_range[j]))``.
    name : str, optional
        C prefix of the generated tables (default ``<table name>_<arith>``).

    Raises
    ------
    ValueError
        Unknown `arith`, a non-positive or non-finite range, or a scale exponent beyond
        +-EXP_MAX (gains or ranges too extreme for the format).
    """
    x_exp, u_exp, v_exp = scale_exponents(table, arith, x_range)
    F = FRAC_BITS[arith]
    qmax = (1 << F) - 1
    Ks, k0s, Ls, Lams, lam0s = scaled_entries(table, F, x_exp, u_exp, v_exp)
    Kq, k0q, Lq, Lamq, lam0q = (_rhu(a) for a in (Ks, k0s, Ls, Lams, lam0s))
    law_rows, latch_rows = row_sums(Kq, k0q, Lq, Lamq, lam0q)
    assert law_rows.max(initial=0) <= qmax and latch_rows.max(initial=0) <= qmax, \
        "exponent choice must keep every row sum within 2^F - 1"
    return assemble(table, arith, x_range, (x_exp, u_exp, v_exp), (Kq, k0q, Lq, Lamq, lam0q),
                    (Ks, k0s, Ls, Lams, lam0s), name=name)


def scaled_entries(table, F: int, x_exp, u_exp, v_exp) -> tuple[np.ndarray, ...]:
    """``Ks, k0s, Ls, Lams, lam0s``: `table`'s entries scaled to the Q format of the given
    exponents, gains negated (the module docstring), before rounding (float64)."""
    x_exp, u_exp, v_exp = (np.asarray(e, dtype=int) for e in (x_exp, u_exp, v_exp))
    K, k0, L = (np.asarray(a, dtype=float) for a in (table.K, table.k0, table.L))
    Lam, lam0 = np.asarray(table.Lambda, dtype=float), np.asarray(table.lambda0, dtype=float)
    # Times minus a power of two: exactly -(x 2^e), in one pass over the 60 s patrol's ticks.
    Ks = K * -np.ldexp(1.0, x_exp[None, None, :] - u_exp[None, :, None] + F)
    k0s = k0 * -np.ldexp(1.0, F - u_exp[None, :])
    Ls = L * -np.ldexp(1.0, v_exp[None, None, :] - u_exp[None, :, None] + F)
    Lams = Lam * np.ldexp(1.0, x_exp[None, None, :] - v_exp[None, :, None] + F)
    lam0s = lam0 * np.ldexp(1.0, F - v_exp[None, :])
    return Ks, k0s, Ls, Lams, lam0s


def _abs_row_sums(A: np.ndarray) -> np.ndarray:
    """``|A|`` summed over the last axis, column by column (integers: any order is exact;
    numpy reduces a short last axis slowly, 60 000 rows of 4 on the patrol)."""
    acc = np.abs(A[..., 0]) if A.shape[-1] else np.zeros(A.shape[:-1], dtype=A.dtype)
    for j in range(1, A.shape[-1]):
        acc += np.abs(A[..., j])
    return acc


def row_sums(Kq, k0q, Lq, Lamq, lam0q) -> tuple[np.ndarray, np.ndarray]:
    """The law's row sums (ticks, m) and the latch's (stages, n_latch) of integer entries,
    each of which the firmware requires to be at most 2^F - 1."""
    law_rows = np.abs(k0q) + _abs_row_sums(np.asarray(Kq)) + _abs_row_sums(np.asarray(Lq))
    latch_rows = np.abs(lam0q) + _abs_row_sums(np.asarray(Lamq))
    return law_rows, latch_rows


# The bound's sums run left to right over the last axis, a column at a time: the same bits on
# every machine and numpy version (numpy's reductions and einsum choose their own order), and
# temporaries of one column (ticks, m) that stay in the cache, not of the whole table.
def _abs_error_sums(q: np.ndarray, s: np.ndarray) -> np.ndarray:
    """``sum_j |q[..., j] - s[..., j]|`` (float64), j = 0, 1, ... in turn."""
    acc = np.zeros(q.shape[:-1])
    for j in range(q.shape[-1]):
        acc += np.abs(q[..., j] - s[..., j])
    return acc


def _latch_error_sums(Ls: np.ndarray, eps_t: np.ndarray) -> np.ndarray:
    """``sum_c |Ls[t, i, c]| eps_t[t, c]`` (ticks, m), c = 0, 1, ... in turn."""
    acc = np.zeros(Ls.shape[:-1])
    for c in range(Ls.shape[-1]):
        acc += np.abs(Ls[..., c]) * eps_t[:, c, None]
    return acc


def assemble(table: GainTable, arith: str, x_range, exponents, q_entries, scaled,
             *, name: str | None = None) -> FixedPointTable:
    """The `FixedPointTable` of integer entries `q_entries` (``Kq, k0q, Lq, Lamq, lam0q``) in
    the scales `exponents` (``x_exp, u_exp, v_exp``), with `table`'s limits and safe command
    converted, and the error bound of each tick against `table`'s double law, whose scaled
    entries are `scaled` (``scaled_entries``; the module docstring's bound, with each entry's
    actual error, whatever its size)."""
    F = FRAC_BITS[arith]
    one, qmax = 1 << F, (1 << F) - 1
    _, m, n_latch = table.dims
    x_exp, u_exp, v_exp = (np.asarray(e, dtype=int) for e in exponents)
    Kq, k0q, Lq, Lamq, lam0q = q_entries
    Ks, k0s, Ls, Lams, lam0s = scaled
    # Limits in command units, rounded inwards so the clamp never passes the real limit.
    lo, hi = np.asarray(table.u_min, float), np.asarray(table.u_max, float)
    scale_u = np.ldexp(1.0, F - u_exp)
    u_min = np.where(lo <= -F32_MAX, -one, np.maximum(-one, np.ceil(lo * scale_u))).astype(np.int64)
    u_max = np.where(hi >= F32_MAX, qmax, np.minimum(qmax, np.floor(hi * scale_u))).astype(np.int64)
    # The safe command to the nearest unit, kept within the rounded-inward limits.
    u_hold = np.clip(_rhu(np.asarray(table.u_hold, float) * scale_u), u_min, u_max).astype(np.int64)

    # Error bound (module docstring): per tick and input, in command LSBs.
    stage_of = np.searchsorted(table.stage_start, np.arange(table.n_ticks), side="right") - 1
    ft = FixedPointTable(name or f"{table.name}_{arith}", arith, table.tick_hz, table.t0,
                    np.asarray(table.stage_start, np.uint32), np.asarray(table.stage_n_latch, np.uint16),
                    Kq, k0q, Lq, Lamq, lam0q, u_min, u_max, u_hold, x_exp.astype(np.int8),
                    u_exp.astype(np.int8), v_exp.astype(np.int8), table.problem_sha256,
                    table, x_range, np.zeros((table.n_ticks, m)))
    eps = 0.5 + np.abs(lam0q - lam0s) + np.abs(Lamq - Lams).sum(axis=2)        # (S, n_latch)
    eps = np.where(np.arange(n_latch)[None, :] < np.asarray(table.stage_n_latch)[:, None], eps, 0.0)
    ls = ft.latch_stage(stage_of)
    eps_t = np.where((ls >= 0)[:, None], eps[np.maximum(ls, 0)], 0.0)            # (T, n_latch)
    bound = 0.5 + np.abs(k0q - k0s)
    bound += _abs_error_sums(Kq, Ks)
    bound += _abs_error_sums(Lq, Ls)
    bound += _latch_error_sums(Ls, eps_t) / one
    object.__setattr__(ft, "bound_lsb", bound)
    return ft


def latch_q(ft: FixedPointTable, stage: np.ndarray, X: np.ndarray) -> np.ndarray:
    """v_q latched at `stage` (per row) from integer states X (N, n), bit-exact with the C."""
    F = ft.frac_bits
    n_latch = ft.dims[2]
    stage = np.asarray(stage)
    acc = (ft.lambda0[stage] << F) + np.einsum("ncj,nj->nc", ft.Lambda[stage], X)
    V = (acc + (1 << (F - 1))) >> F
    return np.where(np.arange(n_latch)[None, :] < ft.stage_n_latch[stage][:, None], V, 0)


def law_q(ft: FixedPointTable, tick: np.ndarray, X: np.ndarray, V: np.ndarray) -> np.ndarray:
    """u_q at ticks `tick` (N,) from X (N, n) and V (N, n_latch), bit-exact with the C (unclamped;
    int64 is exact: every row sum is at most (2^F - 1) 2^F in magnitude)."""
    F = ft.frac_bits
    tick = np.asarray(tick)
    acc = ((ft.k0[tick] << F) + np.einsum("nij,nj->ni", ft.K[tick], X)
           + np.einsum("nic,nc->ni", ft.L[tick], V))
    return (acc + (1 << (F - 1))) >> F


def law_double(ft: FixedPointTable, tick: np.ndarray, x: np.ndarray, x_latch: np.ndarray
               ) -> np.ndarray:
    """The design's law in double precision: u = -K x - k0 - L v, v latched from x_latch at the
    tick's latch stage (rows beyond stage_n_latch zero), from the unquantized source table."""
    src = ft.source
    tick = np.asarray(tick)
    ls = ft.latch_stage(ft.stage_of_tick(tick))
    n_latch = ft.dims[2]
    lsc = np.maximum(ls, 0)
    v = np.asarray(src.lambda0, float)[lsc] + np.einsum(
        "ncj,nj->nc", np.asarray(src.Lambda, float)[lsc], x_latch)
    keep = (np.arange(n_latch)[None, :] < ft.stage_n_latch[lsc][:, None]) & (ls >= 0)[:, None]
    v = np.where(keep, v, 0.0)
    K, k0, L = (np.asarray(a, float)[tick] for a in (src.K, src.k0, src.L))
    return -(np.einsum("nij,nj->ni", K, x) + k0 + np.einsum("nic,nc->ni", L, v))
