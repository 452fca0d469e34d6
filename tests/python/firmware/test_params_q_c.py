"""Runtime parameters in the Q15/Q31 firmware (stsp_params.h, "Fixed point"): the compiled
controller with a fixed-point parametric table is the host's reference
(`stospline.table.qparams.QParamSpec`) bit for bit, at random parameter vectors over the box
(its vertices included), changed at a stage start and inside a stage, with integer states over
the whole Q range; and its commands are within the table's bound of the double-precision law
at each theta (`qparams.law_double_at`). The C test's expected values
(tests/c/params_q_expected.h) are the reference's."""
import sys

import numpy as np
import pytest

from conftest import EXAMPLES, REPO
from stospline import load_problem
from stospline.harness.params_loop import build_params_qcontroller
from stospline.oracle.over_box import box_moments, box_state_range, vertices
from stospline.oracle.parametric import design_parametric
from stospline.table.qparams import QParamSpec, law_double_at, quantize_parametric

sys.path.insert(0, str(REPO / "tests" / "c"))
import params_q_reference  # noqa: E402

SEED, PATHS = 20261129, 24


def test_expected_header_is_the_reference():
    assert (REPO / "tests/c/params_q_expected.h").read_text() == params_q_reference.expected(), \
        "regenerate tests/c/params_q_expected.h with tests/c/params_q_reference.py"


def test_spline_expected_header_is_the_reference():
    """tests/c/test_params_spline.c's expected values: the reference of the Q spline
    parametric controllers gains/robot_goal_<arith>_spline*."""
    assert (REPO / "tests/c/params_qspline_expected.h").read_text() == \
        params_q_reference.expected(spline=True), \
        "regenerate tests/c/params_qspline_expected.h with tests/c/params_q_reference.py --spline"


@pytest.fixture(scope="module")
def robot():
    p = load_problem(EXAMPLES / "robot_goal.toml")
    pt = design_parametric(p).table
    return p, pt, box_state_range(box_moments(p, pt))


@pytest.mark.parametrize("arith", ["q15", "q31"])
def test_compiled_controller_is_the_reference_and_within_the_bound(robot, arith, tmp_path):
    p, pt, xr = robot
    pf = quantize_parametric(pt, arith, xr)
    ft = pf.augmented
    F, n, T = ft.frac_bits, pf.n, ft.n_ticks
    ctl = build_params_qcontroller(pt, pf)
    rng = np.random.default_rng(SEED)
    # one theta per path: the box's vertices, then draws; float32, as the device is given
    box = vertices(p.parameters)
    theta = np.vstack([box, rng.uniform(pf.lower, pf.upper, (PATHS - len(box), box.shape[1]))])
    theta = theta.astype(np.float32)
    X = rng.integers(-(1 << F), 1 << F, (T, PATHS, n))
    stage1 = int(ft.stage_start[1])
    for changes in ({0: theta}, {0: theta[::-1], stage1: theta}, {0: theta, 150: theta[::-1]}):
        U = _steps_per_path(ctl, changes, X, pf)
        spec = QParamSpec(pf, PATHS)
        want = np.empty_like(U)
        for j in range(T):
            if j in changes:
                spec.set(changes[j])
            want[j] = spec.step(j, X[j])
        assert np.array_equal(U, want)
    # against the double law at each theta (set before tick 0): the latch state is tick 0's
    # until stage 1, then stage 1's
    ticks = np.arange(T)
    latch_tick = np.where(ticks < stage1, 0, stage1)
    xlsb = ft.x_lsb[:n]
    worst = 0.0
    for k in range(PATHS):
        exact = law_double_at(pt, ticks, X[:, k] * xlsb, X[latch_tick, k] * xlsb,
                              np.broadcast_to(theta[k].astype(float), (T, theta.shape[1])))
        U = _steps_per_path(ctl, {0: theta[k:k + 1]}, X[:, k:k + 1], pf)[:, 0]
        err = np.abs(U * ft.u_lsb - exact) / pf.bound
        worst = max(worst, float(err.max()))
    assert worst <= 1.0 + 1e-9, worst
    assert worst > 0.2, worst                        # not vacuous


def _steps_per_path(ctl, changes, X, pf):
    """The compiled controller with each path's own theta (rows of changes[j])."""
    T, paths, _ = X.shape
    out = np.empty((T, paths, pf.augmented.dims[1]), np.int64)
    dtype = np.int16 if pf.augmented.arith == "q15" else np.int32
    for k in range(paths):
        U, worst = ctl.steps({j: th[k % len(th)] for j, th in changes.items()}, X[:, k:k + 1],
                             dtype)
        assert worst == 0
        out[:, k] = U[:, 0]
    return out
