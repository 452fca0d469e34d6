"""Spline columns in fixed point (stsp_params.h, format 2 in a Q15/Q31 build): the compiled
spline parametric controller (`build_params_qspline_controller`, the gains of x, k0, L and the
columns all integer B-splines) is the host's reference (`QParamSpec` of the augmented law as
evaluated, `stospline.table.spline.qparams`) bit for bit, with theta at the box's vertices and
drawn, changed inside stage 0, on integer states over the whole Q range, and within the
table's bound over the box of the double law at each theta (`qparams.law_double_at`).

Monte Carlo through it (Q15: theta fixed, and changed at tick 150) agrees with the exact oracle
of the table as flashed (`ParametricFixedPoint.as_flashed`, the deviation rounded as the
device does: cost and every knot-mean component, jointly at 99 % from the sample's own
standard errors, fixed seed); the same runs reject the oracle at the parameters not in force
(the test can fail). The certificate over the box of the table as flashed
(`fixed_point_certificate`) is computed from this bound."""
import numpy as np
import pytest

from conftest import EXAMPLES
from stospline import load_problem
from stospline.harness.params_loop import build_params_qspline_controller
from stospline.options import resolve_options
from stospline.oracle.fixed_point_margin import fixed_point_certificate
from stospline.oracle.over_box import box_moments, box_state_range, vertices
from stospline.oracle.parametric import design_parametric
from stospline.table.qparams import QParamSpec, law_double_at
from stospline.table.spline.qparams import quantize_spline_parametric
from support.params_runs import fixed_and_changed_runs

SEED, PATHS, MC_PATHS, SUBSTEPS = 20261129, 8, 400, 2


@pytest.fixture(scope="module")
def robot():
    p = load_problem(EXAMPLES / "robot_goal.toml")
    pd = design_parametric(p)
    box = pd.box if pd.box is not None else box_moments(p, pd.table)
    return p, pd.table, box, box_state_range(box)


def _controller(robot, arith):
    p, pt, box, xr = robot
    pf, gains, cols = quantize_spline_parametric(pt, arith, xr,
                                                 resolve_options(p).spline_tolerance)
    return pf, build_params_qspline_controller(pt, pf, gains, cols)


@pytest.mark.parametrize("arith", ["q15", "q31"])
def test_compiled_is_the_reference_and_within_the_bound(robot, arith):
    p, pt, _, _ = robot
    pf, ctl = _controller(robot, arith)
    ft = pf.augmented
    F, n, T = ft.frac_bits, pf.n, ft.n_ticks
    dtype = np.int16 if arith == "q15" else np.int32
    rng = np.random.default_rng(SEED)
    box = vertices(p.parameters)
    theta = np.vstack([box, rng.uniform(pf.lower, pf.upper, (PATHS - len(box), box.shape[1]))])
    theta = theta.astype(np.float32)
    X = rng.integers(-(1 << F), 1 << F, (T, PATHS, n))
    ticks = np.arange(T)
    stage1 = int(ft.stage_start[1])
    latch_tick = np.where(ticks < stage1, 0, stage1)
    worst = 0.0
    for k in range(PATHS):
        for changes in ({0: theta[k]}, {0: theta[k], 150: theta[-1 - k]}):
            U, status = ctl.steps(changes, X[:, k:k + 1], dtype)
            assert status == 0
            spec = QParamSpec(pf, 1)
            want = np.empty((T, ft.dims[1]), np.int64)
            for j in range(T):
                if j in changes:
                    spec.set(changes[j])
                want[j] = spec.step(j, X[j, k:k + 1])[0]
            assert np.array_equal(U[:, 0], want), (k, changes)
        exact = law_double_at(pt, ticks, X[:, k] * ft.x_lsb[:n], X[latch_tick, k] * ft.x_lsb[:n],
                              np.broadcast_to(theta[k].astype(float), (T, theta.shape[1])))
        U, _ = ctl.steps({0: theta[k]}, X[:, k:k + 1], dtype)
        worst = max(worst, float((np.abs(U[:, 0] * ft.u_lsb - exact) / pf.bound).max()))
    assert worst <= 1.0 + 1e-9, worst
    assert worst > 0.05, worst                       # the bound is not vacuous


def test_monte_carlo_agrees_with_the_oracle_of_the_flashed_table(robot):
    p, pt, box, _ = robot
    pf, ctl = _controller(robot, "q15")
    flashed = pf.as_flashed(pt)
    rng = np.random.default_rng(SEED)
    lo, hi = pf.lower, pf.upper
    theta, theta2 = rng.uniform(lo, hi, (2, lo.size))
    runs = fixed_and_changed_runs(p, ctl, theta, theta2, paths=MC_PATHS, seed=SEED,
                                  substeps=SUBSTEPS)
    for name, (run, right, wrong) in runs.items():
        assert run.worst_status >= 0, name
        own = right(flashed, quantize=True)
        verdict = run.agreement(own.J, own.knot_mean)
        assert verdict.agree, (name, verdict)
        other = wrong(flashed, quantize=True)
        assert not run.agreement(other.J, other.knot_mean).agree, name
    cert = fixed_point_certificate(p, pt, pf, box)
    assert cert["corridors"] and not cert["margins"]      # the robot: corridors, no bands
