"""`substeps="auto"` (the default of `simulate_problem` and `stospline simulate`): the plant
integrator's exact bias in the expected cost stays below 0.1 Monte Carlo standard errors of
the run itself, at 10 Hz (where a fixed 2 substeps is 2 standard errors off) and
at 1 kHz (where one substep is enough), with the fewest substeps that do it."""
import tomllib

import numpy as np
import pytest

from stospline.pipeline import design_problem, simulate_problem
from stospline.problem import parse_problem
from stospline.harness.plant_scheme import scheme_bias

from conftest import EXAMPLES

SEED = 20261124


def _robot_at(hz: int):
    doc = tomllib.loads((EXAMPLES / "robot_corridor.toml").read_text())
    doc["tick_hz"] = hz
    problem = parse_problem(doc)
    return problem, design_problem(problem)


@pytest.fixture(scope="module")
def robot_10hz():
    return _robot_at(10)


@pytest.mark.parametrize("hz, paths", [(10, 20000), (1000, 2000)])
def test_auto_substeps_keep_the_plant_bias_under_a_tenth_of_the_standard_error(hz, paths,
                                                                              robot_10hz):
    problem, d = robot_10hz if hz == 10 else _robot_at(hz)
    mc = simulate_problem(d, paths=paths, seed=SEED)
    choice = mc.substep_choice
    assert choice is not None and choice.substeps == mc.substeps and choice.met
    se = mc.cost_std() / np.sqrt(paths)
    bias = scheme_bias(problem, d.table, mc.substeps, d.implemented.J)
    assert bias == pytest.approx(choice.bias, rel=1e-12)
    assert abs(bias) <= 0.1 * se, (mc.substeps, bias, se)
    if mc.substeps > 1:   # the fewest: half as many miss the target
        assert abs(scheme_bias(problem, d.table, mc.substeps // 2, d.implemented.J)) > choice.target
    if hz == 10:          # what the fixed default of 2 substeps gave: off by standard errors
        assert mc.substeps >= 32
        assert abs(scheme_bias(problem, d.table, 2, d.implemented.J)) > 1.0 * se
    else:
        assert mc.substeps <= 2


def test_the_pilot_leaves_the_run_stream_alone(robot_10hz):
    """The pilot draws from a stream spawned from the seed: the run with the chosen number of
    substeps is the one a fixed `substeps` gives for the same seed."""
    problem, d = robot_10hz
    auto = simulate_problem(d, paths=500, seed=SEED)
    fixed = simulate_problem(d, paths=500, seed=SEED, substeps=auto.substeps)
    assert fixed.substep_choice is None
    assert np.array_equal(auto.cost_moments.mean, fixed.cost_moments.mean)
    assert np.array_equal(auto.cost_moments.comoment, fixed.cost_moments.comoment)


def assert_same_statistics(a, b):
    """The streamed statistics of two runs, bit for bit (they merge in block order)."""
    for x, y in zip([a.cost_moments, *a.knot_moments], [b.cost_moments, *b.knot_moments]):
        for name in ("mean", "comoment", "m3", "m4", "low", "high"):
            assert np.array_equal(getattr(x, name), getattr(y, name)), name
    assert (a.saturated_tick_count, a.saturated_path_count) == (b.saturated_tick_count,
                                                                b.saturated_path_count)
    assert np.array_equal(a.cost_sample, b.cost_sample)


def test_block_streams_are_the_seed_sequence_children():
    """Block 0 draws from the seed's own stream, block i from child i - 1 of
    ``SeedSequence(seed).spawn`` (derived without spawning, so nothing is mutated)."""
    from stospline.harness.montecarlo import block_seed
    root = np.random.SeedSequence(SEED)
    children = np.random.SeedSequence(SEED).spawn(3)
    assert block_seed(SEED, 0).generate_state(4).tolist() == root.generate_state(4).tolist()
    for i, child in enumerate(children, start=1):
        assert block_seed(SEED, i).generate_state(4).tolist() == child.generate_state(4).tolist()


def test_same_numbers_on_one_two_or_four_workers(robot_problem, robot_zoh):
    """The result for a seed does not depend on how many processes run the blocks."""
    from stospline.harness.controller import build_controller
    from stospline.harness.montecarlo import BLOCK_PATHS, simulate
    ctl = build_controller(robot_zoh.table)
    paths = 2 * BLOCK_PATHS + 300                  # three blocks, the last one short
    runs = {w: simulate(robot_problem, ctl, paths=paths, seed=SEED, substeps=1, workers=w,
                     per_path=True)
            for w in (1, 2, 4)}
    for w in (2, 4):
        assert np.array_equal(runs[w].cost, runs[1].cost)
        assert np.array_equal(runs[w].mean_x, runs[1].mean_x)
        assert all(np.array_equal(a, b) for a, b in zip(runs[w].knot_states, runs[1].knot_states))
        assert np.array_equal(runs[w].saturated_ticks, runs[1].saturated_ticks)
        assert runs[w].worst_status == runs[1].worst_status
        assert_same_statistics(runs[w], runs[1])
    # and the blocks are really different streams: no two blocks repeat each other's paths
    c = runs[1].cost
    assert len(np.unique(c)) == paths


def test_dask_cluster_gives_the_same_numbers(robot_problem, robot_zoh):
    """The blocks on a Dask cluster, by address (threads in this process, one and two
    workers) and as a local cluster of processes: the numbers of the run on this machine."""
    from distributed import LocalCluster
    from stospline.harness.controller import build_controller
    from stospline.harness.montecarlo import BLOCK_PATHS, simulate
    ctl = build_controller(robot_zoh.table)
    paths = 2 * BLOCK_PATHS + 100
    ref = simulate(robot_problem, ctl, paths=paths, seed=SEED, substeps=1, workers=1,
                   per_path=True)
    runs = []
    for n in (1, 2):
        with LocalCluster(n_workers=n, processes=False, threads_per_worker=1,
                          dashboard_address=None) as cluster:
            runs.append(simulate(robot_problem, ctl, paths=paths, seed=SEED, substeps=1,
                                 scheduler=cluster.scheduler_address, per_path=True))
    runs.append(simulate(robot_problem, ctl, paths=paths, seed=SEED, substeps=1, workers=2,
                         scheduler="local", per_path=True))
    for run in runs:
        assert np.array_equal(run.cost, ref.cost)
        assert np.array_equal(run.mean_x, ref.mean_x)
        assert all(np.array_equal(a, b) for a, b in zip(run.knot_states, ref.knot_states))
        assert_same_statistics(run, ref)
