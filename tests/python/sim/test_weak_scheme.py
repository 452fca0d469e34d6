"""The plant scheme of weak order two in the second moments (`harness.weak_scheme`): its
step's moment map against the SDE's (third-order local error), the expected cost's bias
against substeps (second order, where the Euler scheme's is first), the harness running it
(its Monte Carlo cost against its oracle; its exits against a fine-step reference), and the
substep choice that uses it."""
import math
import tomllib

import numpy as np
import pytest

from stospline.design.moments import exact_tick, euler_tick, running_cost_matrix
from stospline.harness.controller import build_controller
from stospline.harness.montecarlo import simulate
from stospline.harness.plant_scheme import choose_substeps
from stospline.harness.weak_scheme import scheme_problem, scheme_stage
from stospline.oracle.evaluate import evaluate_table
from stospline.pipeline import design_problem
from stospline.problem import parse_problem
from stospline.problem.model import Stage

from conftest import EXAMPLES

SEED = 20261128


def _problem(name: str, hz: int | None = None):
    doc = tomllib.loads((EXAMPLES / name).read_text())
    if hz is not None:
        doc["tick_hz"] = hz
    problem = parse_problem(doc)
    return problem, design_problem(problem)


@pytest.fixture(scope="module")
def eps01():
    return _problem("robot_corridor_eps01.toml")


@pytest.fixture(scope="module")
def robot_10hz():
    return _problem("robot_corridor.toml", 10)


def _coupled_stage() -> Stage:
    """Noise the robot's shortcut cannot absorb: x_1 drives x_0's noise and x_0 drives x_1's
    on another Brownian component (the noise of the noise is not G(z) T), input noise, and a
    drift f on x_2, which multiplies no noise."""
    G = np.zeros((3, 3, 2))
    G[1, 0, 0] = 0.7             # x_1 * 0.7 dZ_0 into x_0
    G[0, 1, 1] = 0.5             # x_0 * 0.5 dZ_1 into x_1
    H = np.zeros((1, 3, 2))
    H[0, 1, 0] = 0.3             # u * 0.3 dZ_0 into x_1
    A = np.array([[-0.4, 1.0, 0.0], [-2.0, -0.3, 0.5], [0.0, 0.0, -1.0]])
    return Stage(A=A, B=np.array([[0.0], [1.0], [0.0]]), G=G, H=H,
                 Q=np.diag([1.0, 0.2, 0.1]), S=np.array([[0.1], [0.0], [0.0]]), R=np.eye(1),
                 q=np.array([0.3, -0.1, 0.0]), r=np.array([0.05]), rho=0.7,
                 f=np.array([0.0, 0.0, 0.2]))


@pytest.mark.parametrize("which", ["robot", "coupled"])
def test_one_step_second_moments_are_exact_to_third_order(eps01, which):
    stage = eps01[0].stages[0] if which == "robot" else _coupled_stage()
    n, m = stage.B.shape
    d = n + m + 1
    errors, euler = [], []
    for dt in (0.02, 0.01, 0.005):
        exact = exact_tick(stage, m + 1, dt)
        sub = scheme_stage(stage, dt)
        ours = euler_tick(sub, m + 1, dt, 1)
        errors.append(np.abs(ours.Phi - exact.Phi).max())
        euler.append(np.abs(euler_tick(stage, m + 1, dt, 1).Phi - exact.Phi).max())
        # the step's cost is the exact conditional expectation of the running cost
        want = running_cost_matrix(stage, n, m, d, n).ravel() @ exact.Psi
        got = running_cost_matrix(sub, n, m, d, n).ravel() @ ours.Psi
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * np.abs(want).max())
    for a, b in zip(errors, errors[1:]):
        assert 6.5 < a / b < 9.5             # O(dt^3): halving dt divides it by 8
    for a, b in zip(euler, euler[1:]):
        assert 3.5 < a / b < 4.5             # the Euler step's O(dt^2), for contrast


def test_expected_cost_bias_falls_as_substeps_squared(eps01):
    problem, d = eps01
    exact = d.implemented.J
    weak = [evaluate_table(scheme_problem(problem, s), d.table, propagator="euler",
                           substeps=s, path=False).J - exact for s in (1, 2, 4)]
    euler = [evaluate_table(problem, d.table, propagator="euler", substeps=s,
                            path=False).J - exact for s in (1, 2, 4)]
    for a, b in zip(weak, weak[1:]):
        assert 3.6 < a / b < 4.4
    for a, b in zip(euler, euler[1:]):
        assert 1.8 < a / b < 2.2
    assert abs(weak[0]) < abs(euler[0]) / 100     # at 1 kHz one step is 1600x closer


def test_the_harness_runs_the_schemes_moments_and_exits(robot_10hz):
    """At 10 Hz (dt = 0.1, where the schemes differ): the run's mean cost is the scheme
    oracle's within 4 standard errors (160 000 paths), while Euler's with one step is more
    than 6 away (the check can tell them apart); its exit probability with 4 steps is a 32-step Euler run's
    within 4.5 combined standard errors (40 000 paths each), where one Euler step is further.
    Both schemes' exits carry a first-order bias (this one's upwards: one step gives 10.5 %
    against 9.3 %; docs/evidence/corridor-exit.md)."""
    problem, d = robot_10hz
    ctl = build_controller(d.table)
    paths = 40_000
    run = scheme_problem(problem, 1)
    mc = simulate(run, ctl, paths=4 * paths, seed=SEED, substeps=1, workers=1)
    se = mc.cost_std() / math.sqrt(4 * paths)
    J = evaluate_table(run, d.table, propagator="euler", substeps=1, path=False).J
    J_euler = evaluate_table(problem, d.table, propagator="euler", substeps=1, path=False).J
    assert abs(mc.cost_mean_ci()[0] - J) < 4 * se
    assert abs(J_euler - J) > 6 * se

    def exits(prob, s):
        k = simulate(prob, ctl, paths=paths, seed=SEED + s, substeps=s,
                     workers=1).exit_count(0)
        return k / paths, k / paths * (1 - k / paths) / paths

    ref, ref_var = exits(problem, 32)
    for prob, s, close in ((scheme_problem(problem, 4), 4, True), (problem, 1, False)):
        p, var = exits(prob, s)
        z = abs(p - ref) / math.sqrt(var + ref_var)
        assert z < 4.5 if close else z > 4.5, (s, p, ref)


def test_choose_substeps_with_the_scheme(eps01):
    """For a 3·10^6-path run the Euler scheme needs 16 or more steps per tick (by the pilot's
    spread); this scheme one, with its exact bias below the target."""
    problem, d = eps01
    ctl = build_controller(d.table)
    choice = choose_substeps(problem, ctl, d.implemented.J, paths=3_000_000, seed=SEED,
                             scheme="weak2")
    assert choice.met and choice.substeps == 1
    assert abs(choice.bias) <= choice.target
    bias = evaluate_table(scheme_problem(problem, 1), d.table, propagator="euler",
                          substeps=1, path=False).J - d.implemented.J
    assert choice.bias == pytest.approx(bias, rel=1e-12)
    euler = choose_substeps(problem, ctl, d.implemented.J, paths=3_000_000, seed=SEED)
    assert euler.substeps >= 16


def test_refused():
    stage = _coupled_stage()
    G = stage.G.copy()
    G[2, 0, 0] = 1.0                                      # x_2, which f drives, in the noise
    from dataclasses import replace
    with pytest.raises(ValueError, match="drift f enters the noise"):
        scheme_stage(replace(stage, G=G), 0.01)
    with pytest.raises(ValueError, match="scheme"):
        scheme_problem(parse_problem(tomllib.loads((EXAMPLES / "robot_corridor.toml")
                                                   .read_text())), 1, "milstein")
