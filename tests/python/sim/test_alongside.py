"""`simulate(..., alongside=f)` runs f in a thread while the paths run: after the worker
processes are forked, its value in the result, its exception raised; the numbers are those of
a run without it. `pipeline.simulate_problem` computes the summary's corridor bounds so."""
import multiprocessing

import pytest

from stospline.harness import exit_stats
from stospline.harness.controller import build_controller
from stospline.harness.montecarlo import BLOCK_PATHS, simulate
from stospline.pipeline import simulate_problem, simulation_summary

PATHS = 2 * BLOCK_PATHS          # two blocks: enough work for the forked workers


@pytest.fixture(scope="module")
def ctl(robot_zoh):
    return build_controller(robot_zoh.table, plant=robot_zoh.problem)


@pytest.mark.parametrize("workers", [1, 2])
def test_alongside_runs_beside_the_paths(robot_problem, ctl, workers):
    seen = {}

    def work():
        seen["children"] = len(multiprocessing.active_children())
        return "done"
    mc = simulate(robot_problem, ctl, paths=PATHS, seed=5, substeps=1, workers=workers,
                  force_workers=True, alongside=work)
    plain = simulate(robot_problem, ctl, paths=PATHS, seed=5, substeps=1, workers=1)
    assert mc.alongside == "done" and plain.alongside is None
    assert (seen["children"] >= 2) == (workers == 2)      # started once they were forked
    assert mc.cost_moments.mean.tobytes() == plain.cost_moments.mean.tobytes()
    assert mc.mean_x.tobytes() == plain.mean_x.tobytes()


def test_alongside_error_is_raised(robot_problem, ctl):
    def work():
        raise KeyError("alongside")
    with pytest.raises(KeyError, match="alongside"):
        simulate(robot_problem, ctl, paths=8, seed=5, substeps=1, workers=1, alongside=work)


def test_the_summary_uses_the_bounds_computed_beside_the_run(robot_zoh, monkeypatch):
    mc = simulate_problem(robot_zoh, paths=64, seed=5, substeps=1, workers=1)
    problem, table, _ = exit_stats._OUTPUTS[0]
    assert problem is robot_zoh.problem and table is robot_zoh.table

    def again(*args, **kwargs):
        raise AssertionError("the corridor's outputs computed a second time")
    monkeypatch.setattr("stospline.oracle.exit_bound.corridor_outputs", again)
    s = simulation_summary(robot_zoh, mc, seed=5)
    assert s["corridors"][0]["bound"]["cantelli"]["total"] > 0
