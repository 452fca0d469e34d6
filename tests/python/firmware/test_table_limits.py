"""Actuator limits in the table format (format 2): GainTable defaults, validation, the CRC that
Python and C compute identically, and saturation through the compiled firmware."""
from dataclasses import replace

import numpy as np
import pytest

from stospline.harness.controller import STATUS, build_controller
from stospline.table.format import F32_MAX, FORMAT_VERSION, GainTable, table_crc32


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
    assert FORMAT_VERSION == 5
    np.testing.assert_array_equal(t.u_hold, np.float32([0.0]))
    np.testing.assert_array_equal(t.u_min, np.float32([-F32_MAX]))
    np.testing.assert_array_equal(t.u_max, np.float32([F32_MAX]))
    assert not t.limited
    # The same constant is pinned in tests/c/test_controller.c (TABLE_A_CRC32).
    assert table_crc32(t) == 0x6C34DDB7
    assert table_crc32(_table_a(u_min=[-1.0], u_max=[1.0])) != table_crc32(t)
    assert table_crc32(_table_a(u_hold=[0.5])) != table_crc32(t)      # the CRC covers u_hold


@pytest.mark.parametrize("limits, message", [
    (dict(u_min=[0.5]), "u_min <= u_hold <= u_max"),
    (dict(u_max=[-0.5]), "u_min <= u_hold <= u_max"),
    (dict(u_min=[0.5], u_hold=[0.25]), "u_min <= u_hold <= u_max"),
    (dict(u_hold=[np.nan]), "finite"),
    (dict(u_min=[np.nan]), "finite"),
    (dict(u_max=[np.inf]), "finite"),
    (dict(u_min=[-1.0, -1.0]), "one entry per input"),
])
def test_invalid_limits_are_refused(limits, message):
    with pytest.raises(ValueError, match=message):
        _table_a(**limits)


def test_safe_command_through_c(robot):
    """A minimum command (u_min > 0) with a safe command u_hold inside the limits: the C
    controller accepts the table (its CRC equals Python's), and every refused step (NaN state,
    a tick past the plan) commands u_hold, bit for bit."""
    lo, hi, hold = np.float32([0.5, -2.0]), np.float32([9.0, 2.0]), np.float32([4.905, 0.25])
    table = replace(robot.table, u_min=lo, u_max=hi, u_hold=hold)
    ctl = build_controller(table)
    assert ctl.lib.stsp_table_crc32(ctl.c_table) == table_crc32(table) == ctl.c_table.crc32
    step = ctl.stepper(2)
    X = np.float32([[np.nan, 0, 1, 0], [-5, 0, 1, 0]])
    U, status = step(0, X)
    assert status[0] == STATUS["ERR_NONFINITE_STATE"] and status[1] >= 0
    np.testing.assert_array_equal(U[0], hold)
    assert np.all((U[1] >= lo) & (U[1] <= hi))
    U, status = step(table.n_ticks, X)
    assert np.all(status == STATUS["ERR_TICK_RANGE"])
    np.testing.assert_array_equal(U, np.stack([hold, hold]))


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


# ---------------------------------------------------------------------------------------
# Dimension limits: the designer refuses at parse time what stsp_init
# refuses, naming the key that causes it; limits.py agrees with the firmware's header.

from conftest import REPO  # noqa: E402
from stospline import limits  # noqa: E402
from stospline.table import qformat as fixed
from stospline.table import format as tables
from stospline.pipeline import design_problem  # noqa: E402
from stospline.problem import ProblemError, parse_problem  # noqa: E402


def test_limits_module_agrees_with_the_header():
    """One source: the Python constants are the header's defaults (a header change fails
    here), and the modules that used their own copies take them from limits.py."""
    found = limits.read_header_limits(REPO / "firmware" / "include")
    assert set(found) == set(limits.HEADER_MACROS), "a limit macro is missing from the header"
    assert found == {name: getattr(limits, name) for name in limits.HEADER_MACROS}
    assert tables.BANDQP_MAX == limits.BANDQP_MAX and fixed.EXP_MAX == limits.Q_EXP_MAX
    # The 32-bit offset bound limits.py applies is the one stsp_check_dims applies.
    src = (REPO / "firmware" / "src" / "stsp_table.c").read_text()   # stsp_check_dims
    assert ("t->n_ticks > (UINT32_MAX / ((uint32_t)t->nu * ((uint32_t)t->nx + t->n_latch)))"
            in src)


def _zero_table(n: int, m: int, p: int, stages: int) -> GainTable:
    f = lambda *shape: np.zeros(shape, np.float32)  # noqa: E731
    np_ = np.zeros(stages, np.uint16)
    np_[0] = p
    return GainTable("lim", 10, 0.0, np.arange(stages + 1, dtype=np.uint32), np_,
                     f(stages, m, n), f(stages, m), f(stages, m, p), f(stages, p, n),
                     f(stages, p), "")


def _c_init(ctl, t: GainTable) -> int:
    """stsp_init of the compiled firmware on table `t` (built in cffi memory)."""
    ffi, keep = ctl.ffi, []

    def ptr(ctype, a, dtype):
        a = np.ascontiguousarray(a, dtype).reshape(-1)
        a = a if a.size else np.zeros(1, dtype)
        keep.append(a)
        return ffi.cast(f"{ctype} *", ffi.from_buffer(a))

    c = ffi.new("stsp_table_t *")
    n, m, p = t.dims
    c.magic, c.format_version, c.scalar_kind = 0x53545350, FORMAT_VERSION, 1
    c.nx, c.nu, c.n_latch, c.n_stages, c.n_ticks, c.tick_hz = (n, m, p, t.n_stages,
                                                               t.n_ticks, t.tick_hz)
    c.stage_start = ptr("uint32_t", t.stage_start, np.uint32)
    c.stage_n_latch = ptr("uint16_t", t.stage_n_latch, np.uint16)
    for name in ("K", "k0", "L", "Lambda", "lambda0", "u_min", "u_max", "u_hold"):
        setattr(c, name, ptr("float", getattr(t, name), np.float32))
    c.crc32 = table_crc32(t)
    ctrl = ffi.new("stsp_ctrl_t *")
    return int(ctl.lib.stsp_init(ctrl, c))


@pytest.fixture(scope="module")
def generic_controller(robot):
    """The firmware's generic build (any table within the STSP_MAX_* limits)."""
    return build_controller(robot.table, fixed_shape=False)


@pytest.mark.parametrize("dims, at", [((limits.MAX_NX, 1, 0, 1), 0),
                                      ((1, limits.MAX_NU, 0, 1), 1),
                                      ((limits.MAX_LATCH, 1, limits.MAX_LATCH, 1), 2),
                                      ((1, 1, 0, limits.MAX_STAGES), 3)])
def test_firmware_takes_the_limits_and_refuses_one_more(generic_controller, dims, at):
    """(nx, nu, n_latch, n_stages) at a limit: stsp_init of the generic build accepts; one
    more: it refuses, and so does limits.check_table."""
    assert _c_init(generic_controller, _zero_table(*dims)) == STATUS["OK"]
    limits.check_table(_zero_table(*dims))
    more = list(dims)
    more[at] += 1
    if at == 2:
        more[0] += 1   # a designed table has n_latch <= nx: test the latch limit alone
    assert _c_init(generic_controller, _zero_table(*more)) == STATUS["ERR_BAD_DIMS"]
    with pytest.raises(ProblemError):
        limits.check_table(_zero_table(*more))


def _doc(n=2, m=1, knots=1, rows=1, tick_hz=10, **extra) -> dict:
    """n integrators, the first m driven; knot k fixes `rows` states from state k mod m on."""
    eye = lambda r, c, s=0: [[float(j == (i + s) % c) for j in range(c)]  # noqa: E731
                             for i in range(r)]
    doc = {"name": "lim", "x0": [0.0] * n, "tick_hz": tick_hz,
           "dynamics": {"A": [[0.0] * n] * n, "B": eye(n, m)}, "cost": {"R": eye(m, m)},
           "knots": [{"t": float(k + 1), "constraint": {"C": eye(rows, n, k % m),
                                                        "value": [1.0] * rows}}
                     for k in range(knots)]}
    doc.update(extra)
    return doc


@pytest.mark.parametrize("doc, field, words", [
    (_doc(n=33), "x0", "STSP_MAX_NX"),
    (_doc(m=17, n=17), "dynamics.B", "STSP_MAX_NU"),
    (_doc(knots=300), "knots", "STSP_MAX_STAGES"),
    (_doc(n=17, rows=17), "knots[0].constraint.C", "STSP_MAX_LATCH"),
    # 2^31 ticks x 1 input x (2 states + 1 latched): offsets beyond 32 bits.
    (_doc(tick_hz=2**31), "tick_hz", "32-bit offsets"),
    # 2^28 ticks: K takes 2^28 x 2 x 4 bytes = 2 GiB, one more than a 32-bit target's array.
    (_doc(tick_hz=2**28), "tick_hz", "bytes"),
    # A region grid adding a band every tick: 1000 stages.
    (_doc(tick_hz=1000, regions=[{"t": [0.0, 1.0], "every": 0.001, "C": [[1.0, 0.0]],
                                  "lower": [-9.0], "upper": [9.0]}]), "regions",
     "STSP_MAX_STAGES"),
])
def test_parse_refuses_what_the_firmware_refuses(doc, field, words):
    with pytest.raises(ProblemError) as exc:
        parse_problem(doc)
    assert exc.value.field == field and words in exc.value.reason


@pytest.mark.parametrize("doc", [_doc(n=limits.MAX_NX), _doc(n=16, m=limits.MAX_NU),
                                 _doc(knots=limits.MAX_STAGES),
                                 _doc(n=16, rows=limits.MAX_LATCH), _doc(tick_hz=2**27)])
def test_parse_accepts_the_limits(doc):
    parse_problem(doc)


def test_joint_mode_too_wide_is_refused_before_the_design():
    """18 one-row knots on 18 states: stage-wise latches 1, joint 18 > STSP_MAX_LATCH; refused
    at once (the design ran for minutes, and stsp_init refused its table)."""
    import time
    problem = parse_problem(_doc(n=18, m=16, knots=18, rows=1, tick_hz=1))
    limits.check_mode(problem, "stagewise")   # 1 row per stage: fine
    start = time.perf_counter()
    with pytest.raises(ProblemError) as exc:
        design_problem(problem, mode="joint")
    assert time.perf_counter() - start < 1.0
    assert exc.value.field == "design.mode" and "STSP_MAX_LATCH" in exc.value.reason
