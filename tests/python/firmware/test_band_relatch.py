"""Band tables carry their dual QP, and the compiled controller re-solves it from the measured
x0 at the t0 latch (firmware/src/stsp_controller.c -> stsp_bandqp.c): a trajectory started
from another state than the design's still meets its bands, at the optimal cost for that
state. Checked with the exact oracle and Monte Carlo through the compiled C controller."""
import json
import tomllib
from dataclasses import replace

import numpy as np
import pytest

from stospline.design.bands import design_bands
from stospline.oracle.band_latch import target_latch
from stospline.harness.controller import STATUS, build_controller
from stospline.harness.montecarlo import compare_to_oracle, simulate
from stospline.oracle.evaluate import evaluate_table
from stospline.problem import load_problem, parse_problem
from stospline.table.format import BandQP, GainTable, table_crc32, table_of

from conftest import EXAMPLES


def test_crc_of_band_table_matches_the_firmware():
    """Table D of tests/c/test_controller.c: both CRC implementations cover the band data."""
    qp = BandQP(np.eye(2), np.zeros(2), np.array([[2, .5], [.5, 1]]), np.array([.5, -1.]),
                np.array([.5, 1.]))
    t = GainTable("d", 1, 0.0, np.array([0, 2, 4], np.uint32), np.array([2, 0], np.uint16),
                  np.full((4, 1, 2), 0.25, np.float32), np.zeros((4, 1), np.float32),
                  np.tile(np.array([[[1, 10]]], np.float32), (4, 1, 1)),
                  np.array([[[1, 0], [0, 1]], [[0, 0], [0, 0]]], np.float32),
                  np.array([[0.125, -0.25], [0, 0]], np.float32), "", band_qp=qp)
    assert table_crc32(t) == 0x7395DA83
    assert table_crc32(replace(t, band_qp=None)) != table_crc32(t)


def robot_with_loose_band(tick_hz=20):
    """The robot with E{x + y} in [-0.2, 0.2] and E{y} in [0, 1.6] at t = 3: at the design's
    x0 both bands are inactive (the affine latch map then holds no band multiplier at all)."""
    doc = tomllib.loads((EXAMPLES / "robot_corridor.toml").read_text())
    doc["tick_hz"] = tick_hz
    doc["knots"][0]["constraint"] = {"C": [[1, 0, 1, 0], [0, 0, 1, 0]],
                                     "lower": [-0.2, 0.0], "upper": [0.2, 1.6]}
    return parse_problem(doc)


@pytest.fixture(scope="module")
def robot():
    """The robot with bands at t = 3 (6 dual rows: two bands, four equalities) at 20 Hz, and
    a start state (seeded search) from which the design's affine latch map, the multipliers of
    the design's active set, would miss a band by more than 0.05."""
    problem = robot_with_loose_band()
    b = design_bands(problem)
    assert [a["at"] for a in b.active_set()][:2] == ["inactive", "inactive"]
    qp, st0 = BandQP(*b.band_dual()), b.base.stages[0]
    rng = np.random.default_rng(5)
    for _ in range(500):
        x0 = (problem.x0 + rng.normal(scale=[0.6, 0.3, 0.6, 0.3])).astype(np.float32)
        x = x0.astype(float)
        y_affine = qp.e(x) - qp.W @ (st0.Lambda @ x + st0.lambda0)
        if np.max(np.maximum(qp.lo - y_affine, y_affine - qp.hi)) > 0.05:
            return problem, b, x
    raise AssertionError("no start state makes the affine map miss a band")


def _band_violation(problem, moments):
    worst = 0.0
    for k, kn in enumerate(problem.knots):
        if kn.constraint is not None:
            lo, hi = kn.constraint.bounds
            y = moments.knot_constraint[k]
            worst = max(worst, float(np.max(np.maximum(lo - y, y - hi))))
    return worst


def test_table_carries_the_dual_unfolded(robot):
    problem, b, _ = robot
    t = table_of(b)
    assert t.band_qp is not None and t.band_qp.q == 6
    assert t.dims[2] == 6 and list(t.stage_n_latch) == [6, 0]   # one latch, not folded into x
    assert table_of(b, on_target_qp=False).dims[2] == 4          # affine map: folded to n


def test_relatched_multipliers_meet_bands_at_optimal_cost(robot):
    problem, b, x0 = robot
    moved = replace(problem, x0=x0)
    affine = evaluate_table(moved, table_of(b, on_target_qp=False), path=False)
    resolved = evaluate_table(moved, table_of(b), path=False)
    # The design's affine latch map is wrong for this x0: a band is missed...
    assert _band_violation(moved, affine) > 1e-2
    # ...the on-target re-solve meets every band (float32 tables: 1e-5) at the cost of the
    # design made for this x0 from scratch.
    assert _band_violation(moved, resolved) < 1e-5
    assert resolved.J == pytest.approx(design_bands(moved).J0, rel=1e-6)
    exact = evaluate_table(moved, table_of(b, quantize=False), path=False)
    assert _band_violation(moved, exact) < 1e-9
    assert exact.J == pytest.approx(design_bands(moved).J0, rel=1e-9)


def test_compiled_controller_latches_the_host_multipliers(robot):
    problem, b, x0 = robot
    table = table_of(b)
    ctl = build_controller(table)
    step = ctl.stepper(1)
    x = x0.astype(np.float32)[None, :]
    u, status = step(0, x)
    assert status[0] == STATUS["OK"]
    v = np.zeros(table.dims[2])
    v[:6] = target_latch(table.band_qp, x0)
    ref = -(table.K[0].astype(float) @ x[0] + table.k0[0] + table.L[0].astype(float) @ v)
    np.testing.assert_allclose(u[0], ref, rtol=1e-6, atol=1e-6 * np.abs(ref).max())
    # Without the re-solve the command differs (the affine map's multipliers are wrong here).
    u_aff, _ = build_controller(table_of(b, on_target_qp=False)).stepper(1)(0, x)
    assert np.abs(u_aff[0] - u[0]).max() > 1e-3


def test_monte_carlo_from_moved_start_meets_bands(robot):
    problem, b, x0 = robot
    moved = replace(problem, x0=x0)
    table = table_of(b)
    oracle = evaluate_table(moved, table, path=False)
    mc = simulate(moved, build_controller(table), paths=3000, seed=31, substeps=50)
    agree = compare_to_oracle(mc, oracle.J, oracle.knot_mean)
    assert agree.ok, (agree.cost_z, agree.knot_mean_z)


def _cli(*args):
    import subprocess
    import sys
    return subprocess.run([sys.executable, "-m", "stospline.cli", *args], capture_output=True,
                          text=True)


def test_cli_simulates_from_a_measured_start():
    """`stospline simulate --x0`: same tables, the plant and the t0 latch from another state;
    the prediction is the optimum for that state, and the float32 table's oracle matches it."""
    bands = str(EXAMPLES / "robot_bands.toml")
    r = _cli("simulate", bands, "--x0=-5.4,0.1,2.0,0.4", "--paths", "400", "--seed", "2",
             "--json")
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    assert s["x0"] == [-5.4, 0.1, 2.0, 0.4] and s["worst_status"] == 0
    moved = replace(load_problem(bands), x0=np.array(s["x0"]))
    assert s["cost"]["predicted_J0"] == pytest.approx(design_bands(moved).J0, rel=1e-9)
    assert s["cost"]["oracle_implemented"] == pytest.approx(s["cost"]["predicted_J0"],
                                                            rel=1e-6)
    # A stage-wise design from another start: the latched law is optimal from any state.
    r = _cli("simulate", str(EXAMPLES / "robot_corridor.toml"), "--x0=-4.5,0.2,1.5,0",
             "--paths", "50", "--json")
    assert r.returncode == 0, r.stderr
    c = json.loads(r.stdout)["cost"]
    assert c["oracle_implemented"] == pytest.approx(c["predicted_J0"], rel=1e-6)


@pytest.mark.parametrize("x0, reason", [("1,2,3", "4 finite numbers"),
                                        ("1,2,nan,4", "4 finite numbers"),
                                        ("1,2,x,4", "comma-separated numbers")])
def test_cli_rejects_a_bad_start(x0, reason, tmp_path):
    r = _cli("simulate", str(EXAMPLES / "robot_bands.toml"), f"--x0={x0}", "--paths", "10")
    assert r.returncode == 2 and "x0" in r.stderr and reason in r.stderr, r.stderr
