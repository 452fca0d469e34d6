"""The designer's prediction against the exact moment oracle on the paper's robot example."""
from dataclasses import replace

import numpy as np
import pytest

from stospline.oracle.evaluate import evaluate_continuous


def test_predicted_cost_equals_oracle_of_continuous_law(robot):
    assert abs(robot.design.J0 - robot.law.J) <= 1e-8 * abs(robot.design.J0)


def test_oracle_meets_every_constraint(robot):
    for kn, achieved in zip(robot.problem.knots, robot.law.knot_constraint):
        np.testing.assert_allclose(achieved, kn.constraint.value, rtol=0, atol=1e-8)


@pytest.mark.parametrize("shift", [[0.5, 0.2, -0.3, 0.1], [-1.0, 0.0, 0.8, -0.4]])
def test_cost_to_go_from_other_starts_is_the_oracle_cost(robot_problem, robot, shift):
    """J0 is the cost-to-go at x0, a quadratic form of the start state built backwards from the
    Riccati terms. From another start the law latches other multipliers; the oracle integrates
    that latched law's moments forwards, and its exact cost and knot constraints must be what
    the backward value function and the latch promise."""
    x = robot_problem.x0 + np.array(shift)
    oracle = evaluate_continuous(replace(robot_problem, x0=x), robot.design)
    assert robot.design.cost_to_go(0, x) == pytest.approx(oracle.J, rel=1e-8)
    for kn, achieved in zip(robot_problem.knots, oracle.knot_constraint):
        np.testing.assert_allclose(achieved, kn.constraint.value, rtol=0, atol=1e-8)


def test_implemented_table_is_close_but_not_equal(robot):
    """1 kHz zero-order hold of the continuous gains costs a little more and misses the
    constraints by O(h): the oracle of the table sees this, it is not rounding noise."""
    excess = robot.implemented.J - robot.law.J
    assert 0 < excess < 1e-2 * robot.law.J
    resid = np.abs(robot.implemented.knot_constraint[1] - robot.problem.knots[1].constraint.value)
    assert 1e-6 < resid.max() < 1e-2


def test_oracle_of_the_table_converges_to_the_continuous_law(robot_problem, robot):
    """Halving h roughly halves the excess cost (first-order sampling error)."""
    from stospline.oracle.evaluate import evaluate_table
    from stospline.table.format import table_of
    excess = []
    for hz in (250, 500):
        t = table_of(robot.design, hz)
        excess.append(evaluate_table(robot_problem, t, path=False).J - robot.law.J)
    excess.append(robot.implemented.J - robot.law.J)
    ratios = np.array(excess[:-1]) / np.array(excess[1:])
    assert np.all((ratios > 1.6) & (ratios < 2.4)), (excess, ratios)
