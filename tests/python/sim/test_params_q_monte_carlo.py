"""Monte Carlo through the compiled Q15/Q31 parametric controller (stsp_set_params and the
fixed-point stsp_param_step, `build_params_qcontroller`): the harness rounds each path's state
to its Q format and gives the plant the integer commands times their LSB (`controller.q_io`),
with theta drawn in the box (seeded) and changed inside stage 0 (relatched at the stage-1
start).

Two oracles, each jointly at 99 % (Bonferroni, the sample's own standard errors, fixed seed):

* the law as flashed (`ParametricFixedPoint.as_flashed`: the stored integers in real units and
  the deviation as the device rounds it): cost and every knot-mean component;
* the exact oracle of the double table (`evaluate_at`, `evaluate_switched`): every knot-mean
  component, a difference within the fixed-point error bound propagated to the mean
  (`oracle.fixed_point_margin`; for Q31 also the harness's float32 command) counted as none.

The same runs reject both oracles at a theta not in force (the test can fail)."""
import numpy as np
import pytest

from conftest import EXAMPLES
from stospline import load_problem
from stospline.harness.params_loop import build_params_qcontroller
from stospline.oracle.fixed_point_margin import mean_error_bound
from stospline.oracle.over_box import box_moments, box_state_range
from stospline.oracle.parametric import design_parametric
from stospline.table.qparams import quantize_parametric
from support.params_runs import fixed_and_changed_runs

PATHS, SEED, SUBSTEPS = 1000, 20261201, 2


@pytest.fixture(scope="module")
def robot():
    p = load_problem(EXAMPLES / "robot_goal.toml")
    pt = design_parametric(p).table
    rng = np.random.default_rng(SEED)
    lo, hi = np.array([[q.lower, q.upper] for q in pt.parameters]).T
    theta, theta2 = rng.uniform(lo, hi, (2, lo.size))
    return p, pt, box_state_range(box_moments(p, pt)), theta, theta2


def _allowance(p, pt, pf):
    """The bound on each knot mean's distance from the double law's (knot: (n,))."""
    b = pf.command_error_bound(pt)
    if pf.augmented.arith == "q31":            # the harness's plant takes float32 commands
        b = b + np.ldexp(1.0, pf.augmented.u_exp.astype(int) - 24)
    shift = mean_error_bound(p, pt.table, b).rows(np.eye(p.n))
    return [shift[j] for j in pt.table.stage_start[1:]]


@pytest.mark.parametrize("arith", ["q15", "q31"])
def test_q_parametric_monte_carlo_agrees_with_the_oracle(robot, arith):
    p, pt, xr, theta, theta2 = robot
    pf = quantize_parametric(pt, arith, xr)
    flashed = pf.as_flashed(pt)
    ctl = build_params_qcontroller(pt, pf)
    allow = _allowance(p, pt, pf)
    runs = fixed_and_changed_runs(p, ctl, theta, theta2, paths=PATHS, seed=SEED,
                                  substeps=SUBSTEPS)
    for name, (run, right, wrong) in runs.items():
        assert run.worst_status >= 0, name
        own = right(flashed, quantize=True)
        verdict = run.agreement(own.J, own.knot_mean)
        assert verdict.agree, (name, verdict)
        exact = right(pt)
        verdict = run.agreement(None, exact.knot_mean, allowance=allow)
        assert verdict.agree, (name, verdict)
        # power: the oracles with the parameters not in force disagree with the same run
        other = wrong(flashed, quantize=True)
        assert not run.agreement(other.J, other.knot_mean).agree, name
        other = wrong(pt)
        assert not run.agreement(None, other.knot_mean, allowance=allow).agree, name
