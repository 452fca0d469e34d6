"""Guarantees over the box for the Q15/Q31 parametric table as flashed (robot_goal): the
fixed-point error bound propagated to the mean (`oracle.fixed_point_margin`).

* The propagation is exact, not only an upper bound: the error sequence it names
  (`MeanErrorBound.attaining`) moves the oracle's mean by the whole bound (a wrong response,
  latch or feedback would not match).
* It bounds what the table as flashed does: the oracle of its stored integers, at the
  deviation the device rounds, at every vertex of the box and at seeded draws, is within it of
  the double table's mean, at every tick, in every state and along every corridor wall.
* The corridor's certificate over the box (`fixed_point_certificate`) takes it off each
  wall's margin: its per-tick Cantelli bound is the double table's with the smaller margin."""
from dataclasses import replace

import numpy as np
import pytest

from conftest import EXAMPLES
from stospline import load_problem
from stospline.oracle.evaluate import evaluate_table
from stospline.oracle.exit_bound import exit_bounds_over_box
from stospline.oracle.fixed_point_margin import fixed_point_certificate, mean_error_bound
from stospline.oracle.over_box import box_moments, box_state_range, vertices
from stospline.oracle.parametric import design_parametric, evaluate_at
from stospline.table.qparams import quantize_parametric

SEED = 20261202


@pytest.fixture(scope="module")
def robot():
    p = load_problem(EXAMPLES / "robot_goal.toml")
    pt = design_parametric(p).table
    box = box_moments(p, pt)
    walls = p.corridors[0].A @ p.corridors[0].C
    return p, pt, box, box_state_range(box), walls


def test_the_bound_is_attained(robot):
    p, pt, _, xr, walls = robot
    pf = quantize_parametric(pt, "q15", xr)
    meb = mean_error_bound(p, pt.table, pf.command_error_bound(pt))
    law = pt.at(pt.nominal)
    mean = evaluate_table(p, law, path=True).path_mean
    for row, j in ((walls[0], 150), (walls[1], 450), (np.eye(p.n)[2], 600)):
        e = meb.attaining(row, j)
        assert np.all(np.abs(e) <= pf.command_error_bound(pt)) and not e[j:].any()
        moved = evaluate_table(p, replace(law, k0=law.k0 - e), path=True).path_mean[j]
        np.testing.assert_allclose(row @ (moved - mean[j]), meb.rows(row)[j, 0], rtol=1e-9)


@pytest.mark.parametrize("arith", ["q15", "q31"])
def test_the_flashed_tables_mean_is_within_the_bound(robot, arith):
    p, pt, _, xr, walls = robot
    pf = quantize_parametric(pt, arith, xr)
    flashed = pf.as_flashed(pt)
    rows = np.vstack([np.eye(p.n), walls])
    shift = mean_error_bound(p, pt.table, pf.command_error_bound(pt)).rows(rows)
    rng = np.random.default_rng(SEED)
    thetas = np.vstack([vertices(p.parameters), rng.uniform(pf.lower, pf.upper, (2, 2))])
    worst = 0.0
    for theta in thetas:
        exact = evaluate_at(p, pt, theta, path=True).path_mean @ rows.T
        own = evaluate_at(p, flashed, theta, quantize=True, path=True).path_mean @ rows.T
        assert np.all(np.abs(own - exact) <= shift + 1e-12), theta
        worst = max(worst, float((np.abs(own - exact)[1:] / shift[1:]).max()))
    assert worst > 0.01          # the bound is not vacuous: within 100x of the flashed table's


@pytest.mark.parametrize("arith", ["q15", "q31"])
def test_corridor_certificate_of_the_flashed_table(robot, arith):
    p, pt, box, xr, walls = robot
    pf = quantize_parametric(pt, arith, xr)
    cert = fixed_point_certificate(p, pt, pf, box)
    q = cert["corridors"][0]["cantelli"]
    double = exit_bounds_over_box(p.corridors[0], box, p.t0, p.tick_hz)["cantelli"]
    shift = cert["bound"].rows(walls)
    assert shift.max() > 0 and q.worst_tick >= double.worst_tick
    # the margin taken off is the bound's: Q31's is below 1e-6 m, Q15's is not
    gap = q.worst_tick - double.worst_tick
    assert (gap < 1e-5) if arith == "q31" else (gap > 1e-3), gap
    twice = exit_bounds_over_box(p.corridors[0], box, p.t0, p.tick_hz,
                                 extra=lambda c: 2 * cert["bound"].rows(c))["cantelli"]
    assert twice.worst_tick > q.worst_tick
