"""The sensor loop's Monte Carlo in blocks (`harness.sensor_blocks`): the same exits and
moments on one worker as on two forked ones (the blocks' streams are fixed by their path
index), block 0 is `simulate_estimator`'s run of the seed, and corridor-design's sensor loop
takes --workers."""
import copy

import numpy as np
import pytest

from stospline.harness import sensor_blocks
from stospline.harness.estimator_loop import simulate_estimator
from stospline.harness.estimator_run import count_sensor_exits
from stospline.harness.sensor_blocks import simulate_sensor_blocks

from test_sensor_corridor import corridor_case  # noqa: F401  (the module's fixture)

PATHS, BLOCK = 2600, 256        # 11 blocks; 2600 x 40 path-ticks: past the fork threshold


def _same(a, b):
    """Every statistic of two runs bit for bit."""
    assert a.paths == b.paths
    assert a.exit_count(0) == b.exit_count(0)
    assert np.array_equal(a.exits.by_tick[0], b.exits.by_tick[0])
    assert np.array_equal(a.exits.by_wall[0], b.exits.by_wall[0])
    assert a.exits.examples == b.exits.examples
    for x, y in [(a.cost_moments, b.cost_moments)] + list(zip(a.knot_moments, b.knot_moments)):
        assert np.array_equal(x.mean, y.mean) and np.array_equal(x.cov(), y.cov())
    assert np.array_equal(a.mean_x, b.mean_x)
    assert np.array_equal(a.cost_sample, b.cost_sample)
    assert np.array_equal(a.sample_x, b.sample_x)


def test_one_worker_and_two_give_the_same_run(corridor_case, monkeypatch):  # noqa: F811
    problem, d, et, ctl = corridor_case
    forked = []
    real = sensor_blocks._parallel_blocks

    def spy(*args, **kwargs):
        forked.append(args[3])
        return real(*args, **kwargs)
    monkeypatch.setattr(sensor_blocks, "_parallel_blocks", spy)
    one = simulate_sensor_blocks(problem, ctl, paths=PATHS, seed=5, workers=1, block_paths=BLOCK)
    assert forked == []
    two = simulate_sensor_blocks(problem, ctl, paths=PATHS, seed=5, workers=2,
                                 force_workers=True, block_paths=BLOCK)
    assert forked == [2]                       # the second run did fork two workers
    _same(one, two)
    assert 0.01 * PATHS < one.exit_count(0) < 0.2 * PATHS
    # the examples name paths of the whole run, beyond block 0's too
    assert max(p for p, _, _ in one.exits.examples[0]) >= BLOCK
    # block 0 is the seed's own stream: a run of one block is simulate_estimator's
    mc, _ = simulate_estimator(problem, ctl, paths=BLOCK, seed=5, substeps=1)
    _same(mc, simulate_sensor_blocks(problem, ctl, paths=BLOCK, seed=5, block_paths=BLOCK))
    # the blocks draw different numbers (a shared stream would repeat block 0's paths)
    assert one.exits.examples[0][-1][0] < PATHS
    halves = simulate_sensor_blocks(problem, ctl, paths=2 * BLOCK, seed=5, block_paths=BLOCK)
    assert not np.array_equal(halves.cost_sample[:BLOCK], halves.cost_sample[BLOCK:2 * BLOCK])
    # and the count corridor-design uses is this run's, given the block size
    assert count_sensor_exits(problem, d.table, 0, paths=PATHS, seed=5, workers=2,
                              force_workers=True, block_paths=BLOCK) == one.exit_count(0)


def test_corridor_design_spreads_the_sensor_loop_over_workers(tmp_path, capsys):
    """`corridor-design --workers 2` on a [measurement] problem: the certificate's counts are
    the blocked sensor loop's on two workers, and the same with --workers 1."""
    import json
    from stospline.cli import main
    from stospline.problem.reader import parse_problem
    from test_sensor_corridor import CORRIDOR, DOC
    doc = copy.deepcopy(DOC)
    doc["corridors"] = [{**CORRIDOR, "epsilon": 0.3}]
    path = tmp_path / "sensed.toml"
    path.write_text(parse_problem(copy.deepcopy(doc)).to_toml())
    certs = []
    for workers in ("1", "2"):
        assert main(["corridor-design", str(path), "--search", "400", "--certify", "5000",
                     "--strip", "0", "--rate", "0", "--workers", workers, "--json"]) == 0
        certs.append(json.loads(capsys.readouterr().out)["chosen"])
    assert certs[0] == certs[1]
    assert certs[0]["certification"]["paths"] == 5000
    assert certs[0]["certification"]["exits"] > 0


def test_block_paths_must_be_a_positive_count(corridor_case):  # noqa: F811
    problem, _, _, ctl = corridor_case
    with pytest.raises(ValueError, match="block_paths"):
        simulate_sensor_blocks(problem, ctl, paths=10, seed=1, block_paths=0)
