"""Flash a design's tables take, per arithmetic, computed from the dimensions the way
`stospline.table.codegen` lays them out (one ``static const`` array per field, at least one
element each, plus the ``stsp_table_t`` header) on a 32-bit target (4-byte pointers, as on
Cortex-M). A test checks the numbers against the symbol sizes of the compiled C.
"""
from __future__ import annotations

from stospline.firmware_interface import ELEMENT_BYTES

__all__ = ["flash_bytes", "spline_bytes", "ARITH_ELEMENT_BYTES"]

ARITH_ELEMENT_BYTES = ELEMENT_BYTES
_PTR = 4                               # pointer size on the 32-bit targets
_HEADER_FIELDS = 4 + 6 * 2 + 2 * 4     # magic; version, kind, nx, nu, n_latch, n_stages; ticks, hz
_HEADER_TAIL = 4 + 32                  # crc32, problem_sha256
_TABLE_POINTERS = 10 + 2               # stage_start .. u_hold, band_qp, spline
_SPLINE_HEADER = 3 * 4 + 6 * _PTR      # n_knots, n_entries, n_coef; six array pointers
_FIXED_POINTERS = 3                    # x_exp, u_exp, v_exp
_BANDQP_HEADER = 2 * 2 + 5 * _PTR      # q, nx; Nt, mt, W, lo, hi


def _count(k: int) -> int:
    return max(int(k), 1)              # codegen writes an empty array as one zero


def spline_bytes(spline) -> int:
    """Bytes of a spline table's gains (`stospline.table.spline.fit.SplineGains`): its arrays, one
    element at least each, and its `stsp_spline_t`; float32 only."""
    sizes = ((spline.knot_start, 4), (spline.knot, 4), (spline.row_start, 2), (spline.col, 1),
             (spline.coef_start, 4), (spline.coef, 4))
    return sum(b * _count(a.size) for a, b in sizes) + _SPLINE_HEADER


def flash_bytes(table, arith: str = "float32") -> int:
    """Bytes of flash for `table` (a `GainTable`, or anything with ``dims``, ``n_ticks``,
    ``n_stages`` and ``band_qp``) written in arithmetic `arith` (float32, q15 or q31).
    A band table's dual (``band_qp``, float64) is counted for float32, the only arithmetic
    that re-solves it."""
    if arith not in ARITH_ELEMENT_BYTES:
        raise ValueError(f"arith must be one of {sorted(ARITH_ELEMENT_BYTES)}, got {arith!r}")
    n, m, n_latch = table.dims
    T, S = table.n_ticks, table.n_stages
    e = ARITH_ELEMENT_BYTES[arith]
    total = 4 * _count(S + 1) + 2 * _count(S)                       # stage_start, stage_n_latch
    spline = getattr(table, "spline", None)
    if spline is None:
        total += e * (_count(T * m * n) + _count(T * m) + _count(T * m * n_latch))  # K, k0, L
    elif hasattr(spline, "span_log2"):
        # a fixed-point spline (`stospline.table.spline.fixed_point`), linked as a float32 one
        from stospline.table.spline.fixed_point import q_spline_bytes
        total += q_spline_bytes(spline) + _PTR
    else:
        # + the pointer that links the spline code with the table (stsp_spline_t.ops)
        total += spline_bytes(spline) + _PTR
    total += e * (_count(S * n_latch * n) + _count(S * n_latch) + 3 * _count(m))  # Lambda, lambda0, u_min/max/hold
    total += _HEADER_FIELDS + _PTR * _TABLE_POINTERS + _HEADER_TAIL
    if arith == "float32":
        band = getattr(table, "band_qp", None)
        if band is not None:
            q = band.q
            # + the pointer that links the band solver with the table (stsp_bandqp_t.solve_f32)
            total += 8 * (_count(q * n) + 3 * _count(q) + _count(q * q)) + _BANDQP_HEADER + _PTR
    else:
        total += _count(n) + _count(m) + _count(n_latch) + _PTR * _FIXED_POINTERS   # int8 exponents
    return total
