"""Q15/Q31 scaling of the sensitivity columns over the whole parameter box
(`stospline.table.qparams`): for parameter vectors across the box (its vertices and seeded
draws) and integer states anywhere in the range, the fixed-point commands (`qformat.law_q`,
bit-exact with the firmware's fixed-point law, of the table over ``[x; d]``) are within the
written bound of the double law at that parameter vector; the bound is not vacuous; the state
range covers the oracle's mean +- 6 sd at every vertex."""
import numpy as np
import pytest

from conftest import EXAMPLES
from stospline import load_problem
from stospline.oracle.over_box import box_moments, box_state_range, vertices
from stospline.oracle.parametric import design_parametric, evaluate_at
from stospline.table.qformat import latch_q, law_q
from stospline.table.qparams import law_double_at, quantize_parametric

SEED, N = 20261128, 4000


@pytest.fixture(scope="module")
def robot():
    p = load_problem(EXAMPLES / "robot_goal.toml")
    pt = design_parametric(p).table
    return p, pt, box_state_range(box_moments(p, pt))


def test_the_state_range_covers_every_vertex(robot):
    p, pt, xr = robot
    for v in vertices(p.parameters):
        m = evaluate_at(p, pt, v, path=True)
        reach = np.abs(m.path_mean) + 6 * np.sqrt(np.maximum(m.path_var, 0))
        assert np.all(reach.max(axis=0) <= xr * (1 + 1e-9)), v


@pytest.mark.parametrize("arith", ["q15", "q31"])
def test_fixed_point_commands_are_within_the_bound_over_the_box(robot, arith):
    p, pt, xr = robot
    pf = quantize_parametric(pt, arith, xr)
    ft = pf.augmented
    F = ft.frac_bits
    qmax = (1 << F) - 1
    rng = np.random.default_rng(SEED)
    lo, hi = pf.lower, pf.upper
    theta = np.vstack([vertices(p.parameters), rng.uniform(lo, hi, size=(N, lo.size))])
    dq = pf.d_q(theta)
    assert np.abs(dq).max() <= qmax
    assert np.abs(pf.d_q(vertices(p.parameters))).max() > qmax // 2     # the range is used
    k = len(theta)
    n = pf.n
    tick = rng.integers(0, ft.n_ticks, size=k)
    xq = rng.integers(-(1 << F), 1 << F, size=(k, n))
    xlq = rng.integers(-(1 << F), 1 << F, size=(k, n))
    xlq[: len(vertices(p.parameters))] = np.where(rng.random((4, n)) < 0.5, -(1 << F), qmax)
    stage = ft.latch_stage(ft.stage_of_tick(tick))
    V = latch_q(ft, stage, np.hstack([xlq, dq]))
    assert np.abs(V).max() <= qmax
    uq = law_q(ft, tick, np.hstack([xq, dq]), V)
    assert np.abs(uq).max() <= qmax                   # no command leaves the Q range
    xlsb = ft.x_lsb[:n]
    exact = law_double_at(pt, tick, xq * xlsb, xlq * xlsb, theta)
    err = np.abs(uq * ft.u_lsb - exact)
    bound = pf.bound[tick]
    assert np.all(err <= bound * (1 + 1e-9)), float((err / bound).max())
    assert (err / bound).max() > 0.2                  # not vacuous
    # the columns' terms and d's rounding are in it: beyond the augmented table's own bound
    assert np.all(pf.bound_lsb > ft.bound_lsb)


def test_the_check_sees_a_parameter_not_applied(robot):
    """The same check with d_q = 0 (the columns not applied) fails at the box's vertices: the
    comparison resolves the parameters' effect, far above the bound."""
    p, pt, xr = robot
    pf = quantize_parametric(pt, "q15", xr)
    ft = pf.augmented
    theta = vertices(p.parameters)
    k, n = len(theta), pf.n
    tick = np.full(k, ft.n_ticks - 1)
    xq = np.zeros((k, n), np.int64)
    stage = ft.latch_stage(ft.stage_of_tick(tick))
    zero = np.zeros((k, theta.shape[1]), np.int64)
    V = latch_q(ft, stage, np.hstack([xq, zero]))
    uq = law_q(ft, tick, np.hstack([xq, zero]), V)
    err = np.abs(uq * ft.u_lsb - law_double_at(pt, tick, xq * 0.0, xq * 0.0, theta))
    assert np.all(err.max(axis=1) > 10 * pf.bound[tick].max(axis=1))


def test_an_unknown_arith_is_refused(robot):
    _, pt, xr = robot
    with pytest.raises(ValueError, match="arith"):
        quantize_parametric(pt, "q7", xr)
