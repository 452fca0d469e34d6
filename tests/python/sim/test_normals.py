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
