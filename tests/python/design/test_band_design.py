"""Band constraints (the paper's Section 4) with joint multipliers: the OSQP dual against
brute-force active-set enumeration, the oracle, and Monte Carlo through the C controller."""
import tomllib

import numpy as np
import pytest

from stospline.design.bands import design_bands, enumerate_active_sets, solve_band_dual
from stospline.design.continuous import DesignError
from stospline.harness.controller import build_controller
from stospline.harness.montecarlo import compare_to_oracle, simulate
from stospline.oracle.evaluate import evaluate_continuous, evaluate_table
from stospline.table.format import table_of
from stospline.pipeline import design_problem
from stospline.problem import ProblemError, parse_problem

from conftest import EXAMPLES
from support.band_problems import random_band_problem, robot_with_bands


@pytest.mark.parametrize("seed", range(12))
def test_dual_qp_equals_best_active_set(seed):
    problem = random_band_problem(seed)
    b = design_bands(problem)
    st0 = b.base.stages[0]
    e = st0.N0.T @ problem.x0 + st0.m0
    brute = enumerate_active_sets(e, st0.W0, b.lower, b.upper)
    assert b.solution.value == pytest.approx(brute.value, rel=1e-8, abs=1e-10)
    np.testing.assert_allclose(b.solution.lam, brute.lam, atol=1e-8)
    # Multipliers have the right sign and are complementary to the bands.
    lam, y, eq = b.solution.lam, b.solution.expected, b.lower == b.upper
    assert np.all(y >= b.lower - 1e-9) and np.all(y <= b.upper + 1e-9)
    free = ~eq
    assert np.all(lam[free & (lam > 1e-9)] * 0 + y[free & (lam > 1e-9)]
                  == pytest.approx(b.upper[free & (lam > 1e-9)], abs=1e-9))
    assert np.all(y[free & (lam < -1e-9)] == pytest.approx(b.lower[free & (lam < -1e-9)],
                                                           abs=1e-9))
    # The design's table, evaluated exactly, costs what the dual predicts.
    m = evaluate_table(problem, table_of(b, quantize=False), path=False)
    assert m.J == pytest.approx(b.J0, rel=1e-8)
    for k, kn in enumerate(problem.knots):
        lo, hi = kn.constraint.bounds
        assert np.all(m.knot_constraint[k] >= lo - 1e-9) and np.all(m.knot_constraint[k] <= hi + 1e-9)


def test_robot_band_design_continuous_and_zoh():
    problem = robot_with_bands()
    for disc in ("continuous", "exact-zoh"):
        d = design_problem(problem, mode="joint", discretization=disc)
        assert d.law.J == pytest.approx(d.design.J0, rel=1e-8)
        at = {(a["knot"], a["row"]): a["at"] for a in d.design.active_set()}
        assert at[(0, 0)] == "lower" and at[(0, 1)] == "upper" and at[(1, 0)] == "equality"
    # A band around the equality E{x + y} = 0 relaxes it: cheaper than the equality design.
    eq = design_problem(parse_problem(tomllib.loads((EXAMPLES / "robot_corridor.toml")
                                                    .read_text()) | {"tick_hz": 50}),
                        mode="joint")
    relaxed = design_problem(robot_with_bands(rows=1), mode="joint")
    assert relaxed.design.J0 < eq.design.J0 - 1e-3


def test_band_design_monte_carlo_through_c():
    problem = robot_with_bands(tick_hz=20)
    d = design_problem(problem, mode="joint")
    mc = simulate(problem, build_controller(d.table), paths=3000, seed=21, substeps=50)
    agree = compare_to_oracle(mc, d.implemented.J, d.implemented.knot_mean)
    assert agree.ok, (agree.cost_z, agree.knot_mean_z)


def test_stagewise_bands_are_refused_and_empty_bands_rejected():
    with pytest.raises(DesignError, match="mode joint"):
        design_problem(robot_with_bands(), mode="stagewise")
    doc = tomllib.loads((EXAMPLES / "robot_corridor.toml").read_text())
    doc["knots"][0]["constraint"] = {"C": [[1, 0, 1, 0]], "lower": [0.5], "upper": [0.2]}
    with pytest.raises(ProblemError) as err:
        parse_problem(doc)
    assert err.value.field == "knots[0].constraint.lower" and "empty" in err.value.reason


def test_infeasible_equalities_within_bands_are_reported():
    e, W = np.array([1.0, 2.0]), np.array([[1.0, 1.0], [1.0, 1.0]])   # singular: y1 - y2 fixed
    with pytest.raises(DesignError):
        enumerate_active_sets(e, W, np.array([0.0, 0.0]), np.array([0.0, 0.0]))
