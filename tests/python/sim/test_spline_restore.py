"""Spline tables of designs that latch the state (`stospline.table.spline.restore`):
robot_monotone (a region at every tick, the tick-grid QP) and robot_narrow_corridor (122 band
rows, beyond a band dual). The feed-forward's k0 coefficients are corrected so that, for the
design's x0, every constraint row holds for the law as the firmware evaluates it. Checked with
the exact oracle (every knot row and every region row at every tick it constrains, within the
float32 floor of `float32_floor`; cost within 1e-6 of the per-tick law), against the plain fit
(which misses rows at a coarse tolerance), the compiled C controller bit for bit against the
host's evaluation, and Monte Carlo through the compiled C against the oracle (fixed seed,
99 % jointly)."""
from dataclasses import replace

import numpy as np
import pytest

import stospline
from stospline.harness.controller import build_controller
from stospline.oracle.evaluate import evaluate_table
from stospline.table.flash import flash_bytes
from stospline.table.format import table_of
from stospline.table.spline.fit import command
from stospline.table.spline import restore as sr

from conftest import EXAMPLES
from test_spline_monte_carlo import assert_agrees_and_rejects_frozen

SEED, PATHS, SUBSTEPS = 20261128, 4000, 2
EXAMPLES_LATCHING = ("robot_monotone", "robot_narrow_corridor")


@pytest.fixture(scope="module", params=EXAMPLES_LATCHING)
def designed(request):
    """The spline table at the file's tolerance and the per-tick one."""
    p = stospline.load_problem(EXAMPLES / f"{request.param}.toml")
    return (stospline.design_problem(p, mode="joint", table="spline"),
            stospline.design_problem(p, mode="joint"))


@pytest.fixture(scope="module")
def monotone():
    p = stospline.load_problem(EXAMPLES / "robot_monotone.toml")
    return stospline.design_problem(p, mode="joint")


def _row_violations(problem, table, x0=None):
    """Every constraint row's distance outside its bound (oracle, mean path) and its float32
    floor, from x0 (default the problem's)."""
    if x0 is not None:
        problem = replace(problem, x0=np.asarray(x0, dtype=float))
    rows = sr.constraint_rows(problem, table)
    path = evaluate_table(problem, table, path=True).path_mean
    y = np.einsum("rn,rn->r", rows.C, path[rows.tick])
    return rows.violation(y), sr.float32_floor(problem, table, rows, problem.x0), rows


def test_the_table_latches_the_state_and_is_a_spline(designed):
    d, per_tick = designed
    t = d.table
    assert t.spline is not None and sr.is_state_latching(t) and sr.is_state_latching(
        per_tick.table)
    np.testing.assert_array_equal(t.Lambda, per_tick.table.Lambda)
    np.testing.assert_array_equal(t.lambda0, per_tick.table.lambda0)
    rows = sr.constraint_rows(d.problem, t)
    assert d.certificate["restored"]["rows"] == rows.tick.size
    # monotone: 5 knot rows + 2 x 600 region rows; narrow corridor: 60 knots' rows
    assert rows.tick.size == {"robot_monotone": 1205, "robot_narrow_corridor": 122}[
        d.problem.name]
    assert d.certificate["restored"]["active"] >= 5


def test_certificate_every_row_at_the_float32_floor(designed):
    """The oracle at x0: every row inside its bound up to the float32 floor (as the per-tick
    table's); the summary's residual is the worst over all rows; the cost within 1e-6 of
    the per-tick law in double precision and of J0."""
    d, per_tick = designed
    viol, floor, rows = _row_violations(d.problem, d.table)
    assert np.all(viol <= floor), (viol.max(), rows.what[int(np.argmax(viol / floor))])
    assert d.certificate["constraint_residual"] == pytest.approx(viol.max(), rel=1e-6,
                                                                 abs=1e-15)
    per_viol, per_floor, _ = _row_violations(per_tick.problem, per_tick.table)
    assert np.all(per_viol <= per_floor)
    assert abs(d.certificate["excess_over_law"]) < 1e-6
    assert abs(d.certificate["excess_over_J0"]) < 1e-6
    assert d.certificate["knot_cov_change"] < 1e-6
    assert d.certificate["flash_bytes"] == flash_bytes(d.table)
    assert d.certificate["compression_ratio"] == flash_bytes(per_tick.table) / flash_bytes(
        d.table)


def test_the_restoration_is_what_meets_the_rows(monotone):
    """At a coarse tolerance (1e-2) the plain fit misses a row by several times its float32
    floor; the restored table meets every row within it, at a cost within 2e-6 of the law."""
    d = monotone
    p, exact = d.problem, table_of(d.design, quantize=False)
    out = {}
    for correct in (False, True):
        spline, K, k0, L, info = sr.restore(p, exact, d.table, 1e-2, correct=correct)
        t = replace(d.table.with_arrays(K=K, k0=k0, L=L), spline=spline)
        viol, floor, _ = _row_violations(p, t)
        out[correct] = (float(np.max(viol / floor)), evaluate_table(p, t, path=False).J, info)
    assert out[False][0] > 3.0, out
    assert out[True][0] <= 1.0, out
    assert out[True][2]["active"] >= 95 and out[True][2]["rounds"] >= 1
    assert abs(out[True][1] - d.law.J) / d.law.J < 2e-6


def test_the_c_controller_is_the_host_evaluation_bit_for_bit(designed):
    """Every tick of the plan, random states around the planned mean, the t0 latch of the
    state itself: the compiled controller's command equals `spline.command` bit for bit."""
    d, _ = designed
    t = d.table
    step = build_controller(t, fixed_shape=False).stepper(1)
    rng = np.random.default_rng(5)
    mean = evaluate_table(d.problem, t, path=True).path_mean
    n = t.dims[0]
    mismatches = 0
    for tick in range(t.n_ticks):
        x = (mean[tick] + rng.normal(scale=0.1, size=n)).astype(np.float32)
        if tick == 0:
            v = np.zeros(t.dims[2], dtype=np.float32)
            for c in range(int(t.stage_n_latch[0])):
                acc = np.float32(t.lambda0[0, c])
                for j in range(n):
                    acc = np.float32(acc + np.float32(t.Lambda[0, c, j] * x[j]))
                v[c] = acc
        u, status = step(tick, x[None, :])
        assert status[0] == 0
        mismatches += int(not np.array_equal(
            u[0].view(np.uint32), command(t.spline, t.stage_start, tick, x, v).view(np.uint32)))
    assert mismatches == 0


def test_monte_carlo_through_the_c_controller_agrees_with_the_oracle(monotone):
    """robot_monotone's restored spline at tolerance 1e-2 (22 and 46 spans): Monte Carlo
    through the compiled controller agrees with the oracle of the law as implemented (cost,
    knot means and covariances, 99 % jointly) and rejects the frozen-span controller's."""
    d = monotone
    p = d.problem
    spline, K, k0, L, _ = sr.restore(p, table_of(d.design, quantize=False), d.table, 1e-2)
    table = replace(d.table.with_arrays(K=K, k0=k0, L=L), spline=spline)
    assert_agrees_and_rejects_frozen(p, table, paths=PATHS, seed=SEED, substeps=SUBSTEPS)


def test_a_region_enforced_between_ticks_is_refused(monotone):
    """What is not restored (the mean between ticks) is refused naming design.table."""
    p = monotone.problem
    moved = replace(p, tick_regions=tuple(replace(r, between=True) for r in p.tick_regions))
    with pytest.raises(stospline.DesignError, match="design.table"):
        sr.restore(moved, table_of(monotone.design, quantize=False), monotone.table, 1e-5)


def test_the_robot_in_joint_mode_latches_the_state_and_is_restored(robot_problem):
    """5 equality rows against 4 states: the joint robot's table latches the state (refused
    before); its spline meets every row within the float32 floor at x0, at 1e-6 of the law."""
    d = stospline.design_problem(robot_problem, mode="joint", table="spline")
    assert sr.is_state_latching(d.table) and d.certificate["restored"]["active"] == 5
    viol, floor, _ = _row_violations(d.problem, d.table)
    assert np.all(viol <= floor), (viol, floor)
    assert abs(d.certificate["excess_over_law"]) < 1e-6
