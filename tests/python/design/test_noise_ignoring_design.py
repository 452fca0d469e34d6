"""The paper's Remark 2: a design that ignores the noise, applied to the noisy robot, is
measurably worse than the stochastic design (exact numbers from the oracle)."""
import numpy as np

from stospline.design.continuous import design_continuous
from stospline.oracle.evaluate import evaluate_continuous


def test_stochastic_design_beats_noise_ignoring_design(robot_problem, robot):
    naive = design_continuous(robot_problem, noise=False)
    naive_on_noisy = evaluate_continuous(robot_problem, naive)
    smart = robot.law
    # Both meet the expected-value constraints: the mean does not see the noise.
    for k, kn in enumerate(robot_problem.knots):
        np.testing.assert_allclose(naive_on_noisy.knot_constraint[k], kn.constraint.value,
                                   atol=1e-8)
    # Cost: the stochastic design is optimal, so strictly lower; here by more than 10%.
    assert smart.J < 0.9 * naive_on_noisy.J, (smart.J, naive_on_noisy.J)
    # Knot variance (trace of the state covariance) is lower at every knot.
    for k in range(len(robot_problem.knots)):
        assert np.trace(smart.knot_cov[k]) < np.trace(naive_on_noisy.knot_cov[k])
    # And the noise-ignoring design underestimates its own cost.
    assert naive.J0 < naive_on_noisy.J
