"""The estimator loop's filter gains and exact moments (`stospline.estimator.oracle`) against
an independent computation (`brute.py`), a Monte Carlo of the sampled loop (`loop_mc.py`), the
full-state oracle, and the designed knot targets."""
import copy

import numpy as np
import pytest
from brute import brute_loop
from loop_mc import simulate_loop

from stospline.estimator.gain import lmmse_gain
from stospline.estimator.oracle import evaluate_estimator
from stospline.pipeline import design_problem
from stospline.problem.measurement import Measurement
from stospline.problem.reader import parse_problem
from stospline.oracle.evaluate import evaluate_table
from stospline.table.format import table_of

# A noisy double integrator with friction, a drift, state and input noise, a penalty, two
# stages with their own data; a position-only sensor sampled every other tick whose noise
# grows with the position, and an uncertain start.
DOC = {
    "name": "sensed", "x0": [0.5, 0.0], "tick_hz": 20,
    "dynamics": {"A": [[0, 1], [0, -0.2]], "B": [[0], [1]], "f": [0.0, -0.1],
                 "noise": [{"state": 1, "G": [[0], [0.3]]}, {"input": 0, "G": [[0], [0.1]]}]},
    "cost": {"Q": [[0.1, 0], [0, 0]], "R": [[1]]},
    "knots": [{"t": 1.0, "penalty": {"C": [[1, 0]], "target": [1.0], "weight": 2.0},
               "constraint": {"C": [[1, 0]], "value": [1.0]}},
              {"t": 2.0, "constraint": {"C": [[1, 0], [0, 1]], "value": [0.0, 0.0]}}],
    "stages": [{"cost": {"R": [[2]]}}, {"dynamics": {"A": [[0, 1], [0, -1]]}}],
    "measurement": {"C": [[1, 0]], "V": [[0.0025]], "every": 2,
                    "noise": [{"state": 0, "D": [[0.1]]}],
                    "x0_cov": [[0.01, 0.0], [0.0, 0.04]]},
}


@pytest.fixture(scope="module")
def case():
    problem = parse_problem(copy.deepcopy(DOC))
    designed = design_problem(problem)
    return problem, designed


def test_gains_and_moments_agree_with_the_kronecker_brute(case):
    problem, designed = case
    table = designed.table
    loop = evaluate_estimator(problem, table)
    J, means, covs, gains = brute_loop(problem, table, problem.measurement)
    assert loop.moments.J == pytest.approx(J, rel=1e-10)
    np.testing.assert_allclose(loop.gain, gains, rtol=1e-8, atol=1e-12)
    assert np.abs(loop.gain[1::2]).max() == 0.0          # every = 2: no update on odd ticks
    for k in range(len(means)):
        np.testing.assert_allclose(loop.moments.knot_mean[k], means[k], rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(loop.moments.knot_cov[k], covs[k], rtol=1e-9, atol=1e-12)


def test_the_estimate_is_unbiased_and_the_knot_means_meet_the_design(case):
    problem, designed = case
    exact = table_of(designed.design, quantize=False)    # the design's own gains
    loop = evaluate_estimator(problem, exact)
    full = evaluate_table(problem, exact, path=False)
    for k, knot in enumerate(problem.knots):
        np.testing.assert_allclose(loop.knot_estimate_mean[k], loop.moments.knot_mean[k],
                                   atol=1e-12)
        np.testing.assert_allclose(loop.moments.knot_mean[k], full.knot_mean[k], atol=1e-12)
        np.testing.assert_allclose(loop.moments.knot_constraint[k], knot.constraint.value,
                                   atol=1e-12)
    # ... while the sensor's noise and the uncertain start cost variance and effort.
    assert loop.moments.J > full.J * 1.01
    assert np.trace(loop.moments.knot_cov[-1]) > np.trace(full.knot_cov[-1])


def test_an_exact_full_state_sensor_is_the_full_state_loop(case):
    problem, designed = case
    exact = Measurement(np.eye(2), np.zeros((2, 2)))
    loop = evaluate_estimator(problem, designed.table, exact)
    full = evaluate_table(problem, designed.table, path=False)
    assert loop.moments.J == pytest.approx(full.J, rel=1e-12)
    np.testing.assert_allclose(loop.moments.knot_cov[-1], full.knot_cov[-1], atol=1e-12)


def test_monte_carlo_of_the_sampled_loop_agrees_within_its_confidence_interval(case):
    problem, designed = case
    table, meas, substeps = designed.table, problem.measurement, 4
    loop = evaluate_estimator(problem, table, propagator="euler", substeps=substeps)
    paths = 40_000
    cost, xk = simulate_loop(problem, table, meas, loop.gain, paths=paths, substeps=substeps,
                             seed=20261128)
    z = 4.0      # two-sided 99.99 % per check, 11 checks: a false alarm about once in 900 runs
    se = cost.std(ddof=1) / np.sqrt(paths)
    assert abs(cost.mean() - loop.moments.J) < z * se, (cost.mean(), loop.moments.J, se)
    for k in range(len(problem.knots)):
        mean, cov = loop.moments.knot_mean[k], loop.moments.knot_cov[k]
        x = xk[k]
        se_mean = x.std(axis=0, ddof=1) / np.sqrt(paths)
        assert np.all(np.abs(x.mean(axis=0) - mean) < z * se_mean)
        sq = (x - x.mean(axis=0)) ** 2
        se_var = sq.std(axis=0, ddof=1) / np.sqrt(paths)
        assert np.all(np.abs(sq.mean(axis=0) - np.diag(cov)) < z * se_var), \
            (sq.mean(axis=0), np.diag(cov), se_var)


def test_the_gain_minimises_the_error_covariance():
    rng = np.random.default_rng(7)
    for _ in range(20):
        n, p = 3, 2
        A = rng.standard_normal((n, n)); P = A @ A.T
        Bm = rng.standard_normal((p, p)); R = Bm @ Bm.T + 0.1 * np.eye(p)
        C = rng.standard_normal((p, n))

        def post(L):
            I_LC = np.eye(n) - L @ C
            return I_LC @ P @ I_LC.T + L @ R @ L.T
        L = lmmse_gain(P, C, R)
        best = post(L)
        for _ in range(5):
            worse = post(L + 1e-2 * rng.standard_normal((n, p)))
            assert np.linalg.eigvalsh(worse - best).min() > -1e-12
