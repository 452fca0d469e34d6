"""Faults of the loop ([faults]): the fault oracle against Monte Carlo through the compiled C
controller, and the faults without an oracle checked where they reduce to a linear law.

Each linear fault is checked twice on the same fixed-seed run: it must agree with the fault
oracle (cost, knot means and knot variances, 99 % jointly) and must *disagree* with the
fault-free oracle, so the check can tell the fault is there.
"""
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

import stospline
from stospline.errors import ProblemError
from stospline.problem.faults import Faults, parse_faults
from stospline.problem.reader import parse_problem
from stospline.harness.controller import build_controller
from stospline.oracle.faults import FaultsNotExact, evaluate_with_faults
from stospline.harness.montecarlo import compare_to_oracle, simulate
from stospline.oracle.evaluate import evaluate_table

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from support.problems import BASE  # noqa: E402

PATHS, SEED, SUBSTEPS = 20000, 20261124, 2


@pytest.fixture(scope="module")
def di():
    """The noisy double integrator of BASE at 10 Hz (20 ticks): faults at a coarse rate are
    large next to the Monte Carlo error."""
    p = parse_problem(tomllib.loads(BASE))
    d = stospline.design_problem(p)
    return p, d, build_controller(d.table)


def _faults(problem, **spec) -> Faults:
    return parse_faults(spec, problem.n, problem.m)


def test_without_faults_the_fault_oracle_is_the_oracle(robot_problem, robot):
    """Two derivations of the same moments (augmented per-tick maps vs. evaluate_table)."""
    for prop in ("exact", "euler"):
        a = evaluate_table(robot_problem, robot.table, propagator=prop, substeps=2, path=False)
        b = evaluate_with_faults(robot_problem, robot.table, Faults(), propagator=prop,
                                 substeps=2)
        assert b.J == pytest.approx(a.J, rel=1e-12)
        for k in range(len(robot_problem.knots)):
            np.testing.assert_allclose(b.knot_mean[k], a.knot_mean[k], atol=1e-11)
            np.testing.assert_allclose(b.knot_cov[k], a.knot_cov[k], atol=1e-11)


@pytest.mark.parametrize("spec", [
    {"sensor_noise": 0.1},
    {"delay_ticks": 1},
    {"actuator_noise": 0.3},
    {"plant_B_scale": 0.9},
    {"plant_A_scale": 1.1},
    {"plant_noise_scale": 1.3},
    {"sensor_noise": [0.1, 0.05], "delay_ticks": 1, "actuator_noise": 0.3, "plant_B_scale": 1.1},
], ids=lambda s: ",".join(s))
def test_monte_carlo_through_c_agrees_with_the_fault_oracle(di, spec):
    p, d, ctl = di
    faults = _faults(p, **spec)
    mc = simulate(p, ctl, paths=PATHS, seed=SEED, substeps=SUBSTEPS, faults=faults)
    assert mc.worst_status == 0
    exact = evaluate_with_faults(p, d.table, faults, propagator="euler", substeps=SUBSTEPS)
    agree = compare_to_oracle(mc, exact.J, exact.knot_mean, knot_covs=exact.knot_cov)
    assert agree.ok, agree.verdict
    nominal = evaluate_table(p, d.table, propagator="euler", substeps=SUBSTEPS, path=False)
    blind = compare_to_oracle(mc, nominal.J, nominal.knot_mean, knot_covs=nominal.knot_cov)
    assert not blind.ok, f"{spec}: the fault is invisible at this level ({blind.verdict})"


def test_faults_draw_from_their_own_stream(di):
    """Common random numbers: a fault of zero size is the fault-free run, bit for bit, and
    the plant's numbers do not move when a fault draws its own."""
    p, _, ctl = di
    base = simulate(p, ctl, paths=500, seed=SEED, substeps=1, faults=Faults(), per_path=True)
    tiny = simulate(p, ctl, paths=500, seed=SEED, substeps=1, per_path=True,
                    faults=Faults(miss_probability=1e-300, sensor_quantum=np.zeros(2)))
    np.testing.assert_array_equal(tiny.cost, base.cost)
    quiet = p.without_noise()
    a = simulate(quiet, ctl, paths=3, seed=SEED, substeps=1, per_path=True,
                 faults=_faults(p, actuator_noise=0.0, sensor_noise=1e-300))
    b = simulate(quiet, ctl, paths=3, seed=SEED, substeps=1, faults=Faults(), per_path=True)
    np.testing.assert_allclose(a.cost, b.cost, rtol=1e-12)


def test_a_quantizer_coarser_than_the_plan_leaves_the_open_loop_law(di):
    """Quantization has no oracle, but a step far beyond the state's range makes every
    measurement 0: the controller then runs the linear law with K = 0 and Lambda = 0, whose
    exact moments the oracle gives."""
    p, d, ctl = di
    faults = _faults(p, sensor_quantum=1e6)
    with pytest.raises(FaultsNotExact):
        evaluate_with_faults(p, d.table, faults)
    mc = simulate(p, ctl, paths=PATHS, seed=SEED, substeps=SUBSTEPS, faults=faults)
    t = d.table
    blind = t.with_arrays(K=np.zeros_like(t.K), Lambda=np.zeros_like(t.Lambda))
    exact = evaluate_table(p, blind, propagator="euler", substeps=SUBSTEPS, path=False)
    agree = compare_to_oracle(mc, exact.J, exact.knot_mean, knot_covs=exact.knot_cov)
    assert agree.ok, agree.verdict
    closed = evaluate_table(p, t, propagator="euler", substeps=SUBSTEPS, path=False)
    assert not compare_to_oracle(mc, closed.J, closed.knot_mean, knot_covs=closed.knot_cov).ok


def test_a_controller_that_never_runs_holds_zero(di):
    """Missed ticks have no oracle; with every tick missed the actuator holds its initial 0,
    the law with every gain 0."""
    p, d, ctl = di
    faults = _faults(p, miss_probability=1 - 1e-15)
    with pytest.raises(FaultsNotExact):
        evaluate_with_faults(p, d.table, faults)
    mc = simulate(p, ctl, paths=PATHS, seed=SEED, substeps=SUBSTEPS, faults=faults)
    assert np.all(mc.sample_u == 0)
    t = d.table
    zero = t.with_arrays(K=np.zeros_like(t.K), k0=np.zeros_like(t.k0), L=np.zeros_like(t.L))
    exact = evaluate_table(p, zero, propagator="euler", substeps=SUBSTEPS, path=False)
    agree = compare_to_oracle(mc, exact.J, exact.knot_mean, knot_covs=exact.knot_cov)
    assert agree.ok, agree.verdict


def test_missed_ticks_are_skipped_ticks_to_the_firmware(di):
    """A missed tick is a tick the firmware never sees: the next call is a skipped tick, which
    it accepts (no error status, a stage entered late latches then), and the run moves."""
    p, _, ctl = di
    base = simulate(p, ctl, paths=2000, seed=SEED, substeps=1, faults=Faults(), per_path=True)
    missed = simulate(p, ctl, paths=2000, seed=SEED, substeps=1, per_path=True,
                      faults=_faults(p, miss_probability=0.3))
    assert missed.worst_status == 0 and not np.array_equal(missed.cost, base.cost)


def test_fault_runs_are_the_same_on_any_number_of_workers(robot_problem, robot_controller):
    faults = _faults(robot_problem, sensor_noise=0.01, miss_probability=0.05, delay_ticks=1)
    one = simulate(robot_problem, robot_controller, paths=2100, seed=SEED, substeps=1,
                   workers=1, faults=faults, per_path=True)
    two = simulate(robot_problem, robot_controller, paths=2100, seed=SEED, substeps=1,
                   workers=2, faults=faults, per_path=True)
    np.testing.assert_array_equal(one.cost, two.cost)
    np.testing.assert_array_equal(one.knot_states[-1], two.knot_states[-1])


def test_faults_refuse_tables_the_fault_harness_does_not_run(di):
    p, d, _ = di
    q15 = build_controller(stospline.fixed_point_table(d, "q15"))
    with pytest.raises(ProblemError, match="^faults: are simulated for float32"):
        simulate(p, q15, paths=2, seed=1, substeps=1, faults=_faults(p, delay_ticks=1))


@pytest.mark.parametrize("spec, field, reason", [
    ({"sensor_nois": 0.1}, "faults.sensor_nois", "unknown fault"),
    ({"sensor_noise": -0.1}, "faults.sensor_noise", "finite and >= 0"),
    ({"sensor_noise": [0.1, 0.1, 0.1]}, "faults.sensor_noise", "length 3, expected 2"),
    ({"actuator_noise": [0.1, 0.2]}, "faults.actuator_noise", "length 2, expected 1"),
    ({"delay_ticks": 2}, "faults.delay_ticks", "0 or 1"),
    ({"delay_ticks": True}, "faults.delay_ticks", "0 or 1"),
    ({"miss_probability": 1.0}, "faults.miss_probability", "below 1"),
    ({"plant_B_scale": 0.0}, "faults.plant_B_scale", "in \\(0, 1000\\]"),
    ({"sensor_quantum": float("nan")}, "faults.sensor_quantum", "finite"),
    ({"actuator_noise": "big"}, "faults.actuator_noise", "must be a number"),
    ({"sensor_noise": 1e300}, "faults.sensor_noise", "within the float32 range"),
])
def test_bad_faults_name_the_field(spec, field, reason):
    doc = tomllib.loads(BASE)
    doc["faults"] = spec
    with pytest.raises(ProblemError) as exc:
        parse_problem(doc)
    assert exc.value.field == field
    assert reason.replace("\\", "") in exc.value.reason or __import__("re").search(
        reason, exc.value.reason)


def test_faults_round_trip_through_the_problem_file():
    doc = tomllib.loads(BASE)
    doc["faults"] = {"sensor_noise": [0.1, 0.05], "delay_ticks": 1, "miss_probability": 0.01,
                     "plant_noise_scale": 1.5}
    p = parse_problem(doc)
    again = parse_problem(tomllib.loads(p.to_toml()))
    assert again.faults == p.faults and again.faults.any
    assert p.faults.label() == ("sensor_noise=[0.1, 0.05] delay_ticks=1 miss_probability=0.01 "
                                "plant_noise_scale=1.5")
