"""Plan -> linearise -> design on [plant] models: a linear model given in C designs exactly as
the same problem given by [dynamics]; the unicycle's converged mean path is a solution of the
nonlinear model's own equation and a fixed point of the iteration; no convergence is refused."""
import copy
import tomllib
from pathlib import Path

import numpy as np
import pytest

from stospline.errors import ProblemError
from stospline.nonlinear.iterate import fit_plant
from stospline.pipeline import design_problem
from stospline.problem.plant_c import build_plant
from stospline.problem.plant_model import parse_plant
from stospline.problem.reader import parse_problem
from support.plant_sources import LINEAR, linear_doc, the_same_linear_doc

from conftest import EXAMPLES

UNICYCLE = EXAMPLES / "nonlinear"


@pytest.fixture(scope="module")
def unicycle_doc():
    return tomllib.loads((UNICYCLE / "robot_unicycle.toml").read_text())


@pytest.fixture(scope="module")
def unicycle_fit(unicycle_doc):
    return fit_plant(unicycle_doc, UNICYCLE)


def test_a_linear_model_in_c_designs_as_the_same_linear_problem(tmp_path):
    (tmp_path / "model.c").write_text(LINEAR)
    problem, fit = fit_plant(linear_doc(), tmp_path)
    # A linear model's linearisation does not depend on the path: the second design
    # reproduces the first.
    assert fit.iterations == 2 and fit.changes[-1] < 1e-9
    got = design_problem(problem)
    want = design_problem(parse_problem(the_same_linear_doc()))
    # The derivatives of a linear C function by differences: exact up to rounding (~1e-11).
    np.testing.assert_allclose(got.design.J0, want.design.J0, rtol=1e-9)
    np.testing.assert_allclose(got.implemented.J, want.implemented.J, rtol=1e-9)
    for a, b in zip(got.implemented.knot_mean, want.implemented.knot_mean):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-9)
    for a, b in zip(got.implemented.knot_cov, want.implemented.knot_cov):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-9)


def _rk4_tick(model, t, x, u, h):
    def f(tt, xx):
        return model.drift(np.full(len(xx), tt) if np.ndim(tt) == 0 else tt, xx, u)
    k1 = f(t, x)
    k2 = f(t + h / 2, x + h / 2 * k1)
    k3 = f(t + h / 2, x + h / 2 * k2)
    k4 = f(t + h, x + h * k3)
    return x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def test_the_converged_mean_path_solves_the_nonlinear_model(unicycle_doc, unicycle_fit):
    """The linear model is exact at the path it is linearised around, so at the fixed point
    the mean path follows dx/dt = f(x, u) of the C model itself, tick by tick (up to the
    linear interpolation of the model between its samples, 10 ms apart)."""
    problem, fit = unicycle_fit
    assert fit.changes[-1] <= fit.tolerance == 1e-6
    model = build_plant(parse_plant(unicycle_doc["plant"], UNICYCLE, 4), 4)
    P = fit.path
    step = np.abs(np.diff(P.x, axis=0))
    residual = np.abs(_rk4_tick(model, P.t[:-1], P.x[:-1], P.u, 1 / problem.tick_hz)
                      - P.x[1:])
    assert residual.max() < 1e-3 * step.max()
    # It meets the knots' expected constraints: x + y = 0 at t = 3, rest at (-1, 5) at t = 6.
    assert abs(P.x[3000, 0] + P.x[3000, 1]) < 1e-6
    np.testing.assert_allclose(P.x[6000, [0, 1, 3]], [-1.0, 5.0, 0.0], atol=1e-6)


def test_the_converged_path_is_a_fixed_point(unicycle_doc, unicycle_fit):
    """Started from its own converged path, the iteration stops at once with the same
    design."""
    problem, fit = unicycle_fit
    doc = copy.deepcopy(unicycle_doc)
    P = fit.path
    doc["plant"]["guess"] = {"t": P.t.tolist(), "x": P.x.tolist(),
                             "u": np.vstack([P.u, P.u[-1:]]).tolist()}
    again, fit2 = fit_plant(doc, UNICYCLE)
    assert fit2.iterations == 1 and fit2.changes[0] <= 1e-6
    np.testing.assert_allclose(design_problem(again).design.J0,
                               design_problem(problem).design.J0, rtol=1e-6)


def test_no_convergence_is_refused_naming_max_iterations(unicycle_doc):
    doc = copy.deepcopy(unicycle_doc)
    doc["plant"]["max_iterations"] = 2
    with pytest.raises(ProblemError) as err:
        fit_plant(doc, UNICYCLE)
    assert err.value.field == "plant.max_iterations"
    assert "did not converge in 2 iterations" in err.value.reason
