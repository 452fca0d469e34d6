"""Exact sampled-data design: optimal for the controller as it really runs."""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from stospline.design.continuous import design_continuous
from stospline.design.zoh import design_zoh
from stospline.harness.controller import build_controller
from stospline.design.moments import exact_tick, moment_generator, augmented_drift
from stospline.harness.montecarlo import compare_to_oracle, simulate
from stospline.oracle.evaluate import evaluate_table
from stospline.problem import parse_problem
from stospline.table.format import table_of

RATES = [10, 20, 50, 100, 1000]


def _residual(problem, moments):
    return max(np.abs(moments.knot_constraint[k] - kn.constraint.value).max()
               for k, kn in enumerate(problem.knots))


@pytest.fixture(scope="module")
def rate_sweep(robot_problem):
    cont = design_continuous(robot_problem)
    rows = {}
    for hz in RATES:
        zoh = design_zoh(robot_problem, hz)
        exact = evaluate_table(robot_problem, table_of(zoh, quantize=False), path=False)
        sampled = evaluate_table(robot_problem, table_of(cont, hz, quantize=False),
                                 path=False)
        rows[hz] = (zoh.J0, exact, sampled)
    return cont, rows


@pytest.mark.parametrize("hz", RATES)
def test_exact_design_predicts_oracle_and_meets_constraints(robot_problem, rate_sweep, hz):
    J0, exact, sampled = rate_sweep[1][hz]
    assert abs(exact.J - J0) <= 1e-8 * J0
    assert _residual(robot_problem, exact) < 1e-9
    # Sampling the continuous gains instead misses the constraints and costs more.
    assert _residual(robot_problem, sampled) > 1e3 * max(_residual(robot_problem, exact), 1e-13)
    assert sampled.J > exact.J


def test_sampled_design_degrades_as_rate_drops(robot_problem, rate_sweep):
    res = [_residual(robot_problem, rate_sweep[1][hz][2]) for hz in RATES]
    excess = [rate_sweep[1][hz][2].J - rate_sweep[1][hz][1].J for hz in RATES]
    assert all(a > b for a, b in zip(res, res[1:]))
    assert all(a > b for a, b in zip(excess, excess[1:]))


def test_exact_cost_converges_to_continuous_J0(rate_sweep):
    cont, rows = rate_sweep
    gaps = np.array([rows[hz][0] - cont.J0 for hz in RATES])
    assert np.all(gaps > 0) and np.all(np.diff(gaps) < 0)
    # First order in h: gap * rate is nearly constant at the fast end.
    assert gaps[-1] * 1000 == pytest.approx(gaps[-2] * 100, rel=0.05)
    assert gaps[-1] < 1e-3 * cont.J0


def test_noise_free_path_is_best_piecewise_constant_acceleration():
    """Separate KKT solve: min h*sum a_j^2 subject to the knot positions, a_j held per tick."""
    hz, y0, v0 = 4, 0.3, -0.7
    times, values = [1.0, 2.5, 3.0, 4.5], [1.0, -0.5, 0.25, 2.0]
    problem = parse_problem({
        "name": "dint", "x0": [y0, v0], "tick_hz": hz,
        "dynamics": {"A": [[0.0, 1.0], [0.0, 0.0]], "B": [[0.0], [1.0]]},
        "cost": {"R": [[1.0]]},
        "knots": [{"t": t, "constraint": {"C": [[1.0, 0.0]], "value": [v]}}
                  for t, v in zip(times, values)]})
    h = 1.0 / hz
    T = int(round(times[-1] * hz))
    # Position after i ticks: y0 + v0 i h + sum_{j<i} a_j h^2 (i - j - 1/2).
    pos = np.array([[h * h * (i - j - 0.5) if j < i else 0.0 for j in range(T)]
                    for i in range(T + 1)])
    vel = np.array([[h if j < i else 0.0 for j in range(T)] for i in range(T + 1)])
    knot_ticks = [int(round(t * hz)) for t in times]
    Cm = pos[knot_ticks]
    d = np.array(values) - y0 - v0 * h * np.array(knot_ticks)
    a = Cm.T @ np.linalg.solve(Cm @ Cm.T, d)
    path_y = y0 + v0 * h * np.arange(T + 1) + pos @ a
    path_v = v0 + vel @ a

    zoh = design_zoh(problem)
    m = evaluate_table(problem, table_of(zoh, quantize=False))
    np.testing.assert_allclose(m.path_mean[:, 0], path_y, rtol=0, atol=1e-9)
    np.testing.assert_allclose(m.path_mean[:, 1], path_v, rtol=0, atol=1e-9)
    assert zoh.J0 == pytest.approx(h * a @ a, rel=1e-9)


def test_tick_map_matches_direct_integration_of_moment_ode(robot_problem):
    """The shared tick map (Van Loan exponential) against solve_ivp on the moment ODE."""
    st = robot_problem.stages[0]
    n_const, h = 4, 0.05
    Ahat = augmented_drift(st, n_const)
    gen = moment_generator(Ahat, st.G)
    rng = np.random.default_rng(3)
    Z = rng.normal(size=(8, 8))
    M0 = (Z @ Z.T).ravel()
    sol = solve_ivp(lambda t, y: np.concatenate([gen @ y[:64], y[:64]]), (0, h),
                    np.concatenate([M0, np.zeros(64)]), rtol=1e-12, atol=1e-14)
    prop = exact_tick(st, n_const, h)
    np.testing.assert_allclose(prop.Phi @ M0, sol.y[:64, -1], rtol=1e-9, atol=1e-11)
    np.testing.assert_allclose(prop.Psi @ M0, sol.y[64:, -1], rtol=1e-9, atol=1e-11)


def test_mc_through_c_at_10hz_agrees_with_oracle(robot_problem):
    zoh = design_zoh(robot_problem, 10)
    table = table_of(zoh)
    exact = evaluate_table(robot_problem, table, path=False)
    assert exact.J == pytest.approx(zoh.J0, rel=1e-6)        # float32 quantization only
    mc = simulate(robot_problem, build_controller(table), paths=4000, seed=10, substeps=200)
    agree = compare_to_oracle(mc, exact.J, exact.knot_mean)
    assert agree.ok, (agree.cost_z, agree.knot_mean_z)
    # The plant scheme's own bias at 200 substeps per 0.1 s tick, next to the MC error.
    euler = evaluate_table(robot_problem, table, propagator="euler", substeps=200, path=False)
    assert abs(euler.J - exact.J) < 0.05 * mc.cost_std() / np.sqrt(mc.paths)
