#!/usr/bin/env python3
"""Expected values for tests/c/test_spline.c, computed independently of the firmware: table S's
commands over a run of ticks by the spline format's evaluation order (numpy float32 scalars,
every operation rounded to binary32, the basis by the literal loops of The NURBS Book A2.2
including the +0 adds; per input the folded feed-forward spline first, then the gains of x),
and its CRC-32 from the documented serialization (zlib). Prints the C
constants that test_spline.c pastes (SPLINE_EXPECTED_BITS, TABLE_S_CRC32).
    .venv/bin/python tests/c/spline_reference.py
Table S must match the arrays of test_spline.c (written out again here on purpose).
"""
from __future__ import annotations

import struct
import zlib

import numpy as np

f = np.float32
NX, NU, N_LATCH, NS = 2, 2, 2, 2
STAGE_START = [0, 10, 22]
STAGE_N_LATCH = [1, 2]
TICK_HZ = 100
KNOT_START = [0, 10, 19]
KNOT = [0, 0, 0, 0, 3, 7, 10, 10, 10, 10, 0, 0, 0, 0, 5, 12, 12, 12, 12]
ROW_START = [0, 3, 4, 4, 8]
COL = [0, 2, 3, 2, 0, 1, 2, 3]
COEF_START = [0, 24, 44]
COEF = ["0.5", "0.625", "0.75", "0.5", "0.25", "0.125",        # stage 0, K00
        "0.1", "0.2", "-0.3", "0.4", "0.05", "-0.06",          # k0[0]
        "1.5", "1.25", "1.0", "0.875", "0.75", "0.5",          # L00
        "-0.2", "-0.1", "0.0", "0.1", "0.2", "0.3",            # k0[1]
        "0.9", "0.8", "0.7", "0.6", "0.5",                     # stage 1, K10
        "-1.1", "-1.2", "-1.3", "-1.4", "-1.5",                # K11
        "0.01", "0.02", "0.03", "0.04", "0.05",                # k0[1]
        "2.0", "1.5", "1.0", "0.5", "0.25"]                    # L10
LAMBDA = ["0.5", "-0.25", "0.0", "0.0", "-1.0", "0.75", "100.0", "2.0"]
LAMBDA0 = ["0.125", "0.0", "0.3", "-0.2"]
U_MIN = [-3.4028234663852886e38] * 2
U_MAX = [3.4028234663852886e38] * 2
U_HOLD = ["0.5", "-0.25"]
PROBLEM_SHA256 = bytes(range(32))


def c_float(text) -> np.float32:
    """The binary32 a C compiler makes of the literal `text`f (correctly rounded)."""
    return f(float(text)) if not isinstance(text, str) else f(np.float64(text))


def state(t: int) -> list:
    """x at tick t, the same expression in test_spline.c: ((float)t * 0.37f - 1.1f, 0.8f -
    (float)t * 0.21f)."""
    return [f(t) * f(0.37) - f(1.1), f(0.8) - f(t) * f(0.21)]


def basis(U: list, tau: np.float32, sigma: int) -> list:
    i = sigma + 3
    left = [f(0)] * 4
    right = [f(0)] * 4
    N = [f(1), f(0), f(0), f(0)]
    for j in range(1, 4):
        left[j] = tau - U[i + 1 - j]
        right[j] = U[i + j] - tau
        saved = f(0)
        for r in range(j):
            temp = N[r] / (right[r + 1] + left[j - r])
            N[r] = saved + right[r + 1] * temp
            saved = left[j - r] * temp
        N[j] = saved
    return N


def latch(s: int, x: list) -> list:
    v = [f(0)] * N_LATCH
    for c in range(STAGE_N_LATCH[s]):
        acc = c_float(LAMBDA0[s * N_LATCH + c])
        for j in range(NX):
            acc = acc + c_float(LAMBDA[(s * N_LATCH + c) * NX + j]) * x[j]
        v[c] = acc
    return v


def command(t: int, x: list, v: list) -> list:
    s = 0 if t < STAGE_START[1] else 1
    U = [f(k) for k in KNOT[KNOT_START[s]:KNOT_START[s + 1]]]
    S = len(U) - 7
    tau = f(t - STAGE_START[s])
    sigma = max(k for k in range(S) if U[k + 3] <= tau)
    N = basis(U, tau, sigma)
    z = list(x) + [f(1)] + list(v)
    coef = [c_float(c) for c in COEF[COEF_START[s]:COEF_START[s + 1]]]
    u = []
    e0 = ROW_START[s * NU]

    def gain(c):
        g = N[0] * c[0]
        g = g + N[1] * c[1]
        g = g + N[2] * c[2]
        return g + N[3] * c[3]

    for i in range(NU):
        rows = range(ROW_START[s * NU + i], ROW_START[s * NU + i + 1])
        # k0[i] + L[i] v folded into one spline: per coefficient, +0 - c z over the entries
        # with an operand beyond x, in stored order; then its value starts the command.
        fold = [f(0)] * 4
        for e in rows:
            if COL[e] >= NX:
                c = coef[(e - e0) * (S + 3) + sigma:]
                fold = [fold[r] - c[r] * z[COL[e]] for r in range(4)]
        acc = gain(fold)
        for e in rows:
            if COL[e] < NX:
                acc = acc - gain(coef[(e - e0) * (S + 3) + sigma:]) * z[COL[e]]
        u.append(acc)
    return u


def bits(v) -> int:
    return struct.unpack("<I", struct.pack("<f", float(v)))[0]


def crc() -> int:
    out = b"".join(struct.pack("<I", v) for v in (NX, NU, N_LATCH, NS, STAGE_START[-1], TICK_HZ))
    out += b"".join(struct.pack("<I", v) for v in STAGE_START + STAGE_N_LATCH)
    f32s = lambda vals: b"".join(struct.pack("<I", bits(c_float(v))) for v in vals)  # noqa: E731
    out += f32s(LAMBDA) + f32s(LAMBDA0) + f32s(U_MIN) + f32s(U_MAX) + f32s(U_HOLD)
    out += b"".join(struct.pack("<I", v) for v in (len(KNOT), len(COL), len(COEF)))
    out += b"".join(struct.pack("<I", v) for v in KNOT_START) + f32s(KNOT)
    out += b"".join(struct.pack("<I", v) for v in ROW_START + COL + COEF_START) + f32s(COEF)
    return zlib.crc32(out + PROBLEM_SHA256)


def main() -> None:
    v = [f(0)] * N_LATCH
    rows = []
    for t in range(STAGE_START[-1]):
        x = state(t)
        if t in STAGE_START[:-1]:
            v = latch(STAGE_START.index(t), x)
        rows.append(command(t, x, v))
    print("/* spline_reference.py: u[tick][i] bit patterns for the run of ticks 0..21 */")
    print("static const uint32_t SPLINE_EXPECTED_BITS[22][2] = {")
    for t, u in enumerate(rows):
        print(f"    {{0x{bits(u[0]):08X}u, 0x{bits(u[1]):08X}u}}, /* {t}: "
              f"{float(u[0]):.9g}, {float(u[1]):.9g} */")
    print("};")
    print(f"#define TABLE_S_CRC32 0x{crc():08X}u")


if __name__ == "__main__":
    main()
