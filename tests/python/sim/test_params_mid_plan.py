"""Parameters changed in the middle of the plan: Monte Carlo through the compiled C
(stsp_set_params between two stsp_param_step calls) against the exact oracle of that change
(`evaluate_switched` with a tick: the feed-forward at the new theta from that tick, the latch
offsets at the next stage start that latches). robot_goal latches at tick 0 and at the
stage-1 start (tick 300), so a change inside stage 0 is relatched at tick 300 and one inside
stage 1 never is. Cost and every knot-mean component within their joint 99 % confidence
limits (Bonferroni, fixed seed; with the sample's own standard errors and with the exact ones
of the run, `tails_at`); the same runs disagree with
the oracle of the change applied at the wrong point: the latch offsets at once (relatched at
the change), or the whole change waiting for the next stage start (the test can fail)."""
from dataclasses import replace

import numpy as np
import pytest

from stospline import evaluate_table
from stospline.harness.params_loop import simulate_params
from stospline.oracle.parametric import evaluate_at, evaluate_switched, tails_at
from stospline.problem.parameters import problem_at

from test_params_monte_carlo import PATHS, THETA, THETA2, robot  # noqa: F401 (the fixture)

SEED = 20261130


def latched_at_once(problem, pt, stage, tick):
    """The wrong oracle: the stage's latch offsets at THETA2 too, as if relatched at `tick`."""
    a, b = pt.at(THETA, quantize=True), pt.at(THETA2, quantize=True)
    lam = a.lambda0.copy()
    lam[stage:] = b.lambda0[stage:]
    law = replace(a, k0=np.concatenate([a.k0[:tick], b.k0[tick:]]), lambda0=lam)
    pa, pb = problem_at(problem, THETA), problem_at(problem, THETA2)
    p = replace(pa, stages=pa.stages[:stage] + pb.stages[stage:],
                knots=pa.knots[:stage] + pb.knots[stage:])
    return evaluate_table(p, law, path=False)


def test_the_stages_latch_where_the_test_assumes(robot):
    _, pt, _ = robot
    assert list(pt.table.stage_start) == [0, 300, 600]
    assert pt.table.stage_n_latch[1] > 0


@pytest.mark.parametrize("stage, tick", [(0, 150), (1, 450)])
def test_a_change_inside_a_stage_agrees_with_the_oracle_of_that_tick(robot, stage, tick):
    problem, pt, ctl = robot
    run = simulate_params(problem, ctl, THETA, paths=PATHS, seed=SEED,
                          change=(stage, THETA2, tick))
    assert run.worst_status >= 0
    exact = evaluate_switched(problem, pt, THETA, stage, THETA2, tick=tick, quantize=True)
    tails = tails_at(problem, pt, THETA, substeps=4, stage=stage, theta2=THETA2, tick=tick,
                     quantize=True)
    for se in (None, tails):
        verdict = run.agreement(exact.J, exact.knot_mean, exact_se=se)
        assert verdict.agree, verdict
    # applied at the wrong point, the oracle disagrees with the same run
    wrong = {"latch offsets at once": latched_at_once(problem, pt, stage, tick)}
    if stage + 1 < pt.table.n_stages:
        wrong["waits for the next stage start"] = evaluate_switched(
            problem, pt, THETA, stage + 1, THETA2, quantize=True)
    else:
        wrong["waits for the next stage start"] = evaluate_at(problem, pt, THETA, quantize=True)
    wrong["at the stage's start"] = evaluate_switched(problem, pt, THETA, stage, THETA2,
                                                      quantize=True)
    for name, m in wrong.items():
        for se in (None, tails):
            assert not run.agreement(m.J, m.knot_mean, exact_se=se).agree, name


def test_a_change_inside_stage_1_is_neither_theta_at_the_goal(robot):
    """No latch after the change: the goal reached is that of neither parameter vector."""
    problem, pt, _ = robot
    end = evaluate_switched(problem, pt, THETA, 1, THETA2, tick=450).knot_mean[-1]
    for th in (THETA, THETA2):
        assert np.abs(end[[0, 2]] - th).min() > 0.1, th


def test_a_tick_outside_the_stage_is_refused(robot):
    problem, pt, ctl = robot
    with pytest.raises(ValueError, match="not in stage 0"):
        evaluate_switched(problem, pt, THETA, 0, THETA2, tick=300)
    with pytest.raises(ValueError, match="not in stage 0"):
        simulate_params(problem, ctl, THETA, paths=4, seed=1, change=(0, THETA2, 300))
