"""Per-stage data: ``[[stages]]`` entries override ``[dynamics]``/``[cost]`` key by key."""
import tomllib

import numpy as np
import pytest

from stospline.design.continuous import design_continuous
from stospline.pipeline import design_problem
from stospline.problem import parse_problem

from support.problems import BASE, STAGES


def parse(text):
    return parse_problem(tomllib.loads(text))


def test_overrides_apply_per_stage_and_the_rest_falls_back():
    top, per = parse(BASE), parse(STAGES)
    s0, s1 = per.stages
    np.testing.assert_array_equal(s0.R, [[2.0]])                     # stages[0].cost.R
    np.testing.assert_array_equal(s1.R, top.stages[1].R)             # inherited from [cost]
    np.testing.assert_array_equal(s0.A, top.stages[0].A)             # inherited from [dynamics]
    np.testing.assert_array_equal(s1.A, [[0.0, 1.0], [0.0, -1.0]])   # stages[1].dynamics.A
    for s in per.stages:
        np.testing.assert_array_equal(s.G, top.stages[0].G)
        np.testing.assert_array_equal(s.B, top.stages[0].B)
        np.testing.assert_array_equal(s.Q, top.stages[0].Q)


def test_empty_stage_entries_change_nothing():
    top, per = parse(BASE), parse(BASE + "\n[[stages]]\n[[stages]]\n")
    for a, b in zip(top.stages, per.stages):
        for f in ("A", "B", "G", "Q", "S", "R", "q", "r", "rho"):
            np.testing.assert_array_equal(getattr(a, f), getattr(b, f))


def test_noise_override_and_common_width():
    """``noise = []`` silences a stage; a stage's noise may set mz when [dynamics] has none."""
    quiet = parse(BASE + "\n[[stages]]\ndynamics = { noise = [] }\n[[stages]]\n")
    assert not quiet.stages[0].G.any() and quiet.stages[1].G.any()
    assert quiet.stages[0].G.shape == quiet.stages[1].G.shape == (2, 2, 1)

    text = BASE.replace("noise = [{ state = 1, G = [[0], [0.3]] }]\n", "")
    wide = parse(text + "\n[[stages]]\n[[stages]]\n"
                        "dynamics = { noise = [{ state = 1, G = [[0, 0], [0.3, 0.1]] }] }\n")
    assert wide.mz == 2
    assert not wide.stages[0].G.any() and wide.stages[0].G.shape == (2, 2, 2)
    np.testing.assert_array_equal(wide.stages[1].G[1], [[0, 0], [0.3, 0.1]])


def test_per_stage_input_weight_reaches_the_design():
    """Deterministic x' = u from x(0) = 0 through x(1) = 1 and x(2) = 3 with min of r_k u^2:
    u = 1 on stage 0 and u = 2 on stage 1, so J0 = r_0 * 1 + r_1 * 4."""
    text = """
name = "ramp"
x0 = [0.0]
tick_hz = 10
[dynamics]
A = [[0]]
B = [[1]]
[cost]
R = [[1]]
[[knots]]
t = 1.0
constraint = { C = [[1]], value = [1.0] }
[[knots]]
t = 2.0
constraint = { C = [[1]], value = [3.0] }
[[stages]]
cost = { R = [[2.5]] }
[[stages]]
"""
    d = design_continuous(parse(text))
    assert d.J0 == pytest.approx(2.5 * 1 + 1.0 * 4, rel=1e-9)


@pytest.mark.parametrize("discretization", ["exact-zoh", "continuous"])
def test_per_stage_design_agrees_with_the_oracle(discretization):
    d = design_problem(parse(STAGES), discretization=discretization)
    assert d.design.J0 == pytest.approx(d.law.J, rel=1e-8)
    for kn, achieved in zip(d.problem.knots, d.law.knot_constraint):
        np.testing.assert_allclose(achieved, kn.constraint.value, rtol=0, atol=1e-8)
