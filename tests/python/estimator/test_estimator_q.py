"""The Q15/Q31 estimator controller (`estimator.qformat`, stsp_est_step in a fixed-point build):
the scales fit the accumulator, the shipped Q15 and Q31 tables are the generator's, the compiled C
equals the integer reference bit for bit (readings, missing readings, skips, saturation), and
the error against the double loop stays within the per-tick bound, which is not loose by more
than a modest factor."""
import numpy as np
import pytest

from conftest import EXAMPLES, GAINS
from stospline import load_problem
from stospline.estimator.filter_kernel import with_table_filter
from stospline.estimator.oracle import evaluate_estimator
from stospline.estimator.qformat import (ACC_BITS, QEstimatorSpec, error_bound, estimator_q_c,
                                         estimator_q_crc32, estimator_state_range,
                                         measured_error, quantize_estimator)
from stospline.harness.estimator_loop import build_estimator_q
from stospline.pipeline import design_problem, double_table, fixed_point_table

TICKS = 1000            # the bound and the comparison on the first 50 samples (it is causal)


@pytest.fixture(scope="module")
def sensor_loop():
    problem = load_problem(EXAMPLES / "robot_position_sensor.toml")
    d = design_problem(problem)
    exact = double_table(d)
    loop = with_table_filter(evaluate_estimator(problem, exact, path=True), problem, d.table)
    return problem, d, loop, estimator_state_range(problem, exact, loop)


@pytest.fixture(scope="module", params=["q15", "q31"])
def q_tables(request, sensor_loop):
    problem, d, loop, x_range = sensor_loop
    ft = fixed_point_table(d, request.param, x_range=x_range)
    return problem, ft, quantize_estimator(problem, ft, loop)


def test_rows_fit_the_accumulator_and_ranges_cover_the_loop(q_tables, sensor_loop):
    problem, ft, qt = q_tables
    F, n, m, p = ft.frac_bits, qt.nx, qt.nu, qt.ny
    lim, qmax = 1 << (ACC_BITS - F), (1 << F) - 1
    k = qt.shift.astype(int)
    assert 1 <= k.min() and k.max() <= ACC_BITS - F and np.all(qt.e_exp <= qt.y_exp)
    for a in (qt.model, qt.C, qt.gain, qt.xhat0):
        assert np.abs(a).max() <= qmax + 1
    up = k[:p] + qt.y_exp.astype(int) - qt.e_exp.astype(int)
    assert np.all(np.abs(qt.C).sum(1) + (1 << up) <= lim)
    assert np.all(np.abs(qt.gain).sum(2) + (1 << k[p:p + n])[None, :] <= lim)
    assert np.all(np.abs(qt.model).sum(2) + (1 << k[p + n:])[None, :] <= lim)
    # the state scales cover the loop's state and estimate, which the full-state range does not
    _, d, loop, x_range = sensor_loop
    assert np.all(np.ldexp(1.0, ft.x_exp.astype(int)) >= x_range)
    assert np.all(np.ldexp(1.0, qt.y_exp.astype(int)) >= qt.y_range)
    assert np.all(np.ldexp(1.0, qt.e_exp.astype(int)) >= np.minimum(qt.e_range, qt.y_range))


def test_shipped_tables_are_these(q_tables):
    """gains/robot_position_sensor_<arith>.c holds this filter (same scales, entries and
    CRC)."""
    problem, ft, qt = q_tables
    header, source = estimator_q_c(qt, ft.name)
    assert source in (GAINS / f"robot_position_sensor_{ft.arith}.c").read_text()
    assert header.strip() in (GAINS / f"robot_position_sensor_{ft.arith}.h").read_text()


def _readings(rng, spec, qt, ft, paths):
    """Integer readings near the prediction (its position rows) with noise of a few innovation
    ranges' hundredths."""
    sh = ft.x_exp.astype(int)[[0, 2]] - qt.y_exp.astype(int)
    near = np.floor(np.ldexp(spec.xhat[:, [0, 2]].astype(float), sh))
    noise = np.ldexp(rng.standard_normal((paths, qt.ny)) * 0.02,
                     ft.frac_bits - qt.y_exp.astype(int))
    return (near + np.round(noise)).astype(np.int64)


def test_c_equals_the_integer_reference_bit_for_bit(q_tables):
    """600 ticks of 4 paths: noisy readings, a missing one (y NULL), a saturating one (the
    status says so), a skip of 7 ticks (a sample lost); commands and predictions bit for bit."""
    problem, ft, qt = q_tables
    ffi, lib = build_estimator_q(ft, qt)
    assert lib.harness_q_crc(0) == lib.harness_q_crc(1) == estimator_q_crc32(qt)
    paths, F = 4, ft.frac_bits
    inst = ffi.new("stsp_est_t[]", paths)
    assert lib.harness_q_init(inst, paths) == 0
    spec = QEstimatorSpec(ft, qt, paths)
    rng = np.random.default_rng(34)
    U, X = np.zeros((paths, qt.nu), np.int32), np.zeros((paths, qt.nx), np.int32)
    S = np.zeros(paths, np.intc)
    seen = set()
    for j in [t for t in range(600) if not 95 <= t < 102]:
        Y = _readings(rng, spec, qt, ft, paths) if j % qt.every == 0 else None
        if j == 200:
            Y = None
        if j == 40:
            Y[1] = [(1 << F) - 1, -(1 << F)]
        Ur, clamped = spec.step(j, Y)
        lib.harness_q_step(inst, paths, j, ffi.NULL if Y is None else ffi.from_buffer(
            "int32_t[]", np.ascontiguousarray(Y, np.int32)), ffi.from_buffer("int32_t[]", U),
            ffi.from_buffer("int[]", S), ffi.from_buffer("int32_t[]", X))
        assert np.array_equal(U, Ur) and np.array_equal(X, spec.xhat), j
        seen.update(int(s) for s in S)
        assert np.array_equal(S[clamped], np.full(clamped.sum(), 4)), j   # STATE_CLAMPED
    assert {0, 1, 4, 6} <= seen          # OK, TICK_SKIPPED, STATE_CLAMPED, NO_MEASUREMENT


def _measured(ft, qt, loop, ticks, paths=16):
    x_err, u_err, clamped = measured_error(ft, qt, loop.innovation_cov, ticks, paths=paths)
    assert not clamped
    return x_err, u_err


def test_error_within_the_bound_and_the_bound_not_loose(q_tables, sensor_loop):
    """Q loop vs the double loop on the same readings: every tick's error below the bound; the
    largest error over the ticks is at least 1/40 of the largest bound (measured: Q15 about
    1/5, Q31 about 1/20)."""
    problem, ft, qt = q_tables
    loop = sensor_loop[2]
    xb, ub = error_bound(ft, qt, ticks=TICKS)
    ex, eu = _measured(ft, qt, loop, TICKS)
    assert np.all(ex <= xb) and np.all(eu <= ub)
    ratio_x, ratio_u = ex.max() / xb.max(), eu.max() / ub.max()
    print(f"{ft.arith}: max error / max bound  x̂ {ratio_x:.3f}  u {ratio_u:.3f}")
    assert ratio_x > 1 / 40 and ratio_u > 1 / 40


def test_a_bound_without_the_prediction_rounding_fails(q_tables, sensor_loop, monkeypatch):
    """Planted fault: the bound computed as if x̂'s roundings (half an LSB per sum) were exact
    is exceeded by the measured error: the comparison above can fail."""
    problem, ft, qt = q_tables
    if ft.arith != "q15":
        pytest.skip("one arithmetic is enough")
    import stospline.estimator.qformat as qf
    real = qf.QEstimatorTable.lsb

    def lsb(self, exps):
        out = real(self, exps)
        return out * 0 if np.array_equal(exps, self.x_exp) else out
    monkeypatch.setattr(qf.QEstimatorTable, "lsb", lsb)
    planted, _ = error_bound(ft, qt, ticks=200)
    monkeypatch.undo()
    ex, _ = _measured(ft, qt, sensor_loop[2], 200, paths=8)
    assert np.any(ex > planted)


@pytest.mark.parametrize("arith, header", [("q15", "estimator_q_expected.h"),
                                           ("q31", "estimator_q31_expected.h")])
def test_the_c_tests_expected_values_are_the_references(arith, header):
    """tests/c/estimator_q_expected.h and estimator_q31_expected.h (what test_estimator.c checks
    its Q15 and Q31 builds against) are what the integer reference gives today: regenerate with
    tests/c/estimator_q_reference.py [--arith q31]."""
    import runpy
    from conftest import REPO
    expected = runpy.run_path(str(REPO / "tests" / "c" / "estimator_q_reference.py"))["expected"]
    assert expected(arith) == (REPO / "tests" / "c" / header).read_text()
