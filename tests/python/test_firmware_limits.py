"""Actuator limits in the table format (format 2): GainTable defaults, validation, the CRC that
Python and C compute identically, and saturation through the compiled firmware."""
from dataclasses import replace

import numpy as np
import pytest

from stospline.harness import STATUS, build_controller
from stospline.tables import F32_MAX, FORMAT_VERSION, GainTable, table_crc32


def _table_a(**limits) -> GainTable:
    """The hand-made table of tests/c/test_controller.c (nx = 2, nu = 1, n_latch = 2)."""
    f = lambda v, shape: np.array(v, np.float32).reshape(shape)  # noqa: E731
    return GainTable(
        "table_a", 10, 0.0, np.array([0, 3, 5], np.uint32), np.array([1, 2], np.uint16),
        f([0.5, -1.0, 0.6, -1.1, 0.7, -1.2, 0.8, -1.3, 0.9, -1.4], (5, 1, 2)),
        f([0.1, 0.2, 0.3, 0.4, 0.5], (5, 1)),
        f([2.0, 0.0, 2.5, 0.0, 3.0, 0.0, 1.0, -1.0, 1.5, -1.5], (5, 1, 2)),
        f([1.0, 2.0, 0.0, 0.0, -1.0, 0.5, 0.25, 3.0], (2, 2, 2)),
        f([-0.5, 0.0, 1.0, -2.0], (2, 2)), "", **limits)


def test_default_limits_are_unlimited_and_pinned_crc():
    t = _table_a()
    assert FORMAT_VERSION == 3
    np.testing.assert_array_equal(t.u_min, np.float32([-F32_MAX]))
    np.testing.assert_array_equal(t.u_max, np.float32([F32_MAX]))
    assert not t.limited
    # The same constant is pinned in tests/c/test_controller.c (TABLE_A_CRC32).
    assert table_crc32(t) == 0x144FE504
    assert table_crc32(_table_a(u_min=[-1.0], u_max=[1.0])) != table_crc32(t)


@pytest.mark.parametrize("limits, message", [
    (dict(u_min=[0.5]), "u_min <= 0 <= u_max"),
    (dict(u_max=[-0.5]), "u_min <= 0 <= u_max"),
    (dict(u_min=[np.nan]), "finite"),
    (dict(u_max=[np.inf]), "finite"),
    (dict(u_min=[-1.0, -1.0]), "one entry per input"),
])
def test_invalid_limits_are_refused(limits, message):
    with pytest.raises(ValueError, match=message):
        _table_a(**limits)


def test_limited_robot_table_saturates_in_c(robot):
    """Limits through codegen and the compiled firmware: the C CRC equals Python's, the
    commands stay within the limits, saturated ticks say so, and the others equal the
    unlimited controller's commands bit for bit."""
    lo, hi = np.float32([-1.0, -0.5]), np.float32([1.0, 0.5])
    limited = replace(robot.table, u_min=lo, u_max=hi)
    assert limited.limited
    ctl = build_controller(limited)
    ref = build_controller(robot.table)
    assert ctl.lib.stsp_table_crc32(ctl.c_table) == table_crc32(limited) == ctl.c_table.crc32
    rng = np.random.default_rng(11)
    X = rng.normal(size=(256, 4)) * 4
    step, step_ref = ctl.stepper(256), ref.stepper(256)
    saw_saturation = False
    for j in [0, 1, 2, 2999, 3000, 3001, 5999]:
        U, status = step(j, X)
        U_ref, status_ref = step_ref(j, X)
        U, status, U_ref = U.copy(), status.copy(), U_ref.copy()
        assert np.all((U >= lo) & (U <= hi))
        sat = status == STATUS["WARN_SATURATED"]
        saw_saturation |= bool(sat.any())
        outside = np.any((U_ref < lo) | (U_ref > hi), axis=1)
        np.testing.assert_array_equal(sat, outside)
        np.testing.assert_array_equal(U[~sat], U_ref[~sat])
        np.testing.assert_array_equal(U[sat], np.clip(U_ref[sat], lo, hi))
        masks = np.array([step.instances[i].sat_mask for i in np.flatnonzero(sat)])
        expect = ((U_ref[sat] < lo) | (U_ref[sat] > hi)) @ np.array([1, 2])
        np.testing.assert_array_equal(masks, expect)
        assert np.all(status[~sat] == status_ref[~sat])
    assert saw_saturation
