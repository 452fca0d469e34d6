"""The firmware's estimator controller (stsp_est_step) through the host-compiled C: its tables'
CRC and C text, bit for bit against the float32 specification (`estimator.spec`), and a Monte
Carlo of the sensor loop through the C against the exact moments of the implemented tables."""
import copy

import numpy as np
import pytest

from conftest import EXAMPLES, GAINS
from stospline.estimator.ctable import estimator_c, estimator_crc32, estimator_table
from stospline.estimator.oracle import evaluate_estimator
from stospline.estimator.spec import EstimatorSpec
from stospline.estimator.tails import evaluate_estimator_tails
from stospline.harness.estimator_loop import build_estimator_controller, simulate_estimator
from stospline.harness.montecarlo import compare_to_oracle
from stospline.pipeline import design_problem
from stospline.problem.reader import parse_problem
from stospline import load_problem

from test_estimator_oracle import DOC


@pytest.fixture(scope="module")
def robot_sensor(tmp_path_factory):
    problem = load_problem(EXAMPLES / "robot_position_sensor.toml")
    d = design_problem(problem)
    et = estimator_table(problem, d.table)
    ctl = build_estimator_controller(problem, d.table, et,
                                     build_dir=tmp_path_factory.mktemp("est_build"))
    return problem, d, et, ctl


def test_crc_and_the_shipped_text(robot_sensor):
    problem, d, et, ctl = robot_sensor
    c_table = ctl.lib.harness_est_table()
    assert ctl.lib.stsp_est_table_crc32(c_table) == estimator_crc32(et) == c_table.crc32
    header, source = estimator_c(et, "robot_position_sensor")
    assert source in (GAINS / "robot_position_sensor.c").read_text()
    assert header.strip() in (GAINS / "robot_position_sensor.h").read_text()
    # one predictor map per (time-invariant) stage, one gain per sample
    assert len(et.model) == 2 and len(et.gain) == -(-d.table.n_ticks // et.every)


def test_the_flashed_filter_keeps_the_knot_means_to_float32_precision(robot_sensor):
    """The rounded predictor map biases the estimate by its rounding error: the knot means of
    the loop with the flashed tables stay within float32's relative precision of the state's
    size of the designed filter's (which are the full-state loop's)."""
    problem, d, et, ctl = robot_sensor
    designed = evaluate_estimator(problem, d.table)
    gains, pred = et.per_tick()
    flashed = evaluate_estimator(problem, d.table, gains=gains, predictor=pred)
    scale = 4 * np.finfo(np.float32).eps * np.abs(problem.x0).max()
    for k in range(len(problem.knots)):
        gap = np.abs(flashed.moments.knot_mean[k] - designed.moments.knot_mean[k]).max()
        assert 0 < gap < scale, (k, gap, scale)


def test_c_equals_the_float32_specification_bit_for_bit(robot_sensor):
    """Every command and every prediction over the whole plan, with noisy readings, one missing
    reading (y NULL) and the latch of stage 1, for several paths."""
    problem, d, et, ctl = robot_sensor
    paths, rng = 6, np.random.default_rng(20261128)
    step, spec = ctl.stepper(paths), EstimatorSpec(d.table, et, paths)
    X = np.tile(problem.x0, (paths, 1))
    for j in range(d.table.n_ticks):
        Y = None
        if j % et.every == 0 and j != 1000:
            Y = (X @ problem.measurement.C.T + 0.02 * rng.standard_normal((paths, 2)))
            Y = Y.astype(np.float32)
        U, status = step(j, Y)
        want = spec.step(j, Y)
        assert np.array_equal(U, want), j            # == : a zero's sign may differ
        assert np.array_equal(step.xhat(), spec.xhat), j
        expect = 6 if (j == 1000) else 0              # STSP_WARN_NO_MEASUREMENT
        assert np.all(status == expect), (j, status)
        X = spec.xhat + 0.01 * rng.standard_normal(X.shape)   # a plant near the estimate


@pytest.fixture(scope="module")
def sensed(tmp_path_factory):
    problem = parse_problem(copy.deepcopy(DOC))
    d = design_problem(problem)
    et = estimator_table(problem, d.table)
    ctl = build_estimator_controller(problem, d.table, et,
                                     build_dir=tmp_path_factory.mktemp("sensed_build"))
    return problem, d, et, ctl


def test_monte_carlo_through_c_agrees_with_the_oracle_of_the_implemented_tables(sensed):
    """The three numbers: the oracle of the designed (double) filter, the oracle of the float32
    tables as flashed, and 40 000 paths through the compiled C (sensor with additive and
    state-proportional noise every other tick, uncertain start, input noise). Cost, every knot
    mean and variance jointly within a Bonferroni-corrected 99.9 % band of the sample's own
    standard errors and of the exact ones (compare_to_oracle); fixed seed."""
    problem, d, et, ctl = sensed
    substeps = 4
    designed = evaluate_estimator(problem, d.table)
    gains, pred = et.per_tick()
    flashed = evaluate_estimator(problem, d.table, gains=gains, predictor=pred,
                                 propagator="euler", substeps=substeps)
    exact_flashed = evaluate_estimator(problem, d.table, gains=gains, predictor=pred)
    assert exact_flashed.moments.J == pytest.approx(designed.moments.J, rel=1e-6)
    mc, rec = simulate_estimator(problem, ctl, paths=40_000, seed=20261128, substeps=substeps,
                                 record=3)
    assert mc.worst_status == 0
    a = compare_to_oracle(mc, flashed.moments.J, flashed.moments.knot_mean, confidence=0.999,
                          knot_covs=flashed.moments.knot_cov)
    assert a.ok, (a.verdict, mc.cost_mean_ci(), flashed.moments.J)
    # With the exact standard errors (the loop's fourth moments) too; and the run's cost
    # variance lies within 4.5 of its sample standard errors of the exact one.
    tails = evaluate_estimator_tails(problem, d.table, flashed, predictor=pred,
                                     substeps=substeps)
    a = compare_to_oracle(mc, flashed.moments.J, flashed.moments.knot_mean, confidence=0.999,
                          knot_covs=flashed.moments.knot_cov, exact_se=tails)
    assert a.ok and a.standard_errors == "exact", a.verdict
    var, var_se = mc.cost_moments.cov()[0, 0], mc.cost_moments.var_se()[0]
    assert abs(var - tails.cost_var) < 4.5 * var_se, (var, tails.cost_var, var_se)
    # the recorded estimate is the controller's: per state, its error is of the filter's size
    err = rec["x"][1:] - rec["xhat"][1:]
    sigma = np.sqrt(np.diagonal(designed.error_cov, axis1=1, axis2=2).max(axis=0))
    assert np.all(np.abs(err).max(axis=(0, 1)) < 10 * sigma), (np.abs(err).max(axis=(0, 1)), sigma)


def test_a_wrong_filter_is_caught_by_the_same_comparison(sensed, tmp_path):
    """Mutation: the C run with gains one sample late (what an index slip in the firmware
    would do) fails the comparison that the right tables pass."""
    problem, d, et, ctl = sensed
    import dataclasses
    late = dataclasses.replace(et, gain=np.roll(et.gain, 1, axis=0))
    bad = build_estimator_controller(problem, d.table, late, build_dir=tmp_path)
    gains, pred = et.per_tick()
    flashed = evaluate_estimator(problem, d.table, gains=gains, predictor=pred,
                                 propagator="euler", substeps=4)
    mc, _ = simulate_estimator(problem, bad, paths=40_000, seed=20261128, substeps=4)
    a = compare_to_oracle(mc, flashed.moments.J, flashed.moments.knot_mean, confidence=0.999,
                          knot_covs=flashed.moments.knot_cov)
    assert not a.ok
    tails = evaluate_estimator_tails(problem, d.table, flashed, predictor=pred, substeps=4)
    a = compare_to_oracle(mc, flashed.moments.J, flashed.moments.knot_mean, confidence=0.999,
                          knot_covs=flashed.moments.knot_cov, exact_se=tails)
    assert not a.ok


def test_the_c_tests_expected_values_are_the_specifications():
    """tests/c/estimator_expected.h (what test_estimator.c checks the C against) is what the
    specification gives today: regenerate with tests/c/estimator_reference.py."""
    import importlib.util
    from conftest import REPO
    path = REPO / "tests" / "c" / "estimator_reference.py"
    spec = importlib.util.spec_from_file_location("estimator_reference", path)
    ref = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(ref)
    assert ref.expected() == (REPO / "tests" / "c" / "estimator_expected.h").read_text()


def test_a_sensor_wider_than_the_firmware_is_refused_in_one_line(tmp_path, capsys):
    """More outputs than STSP_MAX_NY: `stospline design` names measurement.C, status 2, and
    writes nothing."""
    import sys
    sys.path.insert(0, str(EXAMPLES.parent / "tests" / "python" / "cli"))
    from hostile import to_toml
    from stospline.cli import main
    from stospline.limits import MAX_NY
    doc = copy.deepcopy(DOC)
    p = MAX_NY + 1
    doc["measurement"] = {"C": [[1.0, 0.1 * i] for i in range(p)],
                          "V": np.diag(np.full(p, 0.01)).tolist()}
    path = tmp_path / "wide.toml"
    path.write_text(to_toml(doc))
    out = tmp_path / "out"
    assert main(["design", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "measurement.C" in err and "STSP_MAX_NY" in err, err
    assert not out.exists() or not any(out.iterdir())


def test_time_varying_plant_data_get_a_predictor_map_per_tick(tmp_path):
    """With time-varying dynamics each stage's tables hold one predictor map per tick (the
    plant's exact mean map of that tick), and the C runs them bit for bit as specified."""
    doc = copy.deepcopy(DOC)
    doc["dynamics"]["A"] = {"t": [0, 2], "values": [[[0, 1], [0, -0.2]], [[0, 1], [0, -1.0]]]}
    doc["stages"] = [{"cost": {"R": [[2]]}}, {"cost": {"R": [[1]]}}]
    problem = parse_problem(doc)
    d = design_problem(problem)
    et = estimator_table(problem, d.table)
    T = d.table.n_ticks
    assert len(et.model) == T and list(et.model_start) == [0, int(d.table.stage_start[1]), T]
    assert not np.array_equal(et.model[0], et.model[-1])
    ctl = build_estimator_controller(problem, d.table, et, build_dir=tmp_path)
    paths, rng = 4, np.random.default_rng(5)
    step, spec = ctl.stepper(paths), EstimatorSpec(d.table, et, paths)
    for j in range(T):
        Y = None
        if j % et.every == 0:
            Y = (spec.xhat[:, :1] + 0.05 * rng.standard_normal((paths, 1))).astype(np.float32)
        U, status = step(j, Y)
        assert np.array_equal(U, spec.step(j, Y)) and np.all(status == 0), j
        assert np.array_equal(step.xhat(), spec.xhat), j
