"""Affine drift ``dX = (A X + B u + f) dt + ...`` (``[dynamics] f``, constant or sampled): every
design against two independent numbers.

* the same problem written the way a user had to before, with a constant state ``x_c = 1``
  (``A = [[A, f], [0, 0]]``): the designs must give the same predicted cost, and the exact
  ZOH gains on the real states must be the same law (the constant's column folded into k0);
* the oracle of the law (`evaluate_table`, `evaluate_continuous`, which integrate the moments
  with the drift on their own) must meet every constraint exactly and give the predicted cost;
* Monte Carlo through the compiled C controller (the harness plant with the drift) must agree
  with that oracle, and disagree with the oracle of the same table without the drift.
"""
import tomllib

import numpy as np
import pytest

import stospline
from stospline.errors import ProblemError
from stospline.pipeline import predicted_cost
from stospline.problem.reader import parse_problem
from stospline.harness.controller import build_controller
from stospline.oracle.faults import evaluate_with_faults
from stospline.harness.montecarlo import compare_to_oracle, simulate
from stospline.oracle.evaluate import evaluate_table

from conftest import EXAMPLES
from support.problems import BASE, edit

GRAVITY = edit(BASE, ("B = [[0], [1]]", "B = [[0], [1]]\nf = [0, -9.81]"))
# The same problem with gravity as a constant third state (what the drift replaces).
BY_HAND = edit(BASE, ("x0 = [0.0, 0.0]", "x0 = [0.0, 0.0, 1.0]"),
               ("A = [[0, 1], [0, 0]]", "A = [[0, 1, 0], [0, 0, -9.81], [0, 0, 0]]"),
               ("B = [[0], [1]]", "B = [[0], [1], [0]]"),
               ("G = [[0], [0.3]]", "G = [[0], [0.3], [0]]"),
               ("Q = [[0, 0], [0, 0]]", "Q = [[0, 0, 0], [0, 0, 0], [0, 0, 0]]"),
               ("penalty = { C = [[1, 0]]", "penalty = { C = [[1, 0, 0]]"),
               ("constraint = { C = [[1, 0]]", "constraint = { C = [[1, 0, 0]]"),
               ("C = [[1, 0], [0, 1]]", "C = [[1, 0, 0], [0, 1, 0]]"))


def parse(text):
    return parse_problem(tomllib.loads(text))


@pytest.mark.parametrize("discretization", ["exact-zoh", "continuous"])
@pytest.mark.parametrize("mode", ["stagewise", "joint"])
def test_the_drift_is_the_constant_state_done_right(discretization, mode):
    p, hand = parse(GRAVITY), parse(BY_HAND)
    d = stospline.design_problem(p, discretization=discretization, mode=mode)
    dh = stospline.design_problem(hand, discretization=discretization, mode=mode)
    assert predicted_cost(d) == pytest.approx(predicted_cost(dh), rel=1e-10)
    # The law's exact oracle (with the drift): the predicted cost, every constraint met.
    assert d.law.J == pytest.approx(predicted_cost(d), rel=1e-9)
    for k, kn in enumerate(p.knots):
        np.testing.assert_allclose(d.law.knot_constraint[k], kn.constraint.value, atol=1e-9)
    if discretization == "exact-zoh" and mode == "stagewise":
        # The same law: the by-hand constant state's gain column is the drift's feed-forward.
        # (Joint tables with more multipliers than states latch the state instead, so the two
        # problems' tables differ in form there; the costs and the oracle above still agree.)
        Th, T = dh.table, d.table
        np.testing.assert_allclose(T.K, Th.K[:, :, :2], atol=2e-6)
        np.testing.assert_allclose(T.k0, Th.k0 + Th.K[:, :, 2], atol=2e-5)


def test_without_the_drift_the_constraints_are_missed():
    """The drift matters: the oracle of the gravity-free problem's law, run on the plant with
    gravity, misses the constraint by far more than rounding."""
    p = parse(GRAVITY)
    blind = stospline.design_problem(parse(BASE))
    miss = evaluate_table(p, blind.table, path=False).knot_constraint[0][0] - 1.0
    assert abs(miss) > 0.1


def test_time_varying_drift():
    """Sampled f (linear from -9.81 to 0): the exact-ZOH law meets the constraints exactly by
    the oracle's own integration (DOP853 per tick), and its cost is the predicted one to the
    Magnus expansion's accuracy."""
    p = parse(edit(BASE, ("B = [[0], [1]]",
                          "B = [[0], [1]]\nf = { t = [0, 2], values = [[0, -9.81], [0, 0]] }")))
    assert p.stages[0].varying is not None
    np.testing.assert_allclose(p.stages[0].at(1.0).f, [0.0, -4.905])
    d = stospline.design_problem(p)
    assert d.law.J == pytest.approx(predicted_cost(d), rel=1e-6)
    for k, kn in enumerate(p.knots):
        np.testing.assert_allclose(d.law.knot_constraint[k], kn.constraint.value, atol=1e-9)


def test_bands_with_a_drift():
    """The band design (joint, band dual in the table) with a constant drift on the robot:
    the implemented law's expected outputs lie within every band."""
    text = (EXAMPLES / "robot_bands.toml").read_text()
    text = text.replace("B = [[0, 0],", "f = [0, 0.2, 0, -0.1]\nB = [[0, 0],", 1)
    p = parse(text)
    d = stospline.design_problem(p, mode="joint")
    for k, kn in enumerate(p.knots):
        lo, hi = kn.constraint.bounds
        y = d.implemented.knot_constraint[k]
        assert np.all(y >= lo - 1e-5) and np.all(y <= hi + 1e-5), (k, y, lo, hi)


def test_monte_carlo_through_c_with_the_drift():
    p = parse(GRAVITY)
    d = stospline.design_problem(p)
    ctl = build_controller(d.table)
    mc = simulate(p, ctl, paths=20000, seed=20261124, substeps=2)
    exact = evaluate_table(p, d.table, propagator="euler", substeps=2, path=False)
    agree = compare_to_oracle(mc, exact.J, exact.knot_mean, knot_covs=exact.knot_cov)
    assert agree.ok, agree.verdict
    no_drift = evaluate_table(parse(BASE), d.table, propagator="euler", substeps=2, path=False)
    assert not compare_to_oracle(mc, no_drift.J, no_drift.knot_mean).ok
    # The fault oracle carries the drift the same way (no faults: the same moments).
    f = evaluate_with_faults(p, d.table, propagator="euler", substeps=2)
    assert f.J == pytest.approx(exact.J, rel=1e-12)


def test_drift_round_trips_and_bad_drifts_name_the_field():
    p = parse(GRAVITY)
    again = parse(p.to_toml())
    np.testing.assert_array_equal(again.stages[0].f, [0.0, -9.81])
    assert parse(BASE).stages[0].f is None
    for bad, field, reason in [("f = [0, 1, 2]", "dynamics.f", "has length 3, expected 2"),
                               ('f = "down"', "dynamics.f", "vector"),
                               ("f = [0, nan]", "dynamics.f[1]", "finite")]:
        with pytest.raises(ProblemError) as exc:
            parse(edit(BASE, ("B = [[0], [1]]", "B = [[0], [1]]\n" + bad)))
        assert exc.value.field == field and reason in exc.value.reason, exc.value
