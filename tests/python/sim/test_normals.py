"""The harness's standard normal numbers (host/stospline/harness/normals.c: xoshiro256++ through a
256-layer ziggurat): the distribution, checked with fixed seeds on 4·10^6 numbers, and the
committed tables still what their generator writes.

Every moment and tail check is a z-score against its exact value with the sample's own
standard error; the limit 5 makes a false alarm a 1-in-10^6 event per check, while the
ziggurat fault these checks were written against (the wedge test of layer i drawn between
the heights of layers i - 1 and i) moved the variance by 6 and the kurtosis by 10 standard
errors.
"""
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import stospline
from stospline.harness.controller import build_controller

ROOT = Path(__file__).resolve().parents[3]
COUNT = 4_000_000
Z_LIMIT = 5.0


@pytest.fixture(scope="module")
def sample(robot):
    ctl = build_controller(robot.table)
    out = np.empty(COUNT)
    ctl.normals(np.random.SeedSequence(20261124))(out)()
    return out


def _z(values: np.ndarray, exact: float) -> float:
    return (values.mean() - exact) / (values.std(ddof=1) / math.sqrt(len(values)))


@pytest.mark.parametrize("power, exact", [(1, 0.0), (2, 1.0), (3, 0.0), (4, 3.0), (6, 15.0)])
def test_moments(sample, power, exact):
    assert abs(_z(sample ** power, exact)) < Z_LIMIT


@pytest.mark.parametrize("a", [0.5, 1.0, 2.0, 3.0, 3.6541528853610088, 4.0, 4.5])
def test_tail_probabilities(sample, a):
    """P(|Z| > a), including the ziggurat's tail start R = 3.654 and beyond it (the tail
    sampler)."""
    exact = math.erfc(a / math.sqrt(2.0))
    hits = (np.abs(sample) > a).astype(float)
    se = math.sqrt(exact * (1 - exact) / len(sample))
    assert abs(hits.mean() - exact) / se < Z_LIMIT


def test_kolmogorov_smirnov(sample):
    from scipy import stats
    assert stats.kstest(sample, "norm").pvalue > 1e-4


def test_streams_are_seeded_and_independent(robot):
    ctl = build_controller(robot.table)
    a, b, c = (np.empty(1000) for _ in range(3))
    ctl.normals(np.random.SeedSequence(1))(a)()
    ctl.normals(np.random.SeedSequence(1))(b)()
    ctl.normals(np.random.SeedSequence(2))(c)()
    np.testing.assert_array_equal(a, b)
    assert abs(np.corrcoef(a, c)[0, 1]) < 0.2
    fill = ctl.normals(np.random.SeedSequence(1))(b)
    fill()
    fill()                                        # the state advances between calls
    assert not np.array_equal(a, b)


def test_the_committed_tables_are_the_generators():
    r = subprocess.run([sys.executable, str(ROOT / "tools" / "gen" / "ziggurat_tables.py")],
                       capture_output=True, text=True, check=True)
    committed = (Path(stospline.__file__).parent / "harness" / "ziggurat_tables.h").read_text()
    assert r.stdout == committed


def _tables():
    """harness_zig_k, harness_zig_w, harness_zig_f and R from the committed header."""
    import re
    text = (Path(stospline.__file__).parent / "harness" / "ziggurat_tables.h").read_text()
    body = {name: text.split(name, 1)[1].split("{", 1)[1].split("}", 1)[0]
            for name in ("harness_zig_k", "harness_zig_w", "harness_zig_f")}
    k = [int(v) for v in re.findall(r"(\d+)u", body["harness_zig_k"])]
    w, f = ([float.fromhex(v) for v in re.findall(r"-?0x[0-9a-fA-Fp.+-]+", body[name])]
            for name in ("harness_zig_w", "harness_zig_f"))
    r = float.fromhex(re.search(r"HARNESS_ZIG_R (\S+)", text).group(1))
    return k, w, f, r


def _reference_normals(state, count):
    """normals.c's algorithm written plainly (one word per draw; the wedge and the tail
    draw further words): the numbers the C generator must give, bit for bit."""
    k, w, f, big_r = _tables()
    mask = (1 << 64) - 1
    s = [int(v) for v in state]

    def rotl(x, r):
        return ((x << r) | (x >> (64 - r))) & mask

    def word():
        out = (rotl((s[0] + s[3]) & mask, 23) + s[0]) & mask
        t = (s[1] << 17) & mask
        s[2] ^= s[0]
        s[3] ^= s[1]
        s[1] ^= s[2]
        s[0] ^= s[3]
        s[2] ^= t
        s[3] = rotl(s[3], 45)
        return out

    def unit():
        return (word() >> 11) * 2.0**-53

    out = []
    while len(out) < count:
        r = word()
        layer, negative, mag = r & 0xFF, (r >> 8) & 1, (r >> 9) & ((1 << 52) - 1)
        x = mag * w[layer]
        if mag < k[layer]:
            pass
        elif layer == 0:
            while True:
                xx = -math.log1p(-unit()) / big_r
                yy = -math.log1p(-unit())
                if not yy + yy <= xx * xx:
                    break
            x = big_r + xx
        elif not f[layer] + unit() * (f[layer + 1] - f[layer]) < math.exp(-0.5 * x * x):
            continue
        out.append(-x if negative else x)
    return np.array(out), np.array(s, dtype=np.uint64)


def test_the_numbers_are_the_algorithms(robot):
    """The C generator (its fast path written out, the state in registers, the sign as a bit
    flip) gives the algorithm's numbers and state bit for bit, the wedge and tail draws
    included, over calls of several sizes."""
    ctl = build_controller(robot.table)
    into = ctl.normals(np.random.SeedSequence(20261128))
    start = into.state.copy()
    got = []
    for size in (1, 7, 4096, 25_000):
        out = np.empty(size)
        into(out)()
        got.append(out)
    got = np.concatenate(got)
    want, state = _reference_normals(start, len(got))
    assert (np.abs(want) > _tables()[3]).sum() >= 3          # the tail sampler ran
    np.testing.assert_array_equal(got.view(np.uint64), want.view(np.uint64))
    np.testing.assert_array_equal(into.state, state)
