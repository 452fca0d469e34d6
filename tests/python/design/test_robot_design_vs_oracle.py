"""The designer's prediction against the exact moment oracle on the paper's robot example."""
import numpy as np


def test_predicted_cost_equals_oracle_of_continuous_law(robot):
    assert abs(robot.design.J0 - robot.law.J) <= 1e-8 * abs(robot.design.J0)


def test_oracle_meets_every_constraint(robot):
    for kn, achieved in zip(robot.problem.knots, robot.law.knot_constraint):
        np.testing.assert_allclose(achieved, kn.constraint.value, rtol=0, atol=1e-8)


def test_cost_to_go_at_start_is_J0(robot):
    assert robot.design.cost_to_go(0, robot.problem.x0) == robot.design.J0


def test_implemented_table_is_close_but_not_equal(robot):
    """1 kHz zero-order hold of the continuous gains costs a little more and misses the
    constraints by O(h): the oracle of the table sees this, it is not rounding noise."""
    excess = robot.implemented.J - robot.law.J
    assert 0 < excess < 1e-2 * robot.law.J
    resid = np.abs(robot.implemented.knot_constraint[1] - robot.problem.knots[1].constraint.value)
    assert 1e-6 < resid.max() < 1e-2


def test_oracle_of_the_table_converges_to_the_continuous_law(robot_problem, robot):
    """Halving h roughly halves the excess cost (first-order sampling error)."""
    from stospline.oracle import evaluate_table
    from stospline.tables import sample_design
    excess = []
    for hz in (250, 500):
        t = sample_design(robot.design, hz)
        excess.append(evaluate_table(robot_problem, t, path=False).J - robot.law.J)
    excess.append(robot.implemented.J - robot.law.J)
    ratios = np.array(excess[:-1]) / np.array(excess[1:])
    assert np.all((ratios > 1.6) & (ratios < 2.4)), (excess, ratios)
