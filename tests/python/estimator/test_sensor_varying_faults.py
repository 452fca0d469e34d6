"""The loop on a sensor with time-varying data (stage data and the sensor's V sampled in time)
and with faults (sensor noise on the state read, actuator noise, model mismatch, missed
ticks): the estimator oracle's exact moments, and small Monte Carlo runs through the compiled
C against them (CI tolerances from the runs' own standard errors, Bonferroni-corrected, fixed
seeds), with a wrong controller and a fault-blind oracle rejected on the same runs. Refused
faults name their field.
"""
import copy
import dataclasses

import numpy as np
import pytest

from stospline.errors import ProblemError
from stospline.estimator.ctable import estimator_table
from stospline.estimator.oracle import evaluate_estimator
from stospline.harness.estimator_loop import build_estimator_controller, simulate_estimator
from stospline.harness.estimator_run import sensor_loop_unsupported
from stospline.harness.montecarlo import compare_to_oracle, z_value
from stospline.oracle.faults import evaluate_with_faults
from stospline.pipeline import design_problem
from stospline.problem.faults import parse_faults
from stospline.problem.reader import parse_problem

DOC = {  # a double integrator whose stiffness and damping grow, position read every 2 ticks
    "name": "di_sensor_tv", "x0": [0.5, 0.0], "tick_hz": 20,
    "dynamics": {"A": {"t": [0, 2], "values": [[[0, 1], [0, -0.2]], [[0, 1], [-3.0, -1.0]]]},
                 "B": [[0], [1]], "noise": [{"state": 1, "G": [[0], [0.3]]}]},
    "cost": {"R": [[1]]},
    "knots": [{"t": 1.0, "penalty": {"C": [[1, 0]], "target": [1.0], "weight": 2.0},
               "constraint": {"C": [[1, 0]], "value": [1.0]}},
              {"t": 2.0, "constraint": {"C": [[1, 0], [0, 1]], "value": [0.0, 0.0]}}],
    # the sensor improves over the plan (a range sensor nearing its target): V 1e-1 to 1e-3
    "measurement": {"C": [[1.0, 0.0]], "V": {"t": [0, 2], "values": [[[1e-1]], [[1e-3]]]},
                    "every": 2, "x0_cov": [[1e-2, 0.0], [0.0, 0.0]]},
}
FAULTS = {"sensor_noise": [0.2, 0.0], "actuator_noise": [1.0], "plant_B_scale": 0.8,
          "miss_probability": 0.3}
PATHS, SEED, SUBSTEPS, CONFIDENCE = 400, 20261128, 4, 0.999


def _with_faults(problem, faults):
    return dataclasses.replace(problem, faults=parse_faults(faults, problem.n, problem.m))


@pytest.fixture(scope="module")
def loop():
    problem = parse_problem(copy.deepcopy(DOC))
    d = design_problem(problem)
    et = estimator_table(problem, d.table)
    return problem, d, et, build_estimator_controller(problem, d.table, et)


class _Agreement:
    """The run against `oracle`: `loop` (cost, knot means and variances, `compare_to_oracle`)
    and `error` (the estimation error x - x̂ at every knot, its mean and variance per state),
    each jointly at CONFIDENCE."""

    def __init__(self, problem, ctl, oracle):
        mc, rec = simulate_estimator(problem, ctl, paths=PATHS, seed=SEED, substeps=SUBSTEPS)
        assert mc.worst_status == 0
        m = oracle.moments
        self.loop = compare_to_oracle(mc, m.J, m.knot_mean, confidence=CONFIDENCE,
                                      knot_covs=m.knot_cov)
        z = []
        for k, e in enumerate(rec["knot_error"]):
            mean = m.knot_mean[k] - oracle.knot_estimate_mean[k]
            z += list((e.mean - mean) / e.mean_se())
            z += list((np.diag(e.cov()) - np.diag(oracle.knot_error_cov[k])) / e.var_se())
        self.error_z = np.abs(z).max()
        self.error = self.error_z < z_value(CONFIDENCE, len(z))

    @property
    def ok(self) -> bool:
        return self.loop.ok and self.error


def _flashed(problem, d, et, faults=None):
    gains, pred = et.per_tick()
    return evaluate_estimator(problem, d.table, gains=gains, predictor=pred, faults=faults,
                              propagator="euler", substeps=SUBSTEPS)


def test_the_sampled_V_sets_the_gains_tick_by_tick(loop):
    """The filter's gain on a sensor that improves grows as V falls, and differs from the
    gain of a sensor held at V's first sample; the table reads back as written."""
    problem, d, et, _ = loop
    meas = problem.measurement
    assert meas.V_series is not None and meas.V_at(2.0)[0, 0] == pytest.approx(1e-3)
    held = dataclasses.replace(meas, V_series=None)
    g = evaluate_estimator(problem, d.table).gain[::2, 0, 0]
    g_held = evaluate_estimator(problem, d.table, held).gain[::2, 0, 0]
    assert g_held[-1] < 0.5 * g[-1], (g[-1], g_held[-1])
    assert g[0] == pytest.approx(g_held[0], rel=1e-12)       # same V at t = 0
    back = parse_problem({**copy.deepcopy(DOC), "measurement": meas.as_dict()})
    assert back.measurement == meas


def test_time_varying_data_through_c_agree_with_the_oracle(loop):
    """Stage data and V varying in time, 400 paths through the compiled C: cost, knot means and
    variances jointly within the 99.9 % band of the flashed tables' exact moments."""
    problem, d, et, ctl = loop
    assert sensor_loop_unsupported(problem, d.table) is None
    a = _Agreement(problem, ctl, _flashed(problem, d, et))
    assert a.ok, (a.loop.verdict, a.error_z)
    # the same run against the oracle of a sensor held at V's first sample: its estimation
    # error is the wrong size (the check that the run and the oracle both follow V in time)
    held = dataclasses.replace(problem.measurement, V_series=None)
    gains, pred = et.per_tick()
    wrong = evaluate_estimator(problem, d.table, held, gains=gains, predictor=pred,
                               propagator="euler", substeps=SUBSTEPS)
    assert not _Agreement(problem, ctl, wrong).error


def test_a_controller_that_ignores_the_time_variation_is_caught(loop):
    """Mutation: the filter's predictor frozen at each stage's first tick (one map per stage,
    what treating the stage as constant would flash) fails the same comparison."""
    problem, d, et, _ = loop
    ms = et.model_start
    frozen = dataclasses.replace(
        et, model=np.stack([et.model[int(ms[s])] for s in range(len(ms) - 1)]),
        model_start=np.arange(len(ms), dtype=np.uint32))
    bad = build_estimator_controller(problem, d.table, frozen)
    assert not _Agreement(problem, bad, _flashed(problem, d, et)).ok


def test_faults_compose_with_the_sensor_through_c(loop):
    """Sensor noise on the state read, actuator noise, B x 0.8 and 30 % missed ticks around
    the same flashed filter: the run agrees with the fault oracle (cost, knot moments and the
    estimation error); the oracle that leaves out any one of the faults is rejected on the
    same run."""
    problem, d, et, ctl = loop
    faulty = _with_faults(problem, FAULTS)
    assert sensor_loop_unsupported(faulty, d.table) is None
    a = _Agreement(faulty, ctl, _flashed(faulty, d, et, faulty.faults))
    assert a.ok, (a.loop.verdict, a.error_z)
    for key in FAULTS:
        fewer = parse_faults({k: v for k, v in FAULTS.items() if k != key}, 2, 1)
        assert not _Agreement(faulty, ctl, _flashed(faulty, d, et, fewer)).ok, key


def test_a_sensor_that_reads_the_state_exactly_is_the_full_state_fault_loop(loop):
    """With C = I, V = 0, every tick and the gain I, the estimate is the reading x + nu: the
    loop with faults is the full-state loop with the same faults, and the estimator oracle
    gives the fault oracle's moments (`oracle.faults`, computed another way)."""
    problem, d, _, _ = loop
    doc = copy.deepcopy(DOC)
    doc["measurement"] = {"C": [[1.0, 0.0], [0.0, 1.0]], "V": [[0.0, 0.0], [0.0, 0.0]]}
    linear = {k: v for k, v in FAULTS.items() if k != "miss_probability"}
    faulty = _with_faults(parse_problem(doc), {**linear, "sensor_noise": [0.05, 0.1]})
    eye = np.broadcast_to(np.eye(2), (d.table.n_ticks, 2, 2))
    got = evaluate_estimator(faulty, d.table, gains=eye, faults=faulty.faults).moments
    want = evaluate_with_faults(faulty, d.table)
    assert got.J == pytest.approx(want.J, rel=1e-10)
    for k in range(len(faulty.knots)):
        np.testing.assert_allclose(got.knot_mean[k], want.knot_mean[k], rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(got.knot_cov[k], want.knot_cov[k], rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("fault, field", [({"delay_ticks": 1}, "faults.delay_ticks"),
                                          ({"sensor_quantum": [0.01, 0.0]},
                                           "faults.sensor_quantum")])
def test_faults_the_sensor_loop_does_not_run_are_named(loop, fault, field):
    problem, d, _, ctl = loop
    faulty = _with_faults(problem, fault)
    assert sensor_loop_unsupported(faulty, d.table)[0] == field
    with pytest.raises(ProblemError, match=field):
        evaluate_estimator(faulty, d.table, faults=faulty.faults)
    with pytest.raises(ProblemError, match=field):
        simulate_estimator(faulty, ctl, paths=2, seed=1)


@pytest.mark.parametrize("key, value, field", [
    ("C", {"t": [0, 1], "values": [[[1.0, 0.0]], [[1.0, 0.1]]]}, "measurement.C"),
    ("V", {"t": [0, 1], "values": [[[1e-2]], [[-1.0]]]}, "measurement.V.values[1]"),
    ("V", {"t": [1, 0], "values": [[[1e-2]], [[1e-2]]]}, "measurement.V.t")])
def test_bad_sampled_measurements_name_the_field(key, value, field):
    doc = copy.deepcopy(DOC)
    doc["measurement"][key] = value
    with pytest.raises(ProblemError) as e:
        parse_problem(doc)
    assert str(e.value).startswith(field + ":"), str(e.value)
