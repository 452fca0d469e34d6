"""The table layer's compiled kernels (`stospline.table.kernels`): `affine_compose` and
`affine_compose_gains`, the composition of a stage's affine tick maps (given as blocks, or
by the law's gains without forming the blocks), which every latch re-solve of a spline table
uses,
and `qspline_stage`, the exact evaluation of a fixed-point spline stage and its error, which
the Q15/Q31 fit runs for every span length it tries.

* It composes as the numpy reference does (`spline_latch._affine_product_numpy`, pairwise
  products): to round-off on random blocks of the shapes the tables use, exactly on one
  block, and with the constant columns carried (an affine map, not a linear one).
* It refuses blocks it does not take; ``STOSPLINE_TABLE_KERNEL=numpy`` turns it off, and a
  host that cannot build it falls back to the numpy products with a warning.
* The spline tables are the same bits with the kernel and with the numpy products.
* `qspline_stage` gives the numpy reference's integers (`qspline._stage_gains`) and errors
  bit for bit, rounding negative sums as floor(. + 1/2) too, at the format's extremes; with
  an allowance it stops at a miss (NaN included) and passes what is within, equality
  included; it refuses what the format does not hold. The Q15/Q31 spline tables, and the
  message of a stage that misses, are the same with the kernel and with numpy.
"""
import numpy as np
import pytest

import stospline
from stospline.design.varying import mean_maps
from stospline.table.spline import spline_table
from stospline.table import kernels
from stospline.table.spline import fixed_point as qspline
from stospline.table.spline import latch as spline_latch
from stospline.table.format import table_of

from conftest import EXAMPLES


def _blocks(rng, T, n, d):
    P = rng.normal(size=(T, n, d)) * 0.1
    P[:, :, :n] += 0.99 * np.eye(n)
    return P


@pytest.mark.parametrize("T,n,d", [(1, 4, 9), (2, 4, 9), (25, 6, 13), (6000, 4, 9),
                                   (333, 3, 3), (64, 8, 17)])
def test_the_kernel_composes_as_the_numpy_products(T, n, d):
    P = _blocks(np.random.default_rng(T * 100 + n), T, n, d)
    got = kernels.affine_compose(P)
    assert got is not None, "the table kernel did not build on this host"
    want = spline_latch._affine_product_numpy(P)
    if T == 1:
        np.testing.assert_array_equal(got, P[0])
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * np.abs(want).max())


def test_the_constant_columns_are_carried():
    # Two ticks of x+ = x + 1 (n = 1, d = 2: [A | c]): the composition is x + 2, and with a
    # third tick x+ = 2 x, 2 x + 4.
    P = np.array([[[1.0, 1.0]], [[1.0, 1.0]], [[2.0, 0.0]]])
    np.testing.assert_array_equal(kernels.affine_compose(P[:2]), [[1.0, 2.0]])
    np.testing.assert_array_equal(kernels.affine_compose(P), [[2.0, 4.0]])


@pytest.mark.parametrize("T,n,d,K", [(1, 4, 9, 12), (2, 4, 9, 12), (6000, 4, 9, 14),
                                     (25, 6, 13, 20), (40, 2, 3, 0)])
def test_the_kernel_composes_a_law_given_by_its_gains(T, n, d, K):
    # Blocks base + gains[t, k] vec[k] in column col[k]: composed without forming them, the
    # same bits as composing the blocks `_tick_blocks` forms (which the numpy path does).
    rng = np.random.default_rng(T + K)
    base = rng.normal(size=(n, d)) * 0.1
    base[:, :n] += 0.99 * np.eye(n)
    col = rng.integers(0, d, size=K)
    vec = rng.normal(size=(K, n)) * 0.01
    g = rng.normal(size=(T, K))
    got = kernels.affine_compose_gains(base, col, vec, g)
    blocks = spline_latch._tick_blocks(base, col, vec, g)
    np.testing.assert_array_equal(got, kernels.affine_compose(blocks))
    want = spline_latch._affine_product_numpy(blocks)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * np.abs(want).max())
    if T == 1:
        np.testing.assert_array_equal(got, blocks[0])


def test_a_law_given_by_its_gains_is_refused_where_it_does_not_fit():
    base, vec, g = np.eye(2, 3), np.ones((1, 2)), np.ones((4, 1))
    with pytest.raises(ValueError, match="not composable"):
        kernels.affine_compose_gains(base, np.array([3]), vec, g)           # column >= d
    with pytest.raises(ValueError, match="not composable"):
        kernels.affine_compose_gains(base, np.array([-1]), vec, g)
    with pytest.raises(ValueError, match="not composable"):
        kernels.affine_compose_gains(base, np.array([0]), vec, np.ones((0, 1)))   # no tick
    with pytest.raises(ValueError, match="for 1 gains"):
        kernels.affine_compose_gains(base, np.array([0, 1]), vec, g)


def test_blocks_it_does_not_take_are_refused():
    with pytest.raises(ValueError, match="not composable"):
        kernels.affine_compose(np.zeros((3, 4, 2)))          # d < n
    with pytest.raises(ValueError, match="not composable"):
        kernels.affine_compose(np.zeros((0, 4, 9)))          # no tick


def test_the_numpy_path_can_be_asked_for(monkeypatch):
    monkeypatch.setenv("STOSPLINE_TABLE_KERNEL", "numpy")
    assert kernels.affine_compose(np.ones((2, 1, 2))) is None


@pytest.mark.parametrize("example,tolerance", [("coupled_axes", 1e-4),
                                               ("robot_corridor", 1e-5),
                                               ("investment", 1e-5)])
def test_the_spline_tables_are_the_same_bits_either_way(example, tolerance, monkeypatch):
    p = stospline.load_problem(EXAMPLES / f"{example}.toml")
    d = stospline.design_problem(p, table="per-tick", mode=p.options.get("mode", "stagewise"))
    exact = table_of(d.design, quantize=False)
    tables = []
    for kernel in ("c", "numpy"):
        monkeypatch.setenv("STOSPLINE_TABLE_KERNEL", kernel)
        tables.append(spline_table(p, exact, tolerance, per_tick=d.table,
                                   varying_maps=mean_maps))
    for name in ("K", "k0", "L", "Lambda", "lambda0"):
        np.testing.assert_array_equal(getattr(tables[0], name), getattr(tables[1], name), name)
    np.testing.assert_array_equal(tables[0].spline.coef, tables[1].spline.coef)


def test_a_host_that_cannot_build_it_falls_back_with_a_warning(monkeypatch):
    def no_compiler(*args, **kwargs):
        raise kernels.KernelBuildError("cannot build compose_kernel.c: no compiler")

    monkeypatch.setattr(kernels, "_loaded", None)
    monkeypatch.setattr(kernels, "_failed", False)
    monkeypatch.setattr(kernels, "build_kernel", no_compiler)
    P = _blocks(np.random.default_rng(3), 40, 4, 9)
    with pytest.warns(RuntimeWarning, match="runs its numpy references"):
        assert kernels.affine_compose(P) is None
    np.testing.assert_array_equal(spline_latch._affine_product(P),
                                  spline_latch._affine_product_numpy(P))
    assert kernels.qspline_stage(0, np.zeros((1, 4), np.int64), np.ones(1, np.int64),
                                 np.zeros((1, 1))) is None
    assert kernels.affine_compose_gains(np.eye(1, 2), np.zeros(0, np.int64), np.zeros((0, 1)),
                                        np.zeros((3, 0))) is None


def _q_stage(rng, k, T, E, bits=16, shift_range=(1, 31)):
    """Random coefficients (full `bits` range, both signs), shifts and nearby values."""
    nb = ((T - 1) >> k) + 4
    top = 2 ** (bits - 1) - 1
    C = rng.integers(-top - 1, top + 1, size=(E, nb), dtype=np.int64)
    shift = rng.integers(*shift_range, size=E).clip(1, 62 - 3 * k)
    G = qspline._stage_gains(k, C, shift, T)
    YT = G.T + rng.normal(size=(E, T)) * 3.0
    return C, shift, YT


@pytest.mark.parametrize("k,T,E,bits", [(0, 1, 1, 16), (3, 25, 5, 16), (7, 6000, 18, 16),
                                        (9, 1537, 4, 32), (9, 512, 3, 32), (4, 100, 0, 16)])
def test_the_qspline_kernel_evaluates_as_numpy(k, T, E, bits):
    rng = np.random.default_rng(k * 1000 + T)
    C, shift, YT = _q_stage(rng, k, T, E, bits)
    got = kernels.qspline_stage(k, C, shift, YT)
    assert got is not None, "the table kernel did not build on this host"
    G = qspline._stage_gains(k, C, shift, T)
    np.testing.assert_array_equal(got[0], G)
    np.testing.assert_array_equal(got[1], np.abs(G.T - YT).max(axis=1, initial=0.0))
    assert got[0].shape == (T, E) and got[0].dtype == np.int64


def test_the_qspline_kernel_rounds_negative_sums_half_up():
    # One entry, k = 0 (D = 1, the basis is [1, 4, 1, 0] at d = 0), shift 1: g = floor((c0 +
    # 4 c1 + c2 + 1) / 2); -3 -> floor(-1) = -1, -4 -> floor(-1.5) = -2, -5 -> -2, 3 -> 2.
    for acc, want in ((-3, -1), (-4, -2), (-5, -2), (3, 2), (-1, 0), (-2, -1)):
        C = np.array([[acc, 0, 0, 0]], np.int64)
        G, _ = kernels.qspline_stage(0, C, np.array([1]), np.zeros((1, 1)))
        assert int(G[0, 0]) == want == int(qspline._stage_gains(0, C, np.array([1]), 1)[0, 0])


def test_the_qspline_kernel_stops_at_a_miss():
    rng = np.random.default_rng(5)
    C, shift, YT = _q_stage(rng, 6, 700, 6)
    _, err = kernels.qspline_stage(6, C, shift, YT)
    assert kernels.qspline_stage(6, C, shift, YT, err) is not False      # equality is within
    tight = err.copy()
    tight[3] = np.nextafter(err[3], 0.0)
    assert kernels.qspline_stage(6, C, shift, YT, tight) is False
    YT[2, 17] = np.nan
    assert np.isnan(kernels.qspline_stage(6, C, shift, YT)[1][2])
    assert kernels.qspline_stage(6, C, shift, YT, np.full(6, np.inf)) is False
    YT[2, 17] = 0.0
    assert kernels.qspline_stage(6, C, shift, YT, np.full(6, np.nan)) is False


@pytest.mark.parametrize("k,shift,nb,c", [(10, 1, 4, 0), (-1, 1, 4, 0), (0, 0, 4, 0),
                                          (0, 31, 4, 0), (2, 1, 3, 0),
                                          (0, 1, 4, 2 ** 31), (0, 1, 4, -2 ** 31 - 1)])
def test_the_qspline_kernel_refuses_what_the_format_does_not_hold(k, shift, nb, c):
    C = np.zeros((1, nb), np.int64)
    C[0, 0] = c
    with pytest.raises(ValueError, match="not evaluable"):
        kernels.qspline_stage(k, C, np.array([shift]), np.zeros((1, 5)))
    with pytest.raises(ValueError, match="for 1 entries"):
        kernels.qspline_stage(0, np.zeros((2, 8), np.int64), np.ones(2), np.zeros((1, 5)))


@pytest.mark.parametrize("example,arith,tolerance", [("robot_corridor", "q15", 1e-5),
                                                     ("coupled_axes", "q31", 1e-4),
                                                     ("investment", "q15", 1e-3)])
def test_the_q_spline_tables_are_the_same_bits_either_way(example, arith, tolerance,
                                                          monkeypatch):
    from stospline.design.varying import mean_maps
    from stospline.oracle.evaluate import state_range
    p = stospline.load_problem(EXAMPLES / f"{example}.toml")
    d = stospline.design_problem(p, table="per-tick", mode=p.options.get("mode", "stagewise"))
    exact = table_of(d.design, quantize=False)
    x_range = state_range(p, d.table)
    tables = []
    for kernel in ("c", "numpy"):
        monkeypatch.setenv("STOSPLINE_TABLE_KERNEL", kernel)
        tables.append(qspline.q_spline_table(p, exact, arith, x_range, tolerance,
                                             varying_maps=mean_maps))
    for name in ("K", "k0", "L", "Lambda", "lambda0", "bound_lsb"):
        np.testing.assert_array_equal(getattr(tables[0], name), getattr(tables[1], name), name)
    for name in ("coef", "shift", "span_log2", "col", "row_start"):
        np.testing.assert_array_equal(getattr(tables[0].spline, name),
                                      getattr(tables[1].spline, name), name)


def test_a_stage_that_misses_is_reported_the_same_either_way(monkeypatch):
    # The kernel gives up a span length at its first miss; the message's "by ... x" is still
    # the worst over every span length tried, as numpy's full evaluation gives it.
    T = 256
    y = np.zeros((T, 1, 2))
    y[::2, :, 0] = 1000.0                          # a tick-by-tick oscillation
    y[:, :, 1] = np.linspace(0.0, 500.0, T)[:, None] ** 2 / 500.0
    messages = []
    for kernel in ("c", "numpy"):
        monkeypatch.setenv("STOSPLINE_TABLE_KERNEL", kernel)
        with pytest.raises(stospline.DesignError) as err:
            qspline.fit_q_spline((y, np.zeros((T, 1)), np.zeros((T, 1, 0))), [0, T], "q15",
                                 1e-6, max_spans=8)
        messages.append(str(err.value))
    assert messages[0] == messages[1] and "misses the tolerance" in messages[0]
