"""The table layer's compiled kernel (`stospline.table.kernels.affine_compose`): the
composition of a stage's affine tick maps, which every latch re-solve of a spline table uses.

* It composes as the numpy reference does (`spline_latch._affine_product_numpy`, pairwise
  products): to round-off on random blocks of the shapes the tables use, exactly on one
  block, and with the constant columns carried (an affine map, not a linear one).
* It refuses blocks it does not take; ``STOSPLINE_TABLE_KERNEL=numpy`` turns it off, and a
  host that cannot build it falls back to the numpy products with a warning.
* The spline tables are the same bits with the kernel and with the numpy products.
"""
import numpy as np
import pytest

import stospline
from stospline.sim.spline_certificate import spline_table
from stospline.table import kernels, spline_latch
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
        tables.append(spline_table(p, exact, d.table, tolerance))
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
    with pytest.warns(RuntimeWarning, match="composing tick maps in numpy"):
        assert kernels.affine_compose(P) is None
    np.testing.assert_array_equal(spline_latch._affine_product(P),
                                  spline_latch._affine_product_numpy(P))
