"""The linearisation of the compiled unicycle (examples/nonlinear/unicycle.c) against its
analytic Jacobians, at random points of a fixed seed; an affine model's to its coefficients,
to a few eps, unless it refuses the wide differences' points."""
from pathlib import Path

import numpy as np
import pytest

from stospline.design.linearise import linearise
from stospline.errors import ProblemError
from stospline.problem.plant_c import build_plant
from stospline.problem.plant_model import parse_plant

from conftest import EXAMPLES

SIGMA = np.array([0.5, 0.2])


@pytest.fixture(scope="module")
def unicycle():
    spec = parse_plant({"source": "unicycle.c", "params": SIGMA.tolist()},
                       Path(EXAMPLES / "nonlinear"), 4)
    return build_plant(spec, 4)


def analytic(x, u):
    """A, B, c, G (by state), H, g0 of the unicycle at (x, u)."""
    th, v = x[2], x[3]
    A = np.zeros((4, 4))
    A[0, 2], A[0, 3] = -v * np.sin(th), np.cos(th)
    A[1, 2], A[1, 3] = v * np.cos(th), np.sin(th)
    B = np.array([[0, 0], [0, 0], [0, 1], [1, 0]], dtype=float)
    f = np.array([v * np.cos(th), v * np.sin(th), u[1], u[0]])
    G = np.zeros((4, 4, 2))
    G[3, 3, 0], G[3, 2, 1] = SIGMA[0], SIGMA[1]     # the speed multiplies both slips
    return A, B, f - A @ x - B @ u, G


def test_the_unicycle_linearises_to_its_analytic_jacobians(unicycle):
    rng = np.random.default_rng(35)
    N = 64
    x = rng.normal(size=(N, 4)) * [3, 3, 2, 2]
    u = rng.normal(size=(N, 2))
    lin = linearise(unicycle, rng.uniform(0, 6, N), x, u)
    # Central differences with h ~ eps^(1/3): truncation and rounding both ~ eps^(2/3) ~ 4e-11
    # relative to the entries (of size up to ~10 here).
    assert lin.error < 1e-8
    for k in range(N):
        A, B, c, G = analytic(x[k], u[k])
        np.testing.assert_allclose(lin.A[k], A, rtol=0, atol=1e-8)
        np.testing.assert_allclose(lin.B[k], B, rtol=0, atol=1e-8)
        np.testing.assert_allclose(lin.c[k], c, rtol=0, atol=1e-7)
        np.testing.assert_allclose(lin.G[k], G, rtol=0, atol=1e-8)
    np.testing.assert_allclose(lin.H, 0, atol=1e-8)
    np.testing.assert_allclose(lin.g0, 0, atol=1e-7)    # noise proportional to the speed


def test_the_error_estimate_sees_a_kink():
    """|x| at 0 has no derivative: the two differences disagree, and the estimate says so."""
    class Kink:
        def drift(self, t, x, u):
            return np.abs(x[:, :1]) + u
        def diffusion(self, t, x, u):
            return np.zeros((x.shape[0], 1, 1))
    lin = linearise(Kink(), np.zeros(1), np.array([[1e-6]]), np.zeros((1, 1)))
    assert lin.error > 0.01
    smooth = linearise(Kink(), np.zeros(1), np.array([[0.5]]), np.zeros((1, 1)))
    assert smooth.error < 1e-9


class _Affine:
    """dx = (A x + B u + f) dt + Σ x_i G_i dZ, with random coefficients of a fixed seed; with
    `bound`, refused (as a C model's status is) beyond |x_i| > bound."""

    def __init__(self, bound=None):
        rng = np.random.default_rng(35)
        self.A, self.B = rng.normal(size=(3, 3)), rng.normal(size=(3, 2))
        self.f = rng.normal(size=3)
        self.G = rng.normal(size=(3, 3, 2))        # G[i] multiplies x_i
        self.bound = bound

    def _check(self, x):
        if self.bound is not None and np.any(np.abs(x) > self.bound):
            raise ProblemError("plant.source", "stospline_plant_drift returned 1")

    def drift(self, t, x, u):
        self._check(x)
        return x @ self.A.T + u @ self.B.T + self.f

    def diffusion(self, t, x, u):
        self._check(x)
        return np.einsum("ki,iab->kab", x, self.G)


def test_an_affine_model_linearises_to_its_coefficients():
    """The wide differences: a few eps, where the narrow ones alone are off by ~eps^(2/3)."""
    model, rng = _Affine(), np.random.default_rng(1)
    x, u = rng.normal(size=(32, 3)), rng.normal(size=(32, 2))
    lin = linearise(model, np.zeros(32), x, u)
    assert lin.error < 1e-14
    for k in range(32):
        np.testing.assert_allclose(lin.A[k], model.A, rtol=0, atol=1e-14)
        np.testing.assert_allclose(lin.B[k], model.B, rtol=0, atol=1e-14)
        np.testing.assert_allclose(lin.c[k], model.f, rtol=0, atol=1e-14)
        np.testing.assert_allclose(lin.G[k], model.G, rtol=0, atol=1e-14)


def test_a_model_that_refuses_the_wide_points_keeps_the_narrow_differences():
    model, rng = _Affine(bound=1.5), np.random.default_rng(1)
    x, u = rng.uniform(-1, 1, size=(32, 3)), rng.normal(size=(32, 2))
    lin = linearise(model, np.zeros(32), x, u)
    assert 1e-14 < lin.error < 1e-9
    for k in range(32):
        np.testing.assert_allclose(lin.A[k], model.A, rtol=0, atol=1e-9)
