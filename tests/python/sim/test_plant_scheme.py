"""`substeps="auto"` (the default of `simulate_problem` and `stospline simulate`): the plant
integrator's exact bias in the expected cost stays below 0.1 Monte Carlo standard errors of
the run itself, at 10 Hz (where the old default of 2 substeps is 2 standard errors off) and
at 1 kHz (where one substep is enough), with the fewest substeps that do it."""
import tomllib

import numpy as np
import pytest

from stospline.pipeline import design_problem, simulate_problem
from stospline.problem import parse_problem
from stospline.sim.plant_scheme import scheme_bias

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
    se = mc.cost.std(ddof=1) / np.sqrt(paths)
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
    assert np.array_equal(auto.cost, fixed.cost)
