"""Monte Carlo through the compiled C with runtime parameters (stsp_set_params,
stsp_param_step) against the exact oracle of the parametric table: a fixed theta inside the
range (`evaluate_at`) and theta changed at the stage-1 start (`evaluate_switched`). Cost and
every knot-mean component within their joint 99 % confidence limits (Bonferroni, fixed seed),
with the sample's own standard errors and with the exact ones of the run's plant scheme
(`tails_at`, the loop's moments up to the fourth); and the same runs disagree with the oracle
of the parameters not in force, by either (the test can fail)."""
import numpy as np
import pytest

from conftest import EXAMPLES
from stospline import design_problem, load_problem
from stospline.harness.params_loop import build_params_controller, simulate_params
from stospline.oracle.parametric import (design_parametric, evaluate_at, evaluate_switched,
                                         tails_at)

PATHS, SEED = 2000, 20261128
THETA, THETA2 = np.array([-0.7, 5.3]), np.array([-1.4, 4.6])


@pytest.fixture(scope="module")
def robot(tmp_path_factory):
    problem = load_problem(EXAMPLES / "robot_goal.toml")
    table = design_problem(problem).table
    pt = design_parametric(problem).table
    ctl = build_params_controller(pt, table, build_dir=tmp_path_factory.mktemp("params"))
    return problem, pt, ctl


def test_fixed_theta_agrees_with_the_oracle_at_theta(robot):
    problem, pt, ctl = robot
    run = simulate_params(problem, ctl, THETA, paths=PATHS, seed=SEED)
    assert run.worst_status >= 0
    exact = evaluate_at(problem, pt, THETA, quantize=True)
    tails = tails_at(problem, pt, THETA, substeps=4, quantize=True)
    nominal = evaluate_at(problem, pt, pt.nominal, quantize=True)
    for se in (None, tails):
        verdict = run.agreement(exact.J, exact.knot_mean, exact_se=se)
        assert verdict.agree, verdict
        assert not run.agreement(nominal.J, nominal.knot_mean, exact_se=se).agree


def test_change_at_a_stage_start_agrees_with_the_switched_oracle(robot):
    problem, pt, ctl = robot
    run = simulate_params(problem, ctl, THETA, paths=PATHS, seed=SEED, change=(1, THETA2))
    assert run.worst_status >= 0
    exact = evaluate_switched(problem, pt, THETA, 1, THETA2, quantize=True)
    tails = tails_at(problem, pt, THETA, substeps=4, quantize=True, stage=1, theta2=THETA2)
    for se in (None, tails):
        verdict = run.agreement(exact.J, exact.knot_mean, exact_se=se)
        assert verdict.agree, verdict
        # the change reaches the plan: neither theta alone describes the run
        for th in (THETA, THETA2):
            other = evaluate_at(problem, pt, th, quantize=True)
            assert not run.agreement(other.J, other.knot_mean, exact_se=se).agree, th
    # until the change the run is the fixed-theta run's, path for path
    fixed = simulate_params(problem, ctl, THETA, paths=PATHS, seed=SEED)
    assert np.array_equal(run.knots[0], fixed.knots[0])


def test_a_theta_outside_the_range_is_refused(robot):
    problem, pt, ctl = robot
    with pytest.raises(ValueError, match="goal_x"):
        simulate_params(problem, ctl, np.array([-0.4, 5.0]), paths=4, seed=1)
