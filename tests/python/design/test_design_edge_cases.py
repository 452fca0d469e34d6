"""The Python API beyond problem files: callables for time-varying data, knots with neither
penalty nor constraint, the cost-to-go of every stage, and very coarse tick rates."""
import dataclasses

import numpy as np
import pytest

from stospline.design.continuous import DesignError, design_continuous
from stospline.design.zoh import design_zoh
from stospline.oracle.evaluate import evaluate_continuous, evaluate_table
from stospline.table.format import table_of
from stospline.problem import Knot, Problem, parse_problem


def base_doc():
    return {"name": "api", "x0": [0.5, 0.0], "tick_hz": 4,
            "dynamics": {"A": [[0, 1], [0, 0]], "B": [[0], [1]],
                         "noise": [{"state": 1, "G": [[0.0], [0.3]]}]},
            "cost": {"R": [[1.0]]},
            "knots": [{"t": 1.0, "penalty": {"C": [[1, 0]], "target": [1.0], "weight": 3.0}},
                      {"t": 2.0},
                      {"t": 3.0, "constraint": {"C": [[1, 0], [0, 1]], "value": [0.0, 0.0]}}]}


def test_callable_time_varying_data_from_the_api():
    p = parse_problem(base_doc())
    # A spring that stiffens with time and an input gain that fades, given as callables.
    varying = lambda t: {"A": np.array([[0.0, 1.0], [-0.5 * t, 0.0]]),  # noqa: E731
                         "B": np.array([[0.0], [1.0 / (1.0 + 0.2 * t)]])}
    stages = tuple(dataclasses.replace(s, varying=varying) for s in p.stages)
    p = dataclasses.replace(p, stages=stages)
    d = design_continuous(p)
    m = evaluate_continuous(p, d)
    assert abs(m.J - d.J0) <= 1e-8 * d.J0
    np.testing.assert_allclose(m.knot_constraint[2], [0.0, 0.0], atol=1e-8)


def test_knot_with_neither_penalty_nor_constraint_and_cost_to_go():
    p = parse_problem(base_doc())
    assert p.knots[1].penalty is None and p.knots[1].constraint is None
    for mode in ("stagewise", "joint"):
        d = design_continuous(p, mode=mode)
        m = evaluate_continuous(p, d)
        assert abs(m.J - d.J0) <= 1e-8 * d.J0
    d = design_continuous(p)
    # J_k(x) of every stage is available: from the oracle started at t_1 in state x.
    x1 = np.array([0.2, -0.4])
    tail = Problem("tail", 1.0, x1, p.tick_hz, p.stages[1:], p.knots[1:])
    sub = dataclasses.replace(d, problem=tail, stages=d.stages[1:])
    assert evaluate_continuous(tail, sub).J == pytest.approx(d.cost_to_go(1, x1), rel=1e-8)


@pytest.mark.parametrize("hz", [1, 2])
def test_exact_design_at_a_few_ticks_per_stage(hz):
    """At 1 Hz the last stage has one tick, one held input, for a two-row constraint: W is
    singular and the design is refused with a DesignError. At 2 Hz (two ticks) it is met."""
    p = dataclasses.replace(parse_problem(base_doc() | {"tick_hz": 2}), tick_hz=hz)
    if hz == 1:
        with pytest.raises(DesignError, match="cannot be met"):
            design_zoh(p)
        return
    d = design_zoh(p)
    m = evaluate_table(p, table_of(d, quantize=False), path=False)
    assert abs(m.J - d.J0) <= 1e-8 * d.J0
    np.testing.assert_allclose(m.knot_constraint[2], [0.0, 0.0], atol=1e-9)
