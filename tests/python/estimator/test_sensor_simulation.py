"""The summary of `stospline simulate` on a sensor (`report.sensor_simulation`): Monte Carlo
through the compiled C estimator controller agrees with the estimator oracle of the flashed
tables on the cost and knot means (the verdict) and on the estimation error ``x - x̂`` at every
knot (its mean and variance per state), with tolerances from the sample's own standard errors,
Bonferroni-corrected; the same comparison rejects the error of a filter on a sensor four times
noisier, which the run did not have."""
import copy
from dataclasses import replace

import numpy as np
import pytest

from stospline.estimator.oracle import evaluate_estimator
from stospline.harness.estimator_run import run_sensor_loop
from stospline.harness.montecarlo import z_value
from stospline.pipeline import design_problem
from stospline.problem.reader import parse_problem
from stospline.report.sensor_simulation import sensor_simulation_summary, sensor_simulation_text

DOC = {  # a double integrator with state-multiplicative noise, position sampled every 2 ticks
    "name": "di_sensor", "x0": [0.5, 0.0], "tick_hz": 20,
    "dynamics": {"A": [[0, 1], [0, 0]], "B": [[0], [1]],
                 "noise": [{"state": 1, "G": [[0], [0.3]]}]},
    "cost": {"R": [[1]]},
    "knots": [{"t": 1.0, "penalty": {"C": [[1, 0]], "target": [1.0], "weight": 2.0},
               "constraint": {"C": [[1, 0]], "value": [1.0]}},
              {"t": 2.0, "constraint": {"C": [[1, 0], [0, 1]], "value": [0.0, 0.0]}}],
    "measurement": {"C": [[1.0, 0.0]], "V": [[1e-2]], "every": 2,
                    "x0_cov": [[1e-2, 0.0], [0.0, 0.0]]},
}
PATHS, SEED, CONFIDENCE = 40_000, 20261128, 0.999


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    problem = parse_problem(copy.deepcopy(DOC))
    d = design_problem(problem)
    r = run_sensor_loop(problem, d.table, paths=PATHS, seed=SEED, substeps=4,
                        build_dir=tmp_path_factory.mktemp("sensor_build"))
    return d, r


def _error_z(r, k: int, mean, cov) -> np.ndarray:
    """z-scores of the Monte Carlo estimation error at knot k against `mean` and `cov`: each
    state's mean and variance, by the sample's standard errors."""
    e = r.record["knot_error"][k]
    var = np.diag(e.cov())
    return np.concatenate([(e.mean - mean) / e.mean_se(), (var - np.diag(cov)) / e.var_se()])


def test_the_run_agrees_with_the_oracle_of_the_flashed_tables(run):
    d, r = run
    s = sensor_simulation_summary(d, r, seed=SEED, confidence=CONFIDENCE)
    assert s["worst_status"] == 0 and s["saturation"]["tick_fraction"] == 0
    assert s["verdict"]["agree"], s["verdict"]
    assert s["cost"]["oracle_implemented"] == pytest.approx(r.exact.moments.J, rel=1e-9)
    text = sensor_simulation_text(s)
    assert "sensor: y = C x" in text and "estimation error x - x̂" in text
    assert text.rstrip().splitlines()[-1].startswith("  verdict: agree")


def test_the_estimation_error_agrees_with_the_oracle_at_every_knot(run):
    d, r = run
    s = sensor_simulation_summary(d, r, seed=SEED)
    knots = len(d.problem.knots)
    limit = z_value(CONFIDENCE, 2 * 2 * knots)          # mean and variance of 2 states
    for k, kn in enumerate(s["knots"]):
        e = kn["estimation_error"]
        z = _error_z(r, k, np.array(e["oracle_mean"]), np.array(e["oracle_cov"]))
        assert np.abs(z).max() < limit, (k, z, limit)
        assert np.abs(e["oracle_mean"]).max() < 1e-6     # unbiased up to float32 rounding


def test_the_same_comparison_rejects_a_noisier_sensors_error(run):
    """Mutation: the oracle of a filter on V x 4 (what a summary comparing against the wrong
    sensor would print) is outside the same limits."""
    d, r = run
    meas = d.problem.measurement
    gains, pred = r.tables.per_tick()
    noisy = replace(meas, V=4 * meas.V)
    wrong = evaluate_estimator(d.problem, d.table, noisy)
    knots = len(d.problem.knots)
    limit = z_value(CONFIDENCE, 2 * 2 * knots)
    worst = max(np.abs(_error_z(r, k, np.zeros(2), wrong.knot_error_cov[k])).max()
                for k in range(knots))
    assert worst > limit, (worst, limit)


def test_the_quadrotor_on_its_barometer_agrees(tmp_path):
    """examples/quadrotor_altimeter.toml (gravity as a drift the predictor carries, actuator
    limits, 50 Hz altitude): never saturated, and the run agrees with the oracle."""
    from stospline import load_problem
    from conftest import EXAMPLES
    problem = load_problem(EXAMPLES / "quadrotor_altimeter.toml")
    d = design_problem(problem)
    r = run_sensor_loop(problem, d.table, paths=4000, seed=SEED, substeps=1,
                        build_dir=tmp_path)
    s = sensor_simulation_summary(d, r, seed=SEED, confidence=CONFIDENCE)
    assert s["saturation"]["tick_fraction"] == 0 and s["worst_status"] == 0
    assert s["verdict"]["agree"], s["verdict"]
    knots = len(problem.knots)
    limit = z_value(CONFIDENCE, 2 * 2 * knots)
    for k in range(knots):
        z = _error_z(r, k, np.zeros(2), r.exact.knot_error_cov[k])
        assert np.abs(z).max() < limit, (k, z)


def test_fewer_paths_than_the_report_records(tmp_path):
    """A run of fewer paths than `record` (the report keeps 200) records every path."""
    problem = parse_problem(copy.deepcopy(DOC))
    d = design_problem(problem)
    r = run_sensor_loop(problem, d.table, paths=5, seed=SEED, substeps=1, record=200,
                        build_dir=tmp_path)
    assert r.record["x"].shape[1:] == (5, 2) and r.record["xhat"].shape[1:] == (5, 2)
