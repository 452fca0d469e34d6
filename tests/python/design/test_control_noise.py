"""Noise that multiplies the control, sum_j u_j H_j dZ (the paper's suggested extension for
investment problems): the designers' extra Riccati terms against the oracle and Monte Carlo."""
import numpy as np
import pytest

from stospline.design.continuous import design_continuous, noise_operator
from stospline.design.zoh import design_zoh
from stospline.harness.controller import build_controller
from stospline.harness.montecarlo import compare_to_oracle, simulate
from stospline.oracle.evaluate import evaluate_continuous, evaluate_table
from stospline.table.format import table_of
from stospline.problem import parse_problem


def investment(h_scale=0.4, stages=2):
    """Wealth x with a risky allocation u: dx = (a x + b u) dt + (g x + h u) dZ, steered in
    expectation to targets while penalising variance and effort."""
    knots = [{"t": 1.0, "constraint": {"C": [[1.0]], "value": [1.5]},
              "penalty": {"C": [[1.0]], "target": [1.5], "weight": 2.0}},
             {"t": 2.0, "constraint": {"C": [[1.0]], "value": [2.0]},
              "penalty": {"C": [[1.0]], "target": [2.0], "weight": 5.0}}][:stages]
    return parse_problem({
        "name": "investment", "x0": [1.0], "tick_hz": 20,
        "dynamics": {"A": [[0.03]], "B": [[0.08]],
                     "noise": [{"state": 0, "G": [[0.1, 0.0]]},
                               {"input": 0, "G": [[0.0, h_scale]]}]},
        "cost": {"R": [[0.5]], "Q": [[0.1]], "S": [[0.05]], "q": [0.02], "r": [-0.01]},
        "knots": knots})


def two_state():
    return parse_problem({
        "name": "two", "x0": [0.5, -0.2], "tick_hz": 10,
        "dynamics": {"A": [[0.0, 1.0], [-0.5, -0.1]], "B": [[0.0, 0.2], [1.0, 0.0]],
                     "noise": [{"state": 1, "G": [[0.0], [0.3]]},
                               {"input": 0, "G": [[0.0], [0.25]]},
                               {"input": 1, "G": [[0.1], [0.0]]}]},
        "cost": {"R": [[1.0, 0.1], [0.1, 0.8]]},
        "knots": [{"t": 1.5, "constraint": {"C": [[1.0, 0.0]], "value": [1.0]}},
                  {"t": 3.0, "constraint": {"C": [[1.0, 0.0], [0.0, 1.0]], "value": [0.0, 0.0]},
                   "penalty": {"C": [[1.0, 0.0], [0.0, 1.0]], "target": [0.0, 0.0],
                               "weight": 1.0}}]})


@pytest.mark.parametrize("seed", range(4))
def test_noise_operator_is_the_trace_form(seed):
    """`noise_operator` (live multipliers only, column-wise products) equals the definition
    tr(G_k' P G_l), entry by entry, with some multipliers and all of them without noise."""
    rng = np.random.default_rng(seed)
    k, n, mz = rng.integers(1, 9), rng.integers(1, 7), rng.integers(1, 4)
    G = rng.normal(size=(k, n, mz))
    G[rng.random(k) < 0.4] = 0.0
    P = rng.normal(size=(n, n))
    P = P + P.T
    want = np.array([[np.trace(G[a].T @ P @ G[b]) for b in range(k)] for a in range(k)])
    np.testing.assert_allclose(noise_operator(G, P), want, rtol=0,
                               atol=1e-14 * max(np.abs(want).max(), 1.0))
    np.testing.assert_array_equal(noise_operator(np.zeros_like(G), P), np.zeros((k, k)))


@pytest.mark.parametrize("make", [investment, two_state])
@pytest.mark.parametrize("mode", ["stagewise", "joint"])
def test_continuous_design_with_input_noise_predicts_oracle(make, mode):
    problem = make()
    d = design_continuous(problem, mode=mode)
    m = evaluate_continuous(problem, d)
    assert abs(m.J - d.J0) <= 1e-8 * abs(d.J0)
    for k, kn in enumerate(problem.knots):
        np.testing.assert_allclose(m.knot_constraint[k], kn.constraint.value, atol=1e-8)


@pytest.mark.parametrize("make", [investment, two_state])
@pytest.mark.parametrize("mode", ["stagewise", "joint"])
def test_zoh_design_with_input_noise_predicts_oracle(make, mode):
    problem = make()
    d = design_zoh(problem, mode=mode)
    m = evaluate_table(problem, table_of(d, quantize=False), path=False)
    assert abs(m.J - d.J0) <= 1e-8 * abs(d.J0)
    for k, kn in enumerate(problem.knots):
        np.testing.assert_allclose(m.knot_constraint[k], kn.constraint.value, atol=1e-9)


def test_ignoring_input_noise_costs_more():
    problem = investment()
    aware = design_continuous(problem)
    naive = design_continuous(problem, noise=False)
    assert evaluate_continuous(problem, naive).J > evaluate_continuous(problem, aware).J * 1.001


def test_input_noise_monte_carlo_through_c():
    problem = two_state()
    table = table_of(design_zoh(problem))
    exact = evaluate_table(problem, table, path=False)
    mc = simulate(problem, build_controller(table), paths=4000, seed=11, substeps=100)
    agree = compare_to_oracle(mc, exact.J, exact.knot_mean)
    assert agree.ok, (agree.cost_z, agree.knot_mean_z)
    euler = evaluate_table(problem, table, propagator="euler", substeps=100, path=False)
    assert abs(euler.J - exact.J) < 0.05 * mc.cost_std() / np.sqrt(mc.paths)
