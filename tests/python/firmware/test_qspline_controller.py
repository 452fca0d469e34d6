"""Fixed-point (Q15/Q31) spline tables through the compiled C (cffi harness; the firmware's
stsp_qspline_t path, firmware/src/stsp_spline.c) on the robot's spline design: commands
bit-exact against the Python model of the integer law with the spline's gains as the host
evaluates them (`qspline.evaluate_q`, the table's K, k0, L), the table's fixed-point error
bound (computed from those gains, `qformat.assemble`) checked over random in-range states and
not loose, the C's CRC equal to the host's, and init refusing the table with one coefficient
changed (CRC) or the per-tick arrays next to it (BAD_DIMS)."""
from dataclasses import replace

import numpy as np
import pytest

import stospline
from stospline.pipeline import fixed_point_spline
from stospline.harness.controller import STATUS, build_controller
from stospline.harness.fixed_point_error import random_q_samples
from stospline.table.format import table_crc32
from stospline.table.qformat import latch_q, law_double, law_q

ARITHS = ["q15", "q31"]
SAMPLES = 200_000


@pytest.fixture(scope="module")
def robot_spline(robot_problem):
    return stospline.design_problem(robot_problem, table="spline")


@pytest.fixture(scope="module")
def qspline(robot_spline):
    return {a: fixed_point_spline(robot_spline, a)[0] for a in ARITHS}


@pytest.fixture(scope="module")
def compiled(qspline):
    return {a: build_controller(ft) for a, ft in qspline.items()}


@pytest.mark.parametrize("arith", ARITHS)
def test_commands_bit_exact_and_within_the_error_bound(qspline, compiled, arith):
    """|u_fixed - u_double| <= the table's bound for random in-range (tick, latch state, state)
    samples through the C's spline path, bit-exact with the integer law of the gains the host
    evaluates from the spline; the worst sample reaches more than half of the bound."""
    ft, ctl = qspline[arith], compiled[arith]
    assert ft.spline is not None and ctl.c_table.spline != ctl.ffi.NULL
    assert ctl.c_table.K == ctl.ffi.NULL
    rng = np.random.default_rng(20261127)
    tick, ls, t_latch, X, XL = random_q_samples(ft, SAMPLES, rng)
    U, status = ctl.pair_steps(t_latch, XL, tick, X)
    assert status.min() >= 0 and set(np.unique(status)) <= {0, 1, 2}
    V = latch_q(ft, np.maximum(ls, 0), XL)
    np.testing.assert_array_equal(U.astype(np.int64), law_q(ft, tick, X, V))
    err = np.abs(U * ft.u_lsb - law_double(ft, tick, X * ft.x_lsb, XL * ft.x_lsb))
    ratio = err / ft.bound[tick]
    assert ratio.max() <= 1.0, f"bound exceeded: {ratio.max()}"
    assert ratio.max() > 0.5, f"bound looser than 2x: worst sample {ratio.max():.3f} of it"


@pytest.mark.parametrize("arith", ARITHS)
def test_c_crc_equals_the_host_crc_and_init_refuses_changes(qspline, compiled, arith):
    ft, ctl = qspline[arith], compiled[arith]
    assert ctl.lib.stsp_table_crc32(ctl.c_table) == table_crc32(ft)
    coef = ft.spline.coef.copy()
    coef[len(coef) // 2] += 1
    changed = replace(ft, spline=replace(ft.spline, coef=coef))
    bad = build_controller(changed)
    # the C of the changed table carries its own CRC, which the host computes too ...
    assert bad.lib.stsp_table_crc32(bad.c_table) == table_crc32(changed) != table_crc32(ft)
    # ... and with the original table's CRC it is refused
    c = bad.ffi.new("stsp_ctrl_t *")
    t = bad.ffi.new("stsp_table_t *", bad.c_table[0])
    t.crc32 = table_crc32(ft)
    assert bad.lib.stsp_init(c, t) == STATUS["ERR_BAD_CRC"]
    t.crc32 = bad.c_table.crc32
    assert bad.lib.stsp_init(c, t) == STATUS["OK"]
    t.K = ctl.ffi.cast("const stsp_scalar_t *", t.Lambda)
    assert bad.lib.stsp_init(c, t) == STATUS["ERR_BAD_DIMS"]
