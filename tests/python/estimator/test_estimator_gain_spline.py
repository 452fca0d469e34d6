"""The filter's update gains as a spline (`estimator.gain_spline`, ``stsp_est_init_spline``):
the fit meets its tolerance and its evaluation is the firmware's, bit for bit through the
compiled C; a Monte Carlo through that C agrees with the oracle of the gains as flashed; the
design writes the spline filter for ``table = "spline"`` with its certificate."""
import copy
import importlib.util
import json

import numpy as np
import pytest

from conftest import REPO
from stospline.errors import DesignError
from stospline.estimator.ctable import (estimator_c, estimator_crc32, estimator_table, flushed,
                                        gain_spline_crc32)
from stospline.estimator.gain_spline import (evaluate_gain_spline, fit_gain_spline,
                                             sample_starts)
from stospline.estimator.oracle import evaluate_estimator
from stospline.estimator.spec import EstimatorSpec
from stospline.harness.estimator_loop import build_estimator_controller, simulate_estimator
from stospline.harness.montecarlo import compare_to_oracle
from stospline.pipeline import design_files, design_problem
from stospline.problem.reader import parse_problem

from test_estimator_oracle import DOC

TOL = 1e-5


def _within_tolerance(F, exact, stage_start, every, tol):
    """Every entry of F within tol of its stage's peak |exact| (what the fit promises)."""
    q0 = sample_starts(stage_start, every)
    for a, b in zip(q0[:-1], q0[1:]):
        if b == a:
            continue
        peak = np.abs(exact[a:b]).max(axis=0)
        err = np.abs(F[a:b].astype(float) - exact[a:b]).max(axis=0)
        assert np.all(err <= tol * peak + (peak == 0) * 0.0), (err / np.where(peak, peak, 1))
        assert np.all(F[a:b][:, peak == 0] == 0)


def test_fit_meets_the_tolerance_and_evaluates_as_stored():
    """Smooth gains with a jump between stages, a stage without samples (ticks 3..3 at every
    4), a zero entry: every entry within the tolerance of its stage's peak, the zero entry
    not stored, the stored arrays evaluating to the fit's values bit for bit."""
    stage_start, every = np.array([0, 3, 4, 161]), 4
    q = np.arange(41, dtype=float)
    F = np.zeros((41, 2, 2))
    F[:, 0, 0] = 0.5 / (1 + q)                          # the filter's 1/k start
    F[:, 1, 0] = np.where(q >= 1, 2 + np.sin(q / 7), 1.0)
    F[:, 0, 1] = np.cos(q / 5)
    spline, values = fit_gain_spline(F, stage_start, every, TOL)
    assert spline.spans()[1] == 0 and spline.knot_start[1] == spline.knot_start[2]
    assert 1 * 2 + 1 not in spline.entry.tolist()       # F[1][1] is zero: not stored
    _within_tolerance(values, F, stage_start, every, TOL)
    again = evaluate_gain_spline(spline, stage_start, every)
    assert np.array_equal(again.view(np.uint32), values.view(np.uint32))


@pytest.fixture(scope="module")
def sensed(tmp_path_factory):
    problem = parse_problem(copy.deepcopy(DOC))
    d = design_problem(problem)
    loop = evaluate_estimator(problem, d.table)
    et = estimator_table(problem, d.table, loop, spline_tolerance=TOL)
    ctl = build_estimator_controller(problem, d.table, et,
                                     build_dir=tmp_path_factory.mktemp("gain_spline_build"))
    return problem, d, loop, et, ctl


def test_tables_crc_and_c_text(sensed):
    problem, d, loop, et, _ = sensed
    every = problem.measurement.every
    _within_tolerance(et.gain, flushed(loop.gain[::every]), d.table.stage_start, every, TOL)
    h, c = estimator_c(et, "sensed")
    assert "sensed_est_gain_spline" in h and "_est_gain[" not in c
    assert f"0x{estimator_crc32(et):08X}u, 0x{gain_spline_crc32(et):08X}u" in c
    assert estimator_crc32(et) != estimator_crc32(estimator_table(problem, d.table, loop))


def test_c_evaluates_the_spline_gains_bit_for_bit(sensed):
    """The compiled C with the spline against the float32 specification run on the gains the
    host evaluates: every command and prediction, a missing reading, a skip."""
    problem, d, _, et, ctl = sensed
    paths, rng = 4, np.random.default_rng(20261129)
    step, spec = ctl.stepper(paths), EstimatorSpec(d.table, et, paths)
    for j in range(d.table.n_ticks):
        if j in (9, 10):
            continue                                   # skipped: predicted with u held
        Y = None
        if j % et.every == 0 and j != 4:
            Y = (spec.xhat[:, :1] + 0.3 * rng.standard_normal((paths, 1))).astype(np.float32)
        U, status = step(j, Y)
        assert np.array_equal(U, spec.step(j, Y)), j
        assert np.array_equal(step.xhat(), spec.xhat), j
        assert np.all(status >= 0), (j, status)


def test_monte_carlo_through_c_agrees_with_the_oracle_of_the_spline_gains(sensed):
    """The loop's cost, knot means and covariances from 20 000 paths through the compiled C
    with the spline gains, within a Bonferroni-corrected 99.9 % band of the oracle of those
    gains as flashed (fixed seed); that oracle within 1e-4 of the per-tick gains'."""
    problem, d, _, et, ctl = sensed
    gains, pred = et.per_tick()
    flashed = evaluate_estimator(problem, d.table, gains=gains, predictor=pred,
                                 propagator="euler", substeps=4)
    per_tick = estimator_table(problem, d.table)
    ref = evaluate_estimator(problem, d.table, gains=per_tick.per_tick()[0],
                             predictor=per_tick.per_tick()[1], propagator="euler", substeps=4)
    assert flashed.moments.J == pytest.approx(ref.moments.J, rel=1e-4)
    mc, _ = simulate_estimator(problem, ctl, paths=20_000, seed=20261129, substeps=4)
    assert mc.worst_status == 0
    a = compare_to_oracle(mc, flashed.moments.J, flashed.moments.knot_mean, confidence=0.999,
                          knot_covs=flashed.moments.knot_cov)
    assert a.ok, (a.verdict, mc.cost_mean_ci(), flashed.moments.J)


def test_design_with_a_spline_table_writes_the_spline_filter_and_its_certificate():
    """``table = "spline"`` on a [measurement] problem: the C holds the gain spline (and no
    per-tick gains), the summary's estimator.gain_spline the oracle of both filters as
    flashed; a tolerance the fit cannot meet is a DesignError naming the field."""
    problem = parse_problem(copy.deepcopy(DOC))
    d = design_problem(problem, table="spline", spline_tolerance=TOL)
    files, summary = design_files(d, "sensed.toml")
    assert "const stsp_est_gain_spline_t sensed_spline_est_gain_spline" in files[
        "sensed_spline.c"]
    cert = json.loads(files["sensed_spline.json"])["estimator"]["gain_spline"]
    samples = -(-d.table.n_ticks // problem.measurement.every)
    assert cert["per_tick_gain_bytes"] == 4 * samples * 2 * 1 and cert["gain_bytes"] > 0
    assert abs(cert["J_change"]) < 1e-4 and cert["knot_cov_change"] < 1e-3
    assert cert["oracle_J"] == pytest.approx(cert["per_tick_oracle_J"], rel=1e-4)
    with pytest.raises(DesignError) as err:
        fit_gain_spline(np.ones((20, 2, 1)), [0, 40], 2, 1e-12)
    assert err.value.field == "design.spline_tolerance"


def test_the_c_tests_expected_gains_are_the_shipped_splines():
    """tests/c/estimator_spline_expected.h (what test_estimator_spline.c checks the C
    against) is the host's evaluation of the shipped gain spline: regenerate with
    tests/c/estimator_spline_reference.py."""
    path = REPO / "tests" / "c" / "estimator_spline_reference.py"
    spec = importlib.util.spec_from_file_location("estimator_spline_reference", path)
    ref = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(ref)
    assert ref.expected() == (REPO / "tests" / "c" / "estimator_spline_expected.h").read_text()


def test_no_shipped_gain_spline_input_is_near_a_rounding_boundary(monkeypatch):
    """gains/robot_position_sensor_spline.* regenerates byte for byte on other BLAS kernels
    (test_gains_regenerate_elsewhere.py) because nothing the gain spline rounds is within
    reach of such last-bit changes (REL there): no gain within reach of the flush of round-off
    zeros, and every coefficient of every fit (the refinement's discarded ones too) clear of
    the midpoints of its entry's float32 grid (`spline._coefficients`)."""
    from stospline import load_problem
    from stospline.table.spline import fit as spline
    from conftest import EXAMPLES
    path = REPO / "tests" / "python" / "table" / "test_gains_regenerate_elsewhere.py"
    spec = importlib.util.spec_from_file_location("regenerate_elsewhere", path)
    elsewhere = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(elsewhere)
    REL, _reach = elsewhere.REL, elsewhere._reach
    seen = []

    def capture(C, peak):
        seen.append((np.array(C, dtype=float), np.array(peak, dtype=float)))
        return coefficients(C, peak)
    coefficients = spline._coefficients
    monkeypatch.setattr(spline, "_coefficients", capture)
    problem = load_problem(EXAMPLES / "robot_position_sensor.toml")
    d = design_problem(problem)
    loop = evaluate_estimator(problem, d.table)
    gains = loop.gain[::problem.measurement.every]
    flush = 1e-9 * np.abs(gains).max()
    assert int(np.sum(np.abs(np.abs(gains) - flush) <= _reach(gains))) == 0
    estimator_table(problem, d.table, loop, spline_tolerance=TOL)
    assert seen
    for a, peak in seen:
        q = np.ldexp(1.0, np.frexp(peak)[1] - 24)[:, None]
        distance = np.abs(a / q - np.floor(a / q) - 0.5) * q
        assert int(np.sum(distance <= _reach(a))) == 0, REL
