"""Monte Carlo through the compiled C controller against the oracle's exact numbers.

Tolerances come from the sample's own confidence intervals (99% jointly, Bonferroni over the
cost and every knot-mean component) with a fixed seed; the planted-fault cases show that the
same check rejects a controller that is slightly wrong.
"""
import numpy as np
import pytest

from stospline.harness.controller import build_controller
from stospline.harness.montecarlo import compare_to_oracle, simulate
from stospline.oracle.evaluate import evaluate_table

PATHS, SEED, SUBSTEPS = 4000, 20261123, 2


@pytest.fixture(scope="module")
def robot_mc(robot_problem, robot_controller):
    return simulate(robot_problem, robot_controller, paths=PATHS, seed=SEED, substeps=SUBSTEPS)


def test_mc_agrees_with_oracle_of_implemented_controller(robot, robot_mc):
    assert robot_mc.worst_status == 0
    agree = compare_to_oracle(robot_mc, robot.implemented.J, robot.implemented.knot_mean)
    assert agree.ok, (agree.cost_z, agree.knot_mean_z, agree.z_limit)


def test_plant_scheme_bias_is_far_below_mc_error(robot_problem, robot, robot_mc):
    """The oracle evaluates the simulator's own scheme exactly: its bias must be tiny next to
    the Monte Carlo standard error (here < 5% of it), so agreement tests the controller."""
    euler = evaluate_table(robot_problem, robot.table, propagator="euler", substeps=SUBSTEPS,
                           path=False)
    se = robot_mc.cost_std() / np.sqrt(robot_mc.paths)
    assert abs(euler.J - robot.implemented.J) < 0.05 * se
    for k in range(len(robot_problem.knots)):
        np.testing.assert_allclose(euler.knot_mean[k], robot.implemented.knot_mean[k], atol=1e-9)


def test_noise_free_plant_reproduces_oracle_to_float32(robot_problem, robot, robot_controller):
    quiet = robot_problem.without_noise()
    mc = simulate(quiet, robot_controller, paths=2, seed=1, substeps=SUBSTEPS, per_path=True)
    exact = evaluate_table(quiet, robot.table, path=False)
    assert mc.cost[0] == pytest.approx(exact.J, rel=1e-6)
    for k in range(2):
        np.testing.assert_allclose(mc.knot_states[k][0], exact.knot_mean[k], atol=1e-5)


def _perturbed(table, what):
    K, k0, L = table.K.copy(), table.k0.copy(), table.L.copy()
    Lam, lam0 = table.Lambda.copy(), table.lambda0.copy()
    s0 = slice(0, int(table.stage_start[1]))
    if what == "feedforward +3% on stage 0":
        k0[s0] *= 1.03
    elif what == "feedback gain sign flip (K[0][1] of every tick)":
        K[:, 0, 1] *= -1
    elif what == "latch map of stage 1 off by 20%":
        Lam[1] *= 1.2
    elif what == "latch offset of stage 0 sign-flipped":
        lam0[0] *= -1
    elif what == "multiplier gain dropped on stage 1":
        L[int(table.stage_start[1]):] = 0
    return table.with_arrays(K=K, k0=k0, L=L, Lambda=Lam, lambda0=lam0)


@pytest.mark.parametrize("fault", [
    "feedforward +3% on stage 0",
    "feedback gain sign flip (K[0][1] of every tick)",
    "latch map of stage 1 off by 20%",
    "latch offset of stage 0 sign-flipped",
    "multiplier gain dropped on stage 1",
])
def test_check_rejects_a_wrong_controller(robot_problem, robot, fault):
    """The compiled controller with a planted fault is compared with the oracle of the
    correct table: the same 99% check must fail."""
    bad = build_controller(_perturbed(robot.table, fault))
    mc = simulate(robot_problem, bad, paths=1000, seed=SEED, substeps=1)
    agree = compare_to_oracle(mc, robot.implemented.J, robot.implemented.knot_mean)
    assert not agree.ok, f"{fault}: max |z| {agree.max_abs_z:.2f} <= {agree.z_limit:.2f}"


@pytest.mark.parametrize("fault", ["feedforward +3% on stage 0",
                                   "latch offset of stage 0 sign-flipped"])
def test_simulation_verdict_rejects_a_wrong_controller(robot_problem, robot, fault):
    """`simulation_summary`'s verdict (what `stospline simulate --check` exits on) for the
    compiled controller of a faulty table, against the oracle of the correct one."""
    from dataclasses import replace
    from stospline.pipeline import simulate_problem, simulation_summary
    bad = replace(robot, table=_perturbed(robot.table, fault))
    mc = simulate_problem(bad, paths=1000, seed=SEED, substeps=1)
    v = simulation_summary(bad, mc, seed=SEED)["verdict"]
    assert not v["agree"], v
    assert v["max_abs_z"] > v["z_limit"] and v["statistics"] == 9
    good = simulation_summary(robot, simulate_problem(robot, paths=1000, seed=SEED,
                                                      substeps=1), seed=SEED)["verdict"]
    assert good["agree"], good
    assert v["standard_errors"] == good["standard_errors"] == "exact"
