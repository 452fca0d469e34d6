"""Fixed-point (Q15/Q31) spline tables (`stospline.table.spline.fixed_point`): the exact integer
evaluation, the fit, the table with re-solved latch maps and its error bound, the certificate.

* `basis_numerators` are the uniform cubic B-splines times 6 D^3, exactly (integers, summing
  to 6 D^3, nonnegative, within the uint32 bound 2^29);
* `evaluate_q` equals an independent evaluation in Python's exact rationals
  (`fractions.Fraction`), at the format's extremes (int32 coefficients, 512-tick spans) too;
* the robot's Q15 and Q31 spline tables: their K, k0, L are the spline's evaluation; every
  row sum within 2^F - 1 (what stsp_init requires); each entry within its stated budget;
  the latch maps re-solved for these gains meet the constraints in float64 before rounding;
  the error bound holds for 200 000 random in-range samples of the host's integer law
  (bit-exact with the C, `test_fixed_point.py`) and is not loose; Q15 within 3 KB;
* bad input: a tolerance out of range names its field; band tables are refused naming
  ``design.table``; the C generator refuses a fixed-point spline (the firmware does not run
  it yet).
"""
from dataclasses import replace
from fractions import Fraction

import numpy as np
import pytest

from stospline.errors import DesignError, ProblemError
from stospline.pipeline import design_problem, fixed_point_spline
from stospline.harness.fixed_point_error import random_q_samples
from stospline.oracle.evaluate import evaluate_table
from stospline.refine.spline_certificate import constraint_residual
from stospline.table.codegen import generate_c
from stospline.table.qformat import _rhu, latch_q, law_double, law_q, row_sums, scaled_entries
from stospline.table.spline.fixed_point import (MAX_SPAN_LOG2, QSplineGains, basis_numerators,
                                     dequantized, evaluate_q, fit_q_spline)
from stospline.table.spline.latch import resolve_latch

ARITHS = ("q15", "q31")


@pytest.mark.parametrize("k", range(MAX_SPAN_LOG2 + 1))
def test_basis_numerators_are_the_uniform_cubic_bsplines(k):
    D = 1 << k
    tau = np.arange(3 * D)
    sigma, P = basis_numerators(k, tau)
    assert np.array_equal(sigma, tau // D)
    P = np.array(P)
    assert np.all(P >= 0) and P.max() <= 2 ** 29 < 2 ** 32
    assert np.all(P.sum(axis=0) == 6 * D ** 3)
    t = (tau % D) / D
    uniform = np.array([(1 - t) ** 3, 3 * t ** 3 - 6 * t ** 2 + 4,
                        -3 * t ** 3 + 3 * t ** 2 + 3 * t + 1, t ** 3])
    np.testing.assert_allclose(P / D ** 3, uniform, rtol=0, atol=1e-12)


def _exact(k, C, shift, tau):
    """g = round half up of sum_r c_r P_r / 2^(3k + s), in exact rationals."""
    D = 1 << k
    sg, d = tau >> k, tau & (D - 1)
    P = [(D - d) ** 3, 4 * D ** 3 - 3 * d * d * (2 * D - d), None, d ** 3]
    P[2] = 6 * D ** 3 - P[0] - P[1] - P[3]
    v = Fraction(sum(int(C[sg + r]) * P[r] for r in range(4)), 2 ** (3 * k + int(shift)))
    return int(np.floor(v + Fraction(1, 2)))


@pytest.mark.parametrize("arith", ARITHS)
def test_evaluation_is_exact_at_the_format_extremes(arith):
    rng = np.random.default_rng(7)
    bits = 16 if arith == "q15" else 32
    top = 2 ** (bits - 1) - 1
    for k in (0, 1, 4, MAX_SPAN_LOG2):
        T = 3 * (1 << k) + 5
        S = -(-T // (1 << k))
        for shift in (1, 7, 30):
            C = rng.integers(-top - 1, top, (2, S + 3), endpoint=True)
            C[0, :] = np.where(np.arange(S + 3) % 2, top, -top - 1)   # the worst alternation
            sp = QSplineGains(span_log2=[k], row_start=[0, 2], col=[0, 1], shift=[shift, 1],
                              coef_start=[0, C.size], coef=C.ravel(), arith=arith, nu=1, nx=2,
                              n_latch=0)
            K, k0, _ = evaluate_q(sp, [0, T])
            for tau in range(T):
                assert K[tau, 0, 0] == _exact(k, C[0], shift, tau)
                assert K[tau, 0, 1] == _exact(k, C[1], 1, tau)
            assert not k0.any()


def test_the_format_refuses_what_the_firmware_would():
    good = dict(span_log2=[3], row_start=[0, 1], col=[0], shift=[4], coef_start=[0, 4],
                coef=[1, 2, 3, 4], arith="q15", nu=1, nx=1, n_latch=0)
    QSplineGains(**good)
    for bad in (dict(span_log2=[MAX_SPAN_LOG2 + 1]), dict(shift=[0]), dict(shift=[31]),
                dict(coef=[1, 2, 3, 2 ** 15]), dict(arith="float32"), dict(shift=[1, 2])):
        with pytest.raises(ValueError):
            QSplineGains(**{**good, **bad})


@pytest.fixture(scope="module")
def robot_spline(robot_problem):
    return design_problem(robot_problem, table="spline")


@pytest.fixture(scope="module")
def qtables(robot_spline):
    return {a: fixed_point_spline(robot_spline, a) for a in ARITHS}


@pytest.mark.parametrize("arith", ARITHS)
def test_the_table_is_its_splines_evaluation_within_the_format(qtables, arith):
    ft, cert = qtables[arith]
    F = ft.frac_bits
    K, k0, L = evaluate_q(ft.spline, ft.stage_start)
    assert np.array_equal(K, ft.K) and np.array_equal(k0, ft.k0) and np.array_equal(L, ft.L)
    law_rows, latch_rows = row_sums(ft.K, ft.k0, ft.L, ft.Lambda, ft.lambda0)
    assert law_rows.max() <= 2 ** F - 1 and latch_rows.max() <= 2 ** F - 1
    # every stored entry within its budget: tolerance * peak + 3 / 2^s + 1/2 LSB
    scaled = scaled_entries(ft.source, F, ft.x_exp, ft.u_exp, ft.v_exp)
    Z = np.concatenate([scaled[0], scaled[1][:, :, None], scaled[2]], axis=2)
    G = np.concatenate([ft.K, ft.k0[:, :, None], ft.L], axis=2)
    sp, start = ft.spline, ft.stage_start.astype(int)
    for s in range(sp.n_stages):
        inputs, cols = sp.entries(s)
        y = Z[start[s]:start[s + 1]][:, inputs, cols]
        g = G[start[s]:start[s + 1]][:, inputs, cols]
        budget = (cert["spline_tolerance"] * np.abs(y).max(axis=0)
                  + 3.0 / 2.0 ** sp.shift[sp.entry_slice(s)] + 0.5)
        assert np.all(np.abs(g - y).max(axis=0) <= budget)
        # entries not stored are below 1/2 LSB over the stage (a per-tick table rounds them to 0)
        rest = np.ones(Z.shape[1:], bool)
        rest[inputs, cols] = False
        assert np.abs(Z[start[s]:start[s + 1]][:, rest]).max(initial=0) < 0.5
        assert not G[start[s]:start[s + 1]][:, rest].any()


@pytest.mark.parametrize("arith", ARITHS)
def test_the_latch_is_resolved_for_the_gains_as_evaluated(robot_problem, qtables, arith):
    ft, cert = qtables[arith]
    law = dequantized(ft)
    Lam, lam0 = resolve_latch(robot_problem, law)
    exact = evaluate_table(robot_problem, replace(law, Lambda=Lam, lambda0=lam0), path=False)
    assert constraint_residual(robot_problem, exact) < 1e-9
    # stored: those maps rounded in the table's v scale
    F = ft.frac_bits
    x_exp, v_exp = ft.x_exp.astype(int), ft.v_exp.astype(int)
    assert np.array_equal(ft.Lambda, _rhu(Lam * np.ldexp(1.0, x_exp[None, None, :]
                                                         - v_exp[None, :, None] + F)))
    assert np.array_equal(ft.lambda0, _rhu(lam0 * np.ldexp(1.0, F - v_exp[None, :])))
    # the certificate's residual is the stored law's, no worse than the per-tick table's
    # (both are the rounding of the latch maps in Q15; float64 rounding in Q31)
    assert cert["constraint_residual"] <= 1.5 * cert["per_tick_constraint_residual"] + 1e-8


@pytest.mark.parametrize("arith", ARITHS)
def test_error_bound_holds_for_the_splines_gains(qtables, arith):
    """|u_fixed - u_double| <= bound at 200 000 random in-range samples of the integer law
    (law_q: bit-exact with the C on these integer gains, test_fixed_point.py), u_double the
    design's own law (its latch maps, not the re-solved ones); the worst sample reaches
    more than a quarter of the bound."""
    ft, cert = qtables[arith]
    rng = np.random.default_rng(20261125)
    tick, ls, t_latch, X, XL = random_q_samples(ft, 200_000, rng)
    V = latch_q(ft, np.maximum(ls, 0), XL)
    U = law_q(ft, tick, X, V)
    err = np.abs(U * ft.u_lsb - law_double(ft, tick, X * ft.x_lsb, XL * ft.x_lsb))
    ratio = err / ft.bound[tick]
    assert ratio.max() <= 1.0
    assert ratio.max() > 0.25
    assert np.all(np.asarray(cert["u_error_bound_lsb"], float) >= ft.bound_lsb.max(axis=0))


def test_certificate_of_the_robot(qtables):
    q15, q31 = qtables["q15"][1], qtables["q31"][1]
    assert q15["flash_bytes"] <= 3 * 1024 and q15["compression_ratio"] > 100
    assert q31["flash_bytes"] < q31["per_tick_flash_bytes"] / 100
    for c in (q15, q31):
        assert c["arith"] in ARITHS and c["entries"] > 0
        assert len(c["spans"]) == len(c["span_ticks"]) == 2
    # Q31 keeps the law: cost within 1e-8, constraints at the float64 floor of the re-solve
    assert abs(q31["excess_over_law"]) < 1e-8 and q31["constraint_residual"] < 1e-8


def test_fit_refuses_what_it_cannot_meet():
    T = 64
    y = np.zeros((T, 1, 1))
    y[::2] = 1000.0                                # a tick-by-tick oscillation
    with pytest.raises(DesignError) as err:
        fit_q_spline((y, np.zeros((T, 1)), np.zeros((T, 1, 0))), [0, T], "q15", 1e-6,
                     max_spans=4)
    assert err.value.field == "design.spline_tolerance"


def test_bad_input(robot_spline):
    with pytest.raises(ProblemError) as err:
        fixed_point_spline(robot_spline, "q15", tolerance=0.5)
    assert err.value.field == "spline_tolerance"
    ft, _ = fixed_point_spline(robot_spline, "q15", tolerance=1e-3)
    # the C of a Q spline table holds the spline (stsp_qspline_t), not the per-tick gains
    _, source = generate_c(ft)
    assert "stsp_qspline_t" in source and f"{ft.name}_K" not in source
    # the per-tick form of the same integer gains is a table the firmware takes too
    _, per_tick = generate_c(replace(ft, spline=None))
    assert f"{ft.name}_K" in per_tick and "stsp_qspline_t" not in per_tick


def test_band_tables_are_refused():
    from conftest import EXAMPLES
    from stospline.problem import load_problem
    d = design_problem(load_problem(EXAMPLES / "robot_bands.toml"), mode="joint")
    with pytest.raises(DesignError) as err:
        fixed_point_spline(d, "q15")
    assert err.value.field == "design.table"


@pytest.mark.parametrize("arith", ARITHS)
def test_short_stages_with_a_partial_last_span(arith):
    """A 25-tick stage whose gain falls steeply to its end (coupled_axes' shape): spans of 16
    leave the second span's last basis functions barely reached, which a plain least squares
    fits with coefficients several times the gain's range (beyond int16); the fit stays within
    the format and its budget (the curvature penalty, or shorter spans)."""
    T = 25
    t = np.arange(T)
    y = -15489.6 * np.cos(0.5 * np.pi * t / 25.5) ** 3
    K = y.reshape(T, 1, 1)
    sp = fit_q_spline((K, np.zeros((T, 1)), np.zeros((T, 1, 0))), [0, T], arith, 1e-5)
    g = evaluate_q(sp, [0, T])[0][:, 0, 0]
    budget = 1e-5 * np.abs(y).max() + 3.0 / 2.0 ** int(sp.shift[0]) + 0.5
    assert np.abs(g - y).max() <= budget
