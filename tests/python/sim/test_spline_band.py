"""Spline tables for band problems: the band dual re-solved for the spline's gains
(`stospline.table.spline.band`), which the compiled controller solves at the t0 latch
(Gaussian elimination for its non-symmetric W'). Checked with the exact oracle at the design's
x0 and at other start states (every band met to the float32 floor; the per-tick table's dual
under the same spline gains misses them by far more), the compiled C controller's latch
against the host's, and Monte Carlo through the compiled C against the oracle (fixed seed,
99 % jointly)."""
import json
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

import stospline
from stospline.oracle.band_latch import target_latch
from stospline.errors import DesignError
from stospline.harness.controller import STATUS, build_controller
from stospline.harness.montecarlo import compare_to_oracle, simulate
from stospline.oracle.evaluate import evaluate_table
from stospline.table.spline.band import is_p_matrix, solve_band_lcp

from conftest import EXAMPLES

EPS32 = 2.0 ** -24   # binary32 unit roundoff
SEED, PATHS, SUBSTEPS = 20261127, 3000, 2


@pytest.fixture(scope="module")
def bands():
    return stospline.load_problem(EXAMPLES / "robot_bands.toml")


@pytest.fixture(scope="module", params=[1e-5, 1e-2], ids=["tol1e-5", "tol1e-2"])
def designed(request, bands):
    """The spline table (at the default tolerance and a coarse one) and the per-tick one."""
    return (stospline.design_problem(bands, mode="joint", table="spline",
                                     spline_tolerance=request.param),
            stospline.design_problem(bands, mode="joint"))


def _start_states(problem, count=4):
    """The design's x0 and seeded others around it, each a float32 (what the controller
    measures), so that the oracle's plant starts where the latch was solved."""
    rng = np.random.default_rng(11)
    xs = [problem.x0] + [problem.x0 + rng.normal(scale=[0.6, 0.3, 0.6, 0.3])
                         for _ in range(count - 1)]
    return [np.asarray(x, dtype=np.float32).astype(float) for x in xs]


def _violations(problem, moments):
    """Per stacked constraint row: |y - value| of an equality, distance outside a band."""
    out = []
    for k, kn in enumerate(problem.knots):
        if kn.constraint is not None:
            lo, hi = kn.constraint.bounds
            y = np.asarray(moments.knot_constraint[k], dtype=float)
            out.append(np.where(lo == hi, np.abs(y - lo), np.maximum(np.maximum(y - hi, lo - y),
                                                                     0.0)))
    return np.concatenate(out)


def _floor(qp, x0):
    """The float32 floor of row i's expected output: the latched multipliers rounded to
    binary32 move it by at most (|W'| |lam|)_i 2^-24; the y values themselves (|y| up to 5
    here) are not rounded, the dual data is at 10 digits. Twice that, plus 1e-9 of scale."""
    lam = target_latch(qp, x0, float32=False)
    return 2 * EPS32 * (np.abs(qp.W) @ np.abs(lam)) + 1e-9 * (1 + np.abs(qp.hi))


def test_the_table_carries_a_non_symmetric_p_matrix_dual(designed):
    d, per_tick = designed
    qp, qp0 = d.table.band_qp, per_tick.table.band_qp
    assert qp is not None and qp.q == qp0.q == 6
    assert list(d.table.stage_n_latch) == [6, 0]
    assert not np.array_equal(qp.W, qp.W.T)              # the Gaussian-elimination path
    assert is_p_matrix(qp.W)[0]
    np.testing.assert_array_equal(qp.lo, qp0.lo)
    np.testing.assert_array_equal(qp.hi, qp0.hi)
    change = np.abs(qp.W - qp0.W).max() / np.abs(qp0.W).max()
    assert 0 < change < 1e-4                              # close to the design's, not equal
    assert d.certificate["band_dual"]["rows"] == 6
    assert d.certificate["band_dual"]["w_change"] == pytest.approx(change, rel=1e-6)


def test_bands_met_at_the_float32_floor_from_several_starts(designed):
    """Oracle of the law as implemented (spline gains, float32, the latch the firmware
    solves): every row at the float32 floor at x0 and at three other starts. The per-tick
    table's dual under the same gains misses by more at the coarse tolerance (the re-solve
    is what makes the compressed law exact)."""
    d, per_tick = designed
    t = d.table
    worst_old = 0.0
    for x0 in _start_states(d.problem):
        moved = replace(d.problem, x0=x0)
        viol = _violations(moved, evaluate_table(moved, t, path=False))
        floor = _floor(t.band_qp, x0)
        assert np.all(viol <= floor), (x0, viol, floor)
        old = evaluate_table(moved, replace(t, band_qp=per_tick.table.band_qp), path=False)
        worst_old = max(worst_old, float(np.max(_violations(moved, old) / floor)))
    if d.certificate["spline_tolerance"] >= 1e-2:
        assert worst_old > 5.0
    assert d.certificate["constraint_residual"] <= float(np.max(_floor(t.band_qp,
                                                                       d.problem.x0)))


def test_the_lcp_solution_is_the_unique_one(designed):
    """At each start the enumerated solution meets the conditions, and no other candidate
    active set does (a P-matrix: exactly one)."""
    d, _ = designed
    qp = d.table.band_qp
    band = np.flatnonzero(qp.lo != qp.hi)
    for x0 in _start_states(d.problem):
        e = qp.e(x0)
        lam, active = solve_band_lcp(e, qp.W, qp.lo, qp.hi)
        meets = 0
        for digits in np.array(np.meshgrid(*[[-1, 0, 1]] * band.size)).reshape(band.size, -1).T:
            act = np.where(qp.lo == qp.hi, 1, 0)
            act[band] = digits
            A = np.flatnonzero(act)
            lam_c = np.zeros(qp.q)
            b = np.where(act[A] > 0, qp.hi[A], qp.lo[A])
            lam_c[A] = np.linalg.solve(qp.W[np.ix_(A, A)], e[A] - b)
            y = e - qp.W @ lam_c
            free = act == 0
            ok = (np.all(lam_c[band][act[band] > 0] >= -1e-12)
                  and np.all(lam_c[band][act[band] < 0] <= 1e-12)
                  and np.all(y[free] <= qp.hi[free] + 1e-9)
                  and np.all(y[free] >= qp.lo[free] - 1e-9))
            if ok and not (np.all(np.abs(lam_c - lam) < 1e-9)):
                meets += 1
        assert meets == 0


def test_the_compiled_controller_latches_the_host_multipliers(designed):
    """The C controller's stage-0 latch (stsp_bandqp_solve, Gaussian elimination) gives the
    command of the host's multipliers, which the oracle above shows band-feasible."""
    d, _ = designed
    t = d.table
    ctl = build_controller(t)
    for x0 in _start_states(d.problem):
        x = x0.astype(np.float32)[None, :]
        u, status = ctl.stepper(1)(0, x)
        assert status[0] == STATUS["OK"]
        v = target_latch(t.band_qp, x0)
        ref = -(t.K[0].astype(float) @ x0 + t.k0[0] + t.L[0].astype(float) @ v)
        np.testing.assert_allclose(u[0], ref, rtol=1e-6, atol=1e-6 * np.abs(ref).max())


def test_monte_carlo_through_the_c_controller_agrees_with_the_oracle(bands):
    """From a moved start (an active set other than the design's): Monte Carlo through the
    compiled spline band controller agrees with the exact oracle of the law as implemented
    (cost, knot means and variances, 99 % jointly)."""
    d = stospline.design_problem(bands, mode="joint", table="spline", spline_tolerance=1e-2)
    x0 = _start_states(d.problem)[2]
    moved = replace(d.problem, x0=x0)
    mc = simulate(moved, build_controller(d.table), paths=PATHS, seed=SEED, substeps=SUBSTEPS)
    assert mc.worst_status == 0
    own = evaluate_table(moved, d.table, propagator="euler", substeps=SUBSTEPS, path=False)
    agree = compare_to_oracle(mc, own.J, own.knot_mean, knot_covs=own.knot_cov)
    assert agree.ok, agree.verdict


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "stospline.cli", *args], capture_output=True,
                          text=True)


def test_cli_writes_a_spline_band_table(tmp_path):
    r = _cli("design", str(EXAMPLES / "robot_bands.toml"), "--table", "spline", "--out",
             str(tmp_path), "--json")
    assert r.returncode == 0, r.stderr
    s = json.loads((tmp_path / "robot_bands_spline.json").read_text())
    assert s["band_qp_rows"] == 6 and s["table"]["band_dual"]["rows"] == 6
    assert "robot_bands_spline_band_W" in (tmp_path / "robot_bands_spline.c").read_text()


def test_cli_refuses_a_fixed_point_band_table_without_its_dual(tmp_path):
    """More than 8 rows (the firmware's solver bound): the table latches the state, whose
    constraints only the float32 spline restores (tests/python/sim/test_spline_restore.py);
    in Q15 exit 2 naming design.table, nothing written."""
    r = _cli("design", str(EXAMPLES / "robot_narrow_corridor.toml"), "--table", "spline",
             "--arith", "q15", "--out", str(tmp_path))
    assert r.returncode == 2
    assert "design.table" in r.stderr and "band dual" in r.stderr, r.stderr
    assert list(tmp_path.iterdir()) == []


def test_p_matrix_check_and_no_solution():
    """is_p_matrix: every principal minor positive; solve_band_lcp refuses (design.table)
    when no candidate meets the conditions (a zero row: the row's output cannot move)."""
    assert is_p_matrix(np.array([[1.0, 2.0], [0.0, 1.0]]))[0]      # triangular, diagonal > 0
    assert not is_p_matrix(np.array([[1.0, 2.0], [1.0, 1.0]]))[0]  # det -1
    assert not is_p_matrix(np.array([[0.0, 1.0], [-1.0, 1.0]]))[0]  # a zero diagonal entry
    with pytest.raises(DesignError, match="design.table"):
        solve_band_lcp(np.array([5.0, 0.0]), np.array([[0.0, 0.0], [0.0, 1.0]]),
                       np.array([-1.0, -1.0]), np.array([1.0, 1.0]))


def test_the_fallback_latch_is_exact_at_the_design_start(designed):
    """Stage 0's Lambda, lambda0 (what the firmware latches when its solve fails) are the
    affine latch of the design x0's active set under W': at x0 the law without its band dual
    meets every row at the float32 floor too (latch maps rounded to float32 as well)."""
    d, _ = designed
    t = d.table
    x0 = np.asarray(d.problem.x0, dtype=np.float32).astype(float)
    moved = replace(d.problem, x0=x0)
    viol = _violations(moved, evaluate_table(moved, replace(t, band_qp=None), path=False))
    # v = Lambda x0 + lambda0 from float32-rounded maps: off by up to 2^-24 of each term
    dv = EPS32 * (np.abs(t.Lambda[0].astype(float)) @ np.abs(x0) + np.abs(t.lambda0[0]))
    bound = _floor(t.band_qp, x0) + 2 * np.abs(t.band_qp.W) @ dv[:t.band_qp.q]
    assert np.all(viol <= bound), (viol, bound)
