"""A run's statistics stream over its blocks of paths (`harness.path_stats`): they equal the
per-path arrays' to rounding (counts exactly), and memory does not grow with the paths."""
import tomllib
import tracemalloc
from dataclasses import replace

import numpy as np
import pytest

from stospline.budget import monte_carlo_terms
from stospline.errors import ProblemError
from stospline.pipeline import design_problem
from stospline.problem import parse_problem
from stospline.harness.controller import build_controller
from stospline.harness.montecarlo import (BLOCK_PATHS, PER_PATH_MAX_BYTES, compare_to_oracle,
                                      per_path_bytes, simulate)
from stospline.harness.path_stats import EXIT_EXAMPLES, CorridorExits, Moments

from conftest import EXAMPLES

SEED = 20261128


@pytest.mark.parametrize("offset", [0.0, 1e6])
def test_merged_moments_equal_the_whole_sample(offset):
    """Any split, merged in order, gives the whole sample's moments to rounding, also far
    from zero (a mean of 1e6 with unit spread, where naive sums of powers lose every digit)."""
    rng = np.random.default_rng(3)
    X = offset + rng.standard_normal((1000, 3)) @ np.array([[1, 0.5, 0], [0, 1, 0.2],
                                                            [0, 0, 2.0]])
    X[:, 2] = np.exp(X[:, 2] - offset)          # a skewed component: third and fourth moments
    whole = Moments.of(X)
    for cuts in ([1], [10, 11, 500], list(range(7, 1000, 93))):
        parts = np.split(X, cuts)
        merged = Moments.of(parts[0])
        for part in parts[1:]:
            merged = merged.merge(Moments.of(part))
        assert merged.count == 1000
        np.testing.assert_allclose(merged.mean, X.mean(axis=0), rtol=1e-13,
                                   atol=1e-15 * np.abs(X).max())
        np.testing.assert_allclose(merged.cov(), np.cov(X, rowvar=False), rtol=1e-9, atol=1e-12)
        for name in ("comoment", "m3", "m4"):
            np.testing.assert_allclose(getattr(merged, name), getattr(whole, name), rtol=1e-9,
                                       atol=1e-9 * np.abs(getattr(whole, name)).max())
        np.testing.assert_array_equal(merged.low, X.min(axis=0))
        np.testing.assert_array_equal(merged.high, X.max(axis=0))


@pytest.fixture(scope="module")
def robot_run(robot_problem, robot_zoh):
    """The robot with a corridor narrowed so that many paths leave through several walls,
    three blocks (the last one short), with the per-path records to compare against."""
    (c,) = robot_problem.corridors
    narrow = type(c)(c.t, c.C, tuple((A, b - 0.3 * (b > 0)) for A, b in c.polygons))
    p = replace(robot_problem, corridors=(narrow,))
    ctl = build_controller(robot_zoh.table)
    paths = 2 * BLOCK_PATHS + 300
    return p, simulate(p, ctl, paths=paths, seed=SEED, substeps=1, workers=1, per_path=True)


def test_streamed_statistics_equal_the_per_path_ones(robot_run):
    """What the summaries and the verdict read, from the streamed statistics, against numpy
    on every path's record (what a run computed before streaming)."""
    p, mc = robot_run
    mean, hw = mc.cost_mean_ci(0.95)
    assert mean == pytest.approx(mc.cost.mean(), rel=1e-13)
    assert hw == pytest.approx(1.959963984540054 * mc.cost.std(ddof=1) / np.sqrt(mc.paths),
                               rel=1e-11)
    for k, X in enumerate(mc.knot_states):
        m, s = mc.knot_mean_se(k)
        np.testing.assert_allclose(m, X.mean(axis=0), rtol=1e-13)
        np.testing.assert_allclose(s, X.std(axis=0, ddof=1) / np.sqrt(len(X)), rtol=1e-10)
        np.testing.assert_allclose(mc.knot_cov(k), np.cov(X, rowvar=False), rtol=1e-10,
                                   atol=1e-14)
        np.testing.assert_allclose(mc.knot_moments[k].var_se(),
                                   np.std((X - X.mean(axis=0)) ** 2, axis=0, ddof=1)
                                   / np.sqrt(len(X)), rtol=1e-9)
        np.testing.assert_array_equal(mc.knot_moments[k].alike(), np.ptp(X, axis=0) == 0)
    assert mc.saturated_tick_count == mc.saturated_ticks.sum()
    assert mc.saturated_path_count == np.count_nonzero(mc.saturated_ticks)
    np.testing.assert_array_equal(mc.cost_sample, mc.cost[:len(mc.cost_sample)])


def test_streamed_exits_equal_the_per_path_ones(robot_run):
    p, mc = robot_run
    et, ew = mc.exit_tick[0], mc.exit_wall[0]
    out = np.flatnonzero(et >= 0)
    walls = len(p.corridors[0].wall_names())
    assert mc.exit_count(0) == len(out) > EXIT_EXAMPLES
    assert np.count_nonzero(np.bincount(ew[out])) >= 3            # several walls
    np.testing.assert_array_equal(mc.exits.by_tick[0],
                                  np.bincount(et[out], minlength=len(mc.sample_t)))
    np.testing.assert_array_equal(mc.exits.by_wall[0], np.bincount(ew[out], minlength=walls))
    assert mc.exits.examples[0] == [(int(i), int(et[i]), int(ew[i]))
                                    for i in out[:EXIT_EXAMPLES]]
    for q in (0, 5, 50, 95, 100):
        assert mc.exits.tick_percentile(0, q) == pytest.approx(np.percentile(et[out], q),
                                                               rel=1e-15)
    np.testing.assert_array_equal(mc.record_exit_tick, mc.exit_tick[:, :0])


def test_exits_merge_across_blocks():
    """Examples keep the first exiting paths of the run, by path index, across blocks."""
    a = CorridorExits.of(np.array([[-1, 3, -1]]), np.array([[-1, 1, -1]]), [2], 4, 0)
    b = CorridorExits.of(np.array([[4] * 12]), np.array([[0] * 12]), [2], 4, 3)
    ab = a.merge(b)
    assert ab.paths == 15 and ab.count.tolist() == [13]
    assert ab.by_tick[0].tolist() == [0, 0, 0, 1, 12] and ab.by_wall[0].tolist() == [12, 1]
    assert ab.examples[0][:3] == [(1, 3, 1), (3, 4, 0), (4, 4, 0)]
    assert len(ab.examples[0]) == EXIT_EXAMPLES


def test_the_verdict_still_fails_a_wrong_controller(robot_run, robot_zoh):
    """The streamed statistics feed the same verdict: an exact cost moved by 5 standard
    errors is refused."""
    _, mc = robot_run
    ok = compare_to_oracle(mc, robot_zoh.implemented.J, robot_zoh.implemented.knot_mean)
    assert ok.ok
    wrong = robot_zoh.implemented.J + 5 * mc.cost_moments.mean_se()[0]
    assert not compare_to_oracle(mc, wrong, robot_zoh.implemented.knot_mean).ok


def test_per_path_records_are_refused_beyond_their_limit(robot_problem, robot_zoh):
    ctl = build_controller(robot_zoh.table)
    paths = int(PER_PATH_MAX_BYTES / per_path_bytes(robot_problem, 1)) + 1
    with pytest.raises(ProblemError) as err:
        simulate(robot_problem, ctl, paths=paths, seed=1, per_path=True)
    assert err.value.field == "per_path" and "GiB" in err.value.reason


def _robot_10hz():
    doc = tomllib.loads((EXAMPLES / "robot_corridor.toml").read_text())
    doc["tick_hz"] = 10                       # 60 ticks: 2e5 paths in a few seconds
    problem = parse_problem(doc)
    return problem, build_controller(design_problem(problem).table)


def _peak(problem, ctl, paths: int, workers: int, per_path: bool = False) -> int:
    tracemalloc.start()
    try:
        simulate(problem, ctl, paths=paths, seed=SEED, substeps=1, workers=workers,
                 per_path=per_path)
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


@pytest.mark.parametrize("workers", [1, 2])
def test_peak_memory_does_not_grow_with_the_paths(workers):
    """Peak traced memory of this process for 2e4 and 2e5 paths: within 1 MB, where the
    per-path records of the 180 000 more paths alone take 14 MB (and do grow)."""
    problem, ctl = _robot_10hz()
    small, large = (_peak(problem, ctl, n, workers) for n in (20_000, 200_000))
    assert large - small < 1e6, (small, large)
    if workers == 1:       # the test sees growth where there is some
        grown = _peak(problem, ctl, 200_000, 1, per_path=True)
        assert grown - small > 0.9 * (per_path_bytes(problem, 200_000)
                                      - per_path_bytes(problem, 20_000))


def test_the_memory_estimate_is_flat_in_the_paths(robot_problem):
    def total(paths):
        return sum(t.bytes for t in monte_carlo_terms(robot_problem, paths=paths, workers=2))
    assert total(10**9) == total(10**5) < total(10**3) + 16e6


def test_the_stage_call_equals_the_tick_calls(robot_problem, robot_zoh):
    """A stage per C call (`harness_run_ticks`, no faults) against a tick per call (the
    fault tick with a fault of zero size, which is the fault-free loop): the same sample
    path, records, mean path, statistics and exits, bit for bit."""
    from stospline.problem.faults import Faults
    ctl = build_controller(robot_zoh.table)
    runs = [simulate(robot_problem, ctl, paths=BLOCK_PATHS + 40, seed=SEED, substeps=2,
                     workers=1, record=30, per_path=True, faults=f)
            for f in (Faults(), Faults(miss_probability=1e-300))]
    stage, tick = runs
    for name in ("sample_x", "sample_u", "record_x", "record_u", "mean_x", "cost",
                 "exit_tick", "exit_wall", "record_exit_tick", "u_low", "u_high"):
        np.testing.assert_array_equal(getattr(stage, name), getattr(tick, name), err_msg=name)
    for a, b in zip(stage.knot_states, tick.knot_states):
        np.testing.assert_array_equal(a, b)
    assert stage.record_x.shape == (len(stage.sample_t), 30, robot_problem.n)
