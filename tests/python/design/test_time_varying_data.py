"""Time-varying stage data (sampled, linear or zero-order-hold interpolation) and tracking of
a nominal path y0(t): designers against the oracle, the Magnus tick map against direct
integration, and Monte Carlo through the compiled controller."""
import numpy as np
import pytest

from stospline.design.continuous import design_continuous
from stospline.harness.controller import build_controller
from stospline.design.moments import exact_tick, running_cost_matrix, varying_tick
from stospline.harness.montecarlo import compare_to_oracle, simulate
from stospline.oracle.evaluate import _tick_varying, evaluate_continuous, evaluate_table
from stospline.problem import ProblemError, parse_problem
from stospline.table.format import table_of


def tv_doc(interpolation="linear"):
    return {
        "name": "tv", "x0": [1.0, 0.0], "tick_hz": 20,
        "dynamics": {
            "A": {"t": [0, 1, 2], "interpolation": interpolation,
                  "values": [[[0, 1], [-1, -0.2]], [[0, 1], [-2, 0.1]], [[0, 1], [-1, 0]]]},
            "B": {"t": [0, 2], "values": [[[0], [1]], [[0], [0.6]]]},
            "noise": [{"state": 1, "G": {"t": [0, 2], "values": [[[0], [0.2]], [[0], [0.5]]]}},
                      {"input": 0, "G": [[0.0], [0.1]]}]},
        "cost": {"R": [[1.0]], "Q": {"t": [0, 2], "values": [[[1, 0], [0, 0]], [[2, 0], [0, 1]]]},
                 "tracking": {"C": [[1, 0]], "weight": 3.0, "t": [0, 1, 2],
                              "y0": [[0.0], [1.0], [0.5]]}},
        "knots": [{"t": 1.0, "constraint": {"C": [[1, 0]], "value": [0.5]}},
                  {"t": 2.0, "constraint": {"C": [[1, 0]], "value": [0.0]},
                   "penalty": {"C": [[0, 1]], "target": [0.0], "weight": 2.0}}]}


def test_tracking_terms_are_derived():
    st = parse_problem(tv_doc()).stages[0].at(0.5)
    # y0(0.5) = 0.5, Qy = 3, C = [1, 0]: Q += C'QyC, q = -C'Qy y0, rho = y0'Qy y0.
    np.testing.assert_allclose(st.Q, [[1.25 + 3.0, 0], [0, 0.25]])
    np.testing.assert_allclose(st.q, [-1.5, 0.0])
    assert st.rho == pytest.approx(0.75)
    np.testing.assert_allclose(st.A, [[0, 1], [-1.5, -0.05]])


@pytest.mark.parametrize("interpolation", ["linear", "zoh"])
@pytest.mark.parametrize("mode", ["stagewise", "joint"])
def test_continuous_design_with_varying_data_predicts_oracle(interpolation, mode):
    problem = parse_problem(tv_doc(interpolation))
    d = design_continuous(problem, mode=mode)
    m = evaluate_continuous(problem, d)
    assert abs(m.J - d.J0) <= 1e-8 * d.J0
    for k, kn in enumerate(problem.knots):
        np.testing.assert_allclose(m.knot_constraint[k], kn.constraint.value, atol=1e-8)


def test_magnus_tick_is_fourth_order_and_exact_when_constant():
    st = parse_problem(tv_doc()).stages[0]
    rng = np.random.default_rng(0)
    Z = rng.normal(size=(4, 4))
    M0 = Z @ Z.T
    errs = []
    for h in (0.1, 0.05):
        Phi, row = varying_tick(st, 2, 0.3, h)
        M1, J1, _ = _tick_varying(st, M0, 0.3, h, 2, 1)
        errs.append(np.abs((Phi @ M0.ravel()).reshape(4, 4) - M1).max())
        assert abs(row @ M0.ravel() - J1) < 1e-5 * h
    assert 25 < errs[0] / errs[1] < 40          # local error O(h^5): ratio ~32
    frozen = st.at(0.3)
    Phi, row = varying_tick(frozen, 2, 0.3, 0.1)
    prop = exact_tick(frozen, 2, 0.1)
    np.testing.assert_allclose(Phi, prop.Phi, atol=1e-14)
    np.testing.assert_allclose(row, running_cost_matrix(frozen, 2, 1, 4, 2).ravel() @ prop.Psi,
                               atol=1e-14)


def test_sampled_varying_design_monte_carlo_through_c():
    problem = parse_problem(tv_doc())
    table = table_of(design_continuous(problem))
    exact = evaluate_table(problem, table, path=False)
    mc = simulate(problem, build_controller(table), paths=3000, seed=4, substeps=20)
    agree = compare_to_oracle(mc, exact.J, exact.knot_mean)
    assert agree.ok, (agree.cost_z, agree.knot_mean_z)


@pytest.mark.parametrize("bad, field, reason", [
    (lambda d: d["dynamics"]["A"].update(t=[0.5, 1, 2]), "dynamics.A.t", "cover"),
    (lambda d: d["dynamics"]["A"].update(t=[0, 2, 1]), "dynamics.A.t", "increase"),
    (lambda d: d["dynamics"]["A"].update(interpolation="cubic"), "dynamics.A.interpolation",
     "linear"),
    (lambda d: d["dynamics"]["A"]["values"].pop(), "dynamics.A.values", "3 samples"),
    (lambda d: d["cost"]["tracking"].update(y0=[[0.0], [1.0, 2.0], [0.5]]),
     "cost.tracking.y0[1]", "length"),
    (lambda d: d["cost"]["tracking"].update(t=[0.5, 1.0, 2.0]), "cost.tracking.t", "cover"),
    (lambda d: d["dynamics"]["A"]["values"].__setitem__(1, [[0.0]]), "dynamics.A.values[1]",
     "same shape"),
    (lambda d: d["cost"]["tracking"].update(weight=[[1.0, 2.0], [3.0, 1.0]]),
     "cost.tracking.weight", "rows"),
    (lambda d: d["cost"].update(Q={"t": [0, 2], "values": [[[1, 0], [0, 0]], [[-2, 0], [0, 1]]]}),
     "cost", "at t = 2"),
])
def test_bad_time_varying_data_is_rejected(bad, field, reason):
    doc = tv_doc()
    bad(doc)
    with pytest.raises(ProblemError) as err:
        parse_problem(doc)
    assert err.value.field == field and reason in err.value.reason, str(err.value)


@pytest.mark.parametrize("mode", ["stagewise", "joint"])
def test_exact_zoh_design_with_varying_data(mode):
    """Per-tick Magnus maps in the designer, the oracle integrating each tick directly: the
    prediction matches to the Magnus error (O(h^5) per tick, here < 1e-8 relative at 20 Hz)
    and constraints are met to the same order; with zoh-interpolated data on the tick grid
    the data are constant per tick and both are exact."""
    from stospline.design.zoh import design_zoh
    for interp, tol in (("linear", 1e-7), ("zoh", 1e-10)):
        doc = tv_doc(interp)
        if interp == "zoh":   # every series held between samples on the tick grid
            for series in (doc["dynamics"]["B"], doc["dynamics"]["noise"][0]["G"],
                           doc["cost"]["Q"], doc["cost"]["tracking"]):
                series["interpolation"] = "zoh"
        problem = parse_problem(doc)
        d = design_zoh(problem, mode=mode)
        m = evaluate_table(problem, table_of(d, quantize=False), path=False)
        assert abs(m.J - d.J0) <= tol * d.J0, (interp, m.J, d.J0)
        for k, kn in enumerate(problem.knots):
            np.testing.assert_allclose(m.knot_constraint[k], kn.constraint.value, atol=tol)
