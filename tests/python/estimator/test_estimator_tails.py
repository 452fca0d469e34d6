"""The sensor loop's fourth moments (estimator.tails): the measurement update's moments of
``[z; r]`` against Gauss-Hermite quadrature over the sensor's noise, and the loop's second
moments against the estimator oracle (the built-in check)."""
import copy
import itertools

import numpy as np
import pytest

from stospline.estimator.oracle import evaluate_estimator
from stospline.estimator.tails import _sensor_form, _update, evaluate_estimator_tails
from stospline.pipeline import design_problem
from stospline.problem.reader import parse_problem

from test_estimator_oracle import DOC


def test_update_equals_quadrature_over_the_sensor_noise():
    """A cloud of states z (its E z^(x)4 and E J z z' with random weights J); after the update
    x̂ += Lf (C x + r - C x̂), with r = sqrt(V) e + sum_a x_a D_a nu, both by `_update` and by
    three-point Gauss-Hermite nodes over (e, nu) for every point of the cloud."""
    problem = parse_problem(copy.deepcopy(DOC))
    meas = problem.measurement
    n, nl, p = 2, 1, meas.p
    d = 2 * n + nl + 1
    rng = np.random.default_rng(7)
    Z = np.hstack([rng.normal(size=(30, d - 1)), np.ones((30, 1))])
    Jw = rng.uniform(0.5, 2.0, size=30)
    T4 = np.einsum("si,sj,sk,sl->ijkl", Z, Z, Z, Z) / len(Z)
    P = np.einsum("s,si,sj->ij", Jw, Z, Z) / len(Z)
    Lf = rng.normal(size=(n, p))
    got_T, got_P = _update(T4, P, _sensor_form(meas, n, d), Lf, meas.C, n, d)
    sqV = np.linalg.cholesky(meas.V)
    D = meas.D                                           # (n, p, mnu)
    channels = p + D.shape[2]
    pts, wts = np.sqrt(3.0) * np.array([-1.0, 0.0, 1.0]), np.array([1.0, 4.0, 1.0]) / 6.0
    want_T, want_P = np.zeros_like(T4), np.zeros_like(P)
    for s, z in enumerate(Z):
        x, xh = z[:n], z[n:2 * n]
        for pick in itertools.product(range(3), repeat=channels):
            xi = pts[list(pick)]
            w = np.prod(wts[list(pick)])
            r = sqV @ xi[:p] + np.einsum("a,apk,k->p", x, D, xi[p:])
            zp = z.copy()
            zp[n:2 * n] = xh + Lf @ (meas.C @ x + r - meas.C @ xh)
            want_T += w * np.einsum("i,j,k,l->ijkl", zp, zp, zp, zp) / len(Z)
            want_P += w * Jw[s] * np.outer(zp, zp) / len(Z)
    np.testing.assert_allclose(got_T, want_T, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(got_P, want_P, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("propagator_substeps", [1, 3])
def test_second_moments_of_the_loop_are_the_oracles(propagator_substeps):
    """`evaluate_estimator_tails` checks its cost, knot means and covariances against the
    estimator oracle of the same scheme (TailsMismatch otherwise); its variances are
    positive and its fourth moments at least the squared variances."""
    problem = parse_problem(copy.deepcopy(DOC))
    table = design_problem(problem).table
    loop = evaluate_estimator(problem, table, propagator="euler",
                              substeps=propagator_substeps)
    tails = evaluate_estimator_tails(problem, table, loop, substeps=propagator_substeps)
    assert tails.J == pytest.approx(loop.moments.J, rel=1e-10)
    assert tails.cost_var > 0
    for k in range(len(problem.knots)):
        v = np.diag(tails.knot_cov[k])
        assert (tails.knot_mu4[k] >= v ** 2).all()
