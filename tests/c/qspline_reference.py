#!/usr/bin/env python3
"""Expected values for tests/c/test_qspline.c, computed independently of the firmware and of
stospline.table.spline.fixed_point: the fixed-point spline format's gains as exact rationals
(`fractions.Fraction`: the uniform cubic B-splines at t = d / D times the coefficients
6 c / 2^s, rounded half up). Prints the C constants test_qspline.c pastes
(QSPLINE_EXPECTED, QSPLINE_EXTREME_Q15, QSPLINE_EXTREME_Q31).
    .venv/bin/python tests/c/qspline_reference.py
Table Q must match the arrays of test_qspline.c (written out again here on purpose).
"""
from __future__ import annotations

from fractions import Fraction
from math import floor

NU, NZ = 2, 4                       # nx = 2, n_latch = 1: z = [x0, x1, 1, v0]
STAGE_START = [0, 10, 17]
SPAN_LOG2 = [2, 0]
ROW_START = [0, 2, 3, 4, 6]
COL = [0, 2, 3, 1, 0, 3]
SHIFT = [3, 1, 1, 5, 30, 2]
COEF_START = [0, 18, 48]
COEF = [100, -200, 300, 32767, -32768, 7,             # stage 0 (6 per entry), col 0
        5, 5, 5, 5, 5, 5,                             # col 2 (k0[0])
        -1, 2, -3, 4, -5, 6,                          # input 1, col 3 (L[1][0])
        1000, 2000, -3000, 4000, -5000, 6000, 7000, 8000, 9000, -10000,  # stage 1, col 1
        3, -3, 3, -3, 3, -3, 3, -3, 3, -3,            # input 1, col 0 (shift 30: ~0)
        -7, 70, -700, 7000, -21000, 21000, 0, 1, -1, 2]  # input 1, col 3 (shift 2)


def spline(k: int, c: list, s: int, tau: int) -> int:
    D = 2 ** k
    sigma, t = tau >> k, Fraction(tau % D, D)
    N = [(1 - t) ** 3 / 6, (3 * t ** 3 - 6 * t ** 2 + 4) / 6,
         (-3 * t ** 3 + 3 * t ** 2 + 3 * t + 1) / 6, t ** 3 / 6]
    value = sum(N[r] * Fraction(6 * c[sigma + r], 2 ** s) for r in range(4))
    return floor(value + Fraction(1, 2))


def table_q() -> list:
    """Every tick's rows g[i * NZ + col] (zeros where nothing is stored)."""
    out = []
    for s in range(2):
        k, T = SPAN_LOG2[s], STAGE_START[s + 1] - STAGE_START[s]
        stride = -(-T // 2 ** k) + 3
        for tau in range(T):
            g = [0] * (NU * NZ)
            off = COEF_START[s]
            for i in range(NU):
                for e in range(ROW_START[s * NU + i], ROW_START[s * NU + i + 1]):
                    g[i * NZ + COL[e]] = spline(k, COEF[off:off + stride], SHIFT[e], tau)
                    off += stride
            out.append(g)
    return out


def extremes(bits: int) -> list:
    """k = 9 (512-tick spans), shifts 1 and 30, coefficients alternating between the type's
    ends: the exact values (before any narrowing to the scalar type) at ticks 0, 1, 255,
    511, 512, 1023 of a 2-span stage."""
    lo, hi = -2 ** (bits - 1), 2 ** (bits - 1) - 1
    c = [hi if r % 2 else lo for r in range(5)]
    return [spline(9, c, s, tau) for s in (1, 30) for tau in (0, 1, 255, 511, 512, 1023)]


def c_array(values) -> str:
    return ", ".join(str(v) for v in values)


if __name__ == "__main__":
    rows = table_q()
    print("#define QSPLINE_EXPECTED { \\")
    for g in rows:
        print(f"    {{{c_array(g)}}}, \\")
    print("}")
    print(f"#define QSPLINE_EXTREME_Q15 {{{c_array(f'INT64_C({v})' for v in extremes(16))}}}")
    print(f"#define QSPLINE_EXTREME_Q31 {{{c_array(f'INT64_C({v})' for v in extremes(32))}}}")
