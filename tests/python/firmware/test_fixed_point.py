"""Fixed-point (Q15/Q31) variants through the compiled C (cffi harness) on the robot design:
bit-exact against the Python model of the integer law, the documented error bound over 10^6
random in-range states, the float->Q conversion, closed-loop tracking, CLI."""
import json
import subprocess
import sys

import numpy as np
import pytest

from stospline.table.qformat import latch_q, law_double, law_q, quantize_table
from stospline.harness.fixed_point_error import noise_free_closed_loop, random_q_samples
from stospline.harness.controller import STATUS, build_controller
from stospline.pipeline import double_table, fixed_point_table
from stospline.table.format import table_crc32

from conftest import EXAMPLES

ARITHS = ["q15", "q31"]
SAMPLES = 1_000_000


@pytest.fixture(scope="module")
def fixed(robot_zoh):
    return {a: fixed_point_table(robot_zoh, a) for a in ARITHS}


@pytest.fixture(scope="module")
def compiled(fixed):
    return {a: build_controller(ft) for a, ft in fixed.items()}


@pytest.mark.parametrize("arith", ARITHS)
def test_error_bound_over_a_million_states(fixed, compiled, arith):
    """|u_fixed - u_double| <= the table's bound for 10^6 random in-range (tick, latch state,
    state) samples through the C, bit-exact with the Python model of the integer law; and the
    bound is not loose: the worst sample reaches more than half of it."""
    ft, ctl = fixed[arith], compiled[arith]
    rng = np.random.default_rng(20260601)
    tick, ls, t_latch, X, XL = random_q_samples(ft, SAMPLES, rng)
    U, status = ctl.pair_steps(t_latch, XL, tick, X)
    assert status.min() >= 0 and set(np.unique(status)) <= {0, 1, 2}
    V = latch_q(ft, np.maximum(ls, 0), XL)
    np.testing.assert_array_equal(U.astype(np.int64), law_q(ft, tick, X, V))
    err = np.abs(U * ft.u_lsb - law_double(ft, tick, X * ft.x_lsb, XL * ft.x_lsb))
    ratio = err / ft.bound[tick]
    assert ratio.max() <= 1.0, f"bound exceeded: {ratio.max()}"
    assert err.max(axis=0).max() <= ft.bound.max()
    assert ratio.max() > 0.5, f"bound looser than 2x: worst sample {ratio.max():.3f} of it"


@pytest.mark.parametrize("arith", ARITHS)
def test_c_accepts_the_python_crc_and_scales(fixed, compiled, arith):
    ft, ctl = fixed[arith], compiled[arith]
    assert ctl.lib.stsp_table_crc32(ctl.c_table) == table_crc32(ft)
    assert ctl.c_table.scalar_kind == {"q15": 2, "q31": 3}[arith]
    assert [ctl.c_table.x_exp[j] for j in range(4)] == ft.x_exp.tolist()
    assert [ctl.c_table.u_exp[i] for i in range(2)] == ft.u_exp.tolist()


@pytest.mark.parametrize("arith", ARITHS)
def test_state_conversion_saturates_and_reports(fixed, compiled, arith):
    """stsp_state_to_q: round half up, saturate at the Q range with STSP_WARN_STATE_CLAMPED,
    NaN/Inf -> STSP_ERR_NONFINITE_STATE with zeros; bit-exact with numpy on random floats."""
    ft, ctl = fixed[arith], compiled[arith]
    ffi, lib = ctl.ffi, ctl.lib
    F = ft.frac_bits
    rng = np.random.default_rng(7)
    ctrl = ctl.new_instances(1)
    n = ft.dims[0]
    xq = ffi.new("stsp_scalar_t[]", n)
    span = np.ldexp(1.0, ft.x_exp.astype(int))
    for _ in range(2000):
        x = (rng.uniform(-1.3, 1.3, n) * span).astype(np.float32)
        st = lib.stsp_state_to_q(ctrl, ffi.cast("const float *", ffi.from_buffer(x)), xq)
        exact = np.floor(x.astype(float) / ft.x_lsb + 0.5)
        expect = np.clip(exact, -(1 << F), (1 << F) - 1)
        assert [xq[j] for j in range(n)] == expect.astype(np.int64).tolist()
        assert st == (STATUS["WARN_STATE_CLAMPED"] if np.any(expect != exact) else STATUS["OK"])
    for bad in (np.nan, np.inf, -np.inf):
        x = np.zeros(n, np.float32)
        x[1] = bad
        st = lib.stsp_state_to_q(ctrl, ffi.cast("const float *", ffi.from_buffer(x)), xq)
        assert st == STATUS["ERR_NONFINITE_STATE"] and [xq[j] for j in range(n)] == [0] * n


def test_q31_tracks_float32_in_closed_loop(robot_zoh, robot_problem, fixed, compiled):
    """Noise-free closed loop of the robot (no Monte Carlo): every Q31 command is within the
    table's bound of the double-precision law at the state it was given, and the Q31 path stays
    within 1e-6 of the float32 controller's path (whose own float32 rounding is ~1e-7 here) and
    ends on the same goal. Q15 obeys its bound too and ends within 1e-3 of the float32 path."""
    f32 = build_controller(robot_zoh.table)
    xf, uf, _ = noise_free_closed_loop(robot_problem, f32, lambda x: x.astype(np.float32),
                                       lambda U: U.astype(float))
    for arith, tol in (("q31", 1e-6), ("q15", 1e-3)):
        ft, ctl = fixed[arith], compiled[arith]
        F = ft.frac_bits

        def to_q(x, ft=ft, F=F, ctl=ctl):
            q = np.clip(np.floor(x / ft.x_lsb + 0.5), -(1 << F), (1 << F) - 1)
            return q.astype(ctl.dtype)

        xq, uq, given = noise_free_closed_loop(robot_problem, ctl, to_q,
                                               lambda U, ft=ft: U * ft.u_lsb)
        ticks = np.arange(ft.n_ticks)
        ls = ft.latch_stage(ft.stage_of_tick(ticks))
        x_latch = given[ft.stage_start[np.maximum(ls, 0)]] * ft.x_lsb
        ud = law_double(ft, ticks, given * ft.x_lsb, x_latch)
        assert np.all(np.abs(uq - ud) <= ft.bound), arith
        assert np.abs(xq - xf).max() < tol, (arith, np.abs(xq - xf).max())


def test_quantizer_rejects_bad_input(robot_zoh):
    src = double_table(robot_zoh)
    with pytest.raises(ValueError, match="arith"):
        quantize_table(src, "q7", np.ones(4))
    with pytest.raises(ValueError, match="x_range"):
        quantize_table(src, "q15", np.array([1.0, 0.0, 1.0, 1.0]))
    with pytest.raises(ValueError, match="exponent"):
        quantize_table(src, "q15", np.full(4, 1e30))


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "stospline.cli", *args],
                          capture_output=True, text=True)


def test_cli_arith_option_and_key(tmp_path):
    r = _cli("design", str(EXAMPLES / "robot_corridor.toml"), "--arith", "q7", "--out",
             str(tmp_path / "o"))
    assert r.returncode == 2 and "--arith" in r.stderr and not (tmp_path / "o").exists()
    text = (EXAMPLES / "robot_corridor.toml").read_text()
    bad = tmp_path / "bad.toml"
    bad.write_text(text + '\n[design]\narith = "q16"\n' if "[design]" not in text
                   else text.replace("[design]", '[design]\narith = "q16"'))
    r = _cli("design", str(bad), "--out", str(tmp_path / "o"))
    assert r.returncode == 2 and "design.arith" in r.stderr, r.stderr
    r = _cli("design", str(EXAMPLES / "robot_corridor.toml"), "--arith", "q31", "--json")
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)["fixed"]
    assert s["arith"] == "q31" and len(s["u_error_bound"]) == 2
