"""The float32 rounding of a spline table's re-solved latch maps (`spline_latch.round_latch`)
and the fit of a stage with more coefficients than ticks (`spline._min_norm`).

* At the design's start the rounded maps meet the constraints well below the float32 floor
  that rounding each map to nearest leaves (the robot at 1e-5: 7.4e-8 to nearest, 4.3e-8 the
  per-tick table's), at other starts no worse than 1.5x rounding to nearest, and the cost
  stays within 1e-8 of the exact (float64) re-solve's. Rounded to nearest instead (the
  compensation removed), the first test fails.
* No Lambda entry leaves its nearest float32 by more than one step but the one finest entry
  of a row; exact zeros stay zero; coupled_axes' lambda0 entries that are exact zeros
  (1e-10 after the re-solve) keep none of those digits (the latch grid).
* The choices do not move with the inputs' last bits (`_snap`).
* A stage with more coefficients than ticks is fitted by the least-norm solution, whose
  coefficients do not move with the gains' last bits; the ridge's solve would move them.
"""
from dataclasses import replace

import numpy as np
import pytest

import stospline
from stospline.design.varying import mean_maps
from stospline.refine.spline_certificate import constraint_residual, first_latch_in_float32
from stospline.table.spline import spline_table
from stospline.table.spline import latch as spline_latch
from stospline.table.format import table_of
from stospline.table.spline.fit import _Bases, _coefficients, _ill_conditioned, _lsq, _min_norm

from conftest import EXAMPLES

CASES = [("robot_corridor", 1e-5), ("robot_corridor", 1e-4), ("quadrotor", 1e-4)]


@pytest.fixture(scope="module")
def designs():
    cache = {}

    def get(example):
        if example not in cache:
            p = stospline.load_problem(EXAMPLES / f"{example}.toml")
            d = stospline.design_problem(p, table="per-tick",
                                         mode=p.options.get("mode", "stagewise"))
            cache[example] = (p, d, table_of(d.design, quantize=False))
        return cache[example]
    return get


def _tables(designs, example, tol):
    p, d, exact = designs(example)
    sp = spline_table(p, exact, tol, per_tick=d.table, varying_maps=mean_maps)
    Lam, lam0 = spline_latch.resolve_latch(p, sp, sp.spline, mean_maps)
    nearest = replace(sp, Lambda=Lam.astype(np.float32), lambda0=lam0.astype(np.float32))
    exact64 = replace(sp, Lambda=Lam, lambda0=lam0)
    return p, d, sp, nearest, exact64, Lam, lam0


def _residual(p, t):
    return constraint_residual(p, stospline.evaluate_table(p, t, path=False))


@pytest.mark.parametrize("example, tol", CASES)
def test_rounded_latch_meets_the_constraints_at_the_start(designs, example, tol):
    p, d, sp, nearest, exact64, _, _ = _tables(designs, example, tol)
    shipped, to_nearest, per_tick = _residual(p, sp), _residual(p, nearest), _residual(p, d.table)
    # The float32 floor: rounding to nearest misses by 2.9e-8 to 7.4e-8 here.
    assert to_nearest > 2e-8
    assert shipped < 0.25 * to_nearest, (shipped, to_nearest)
    assert shipped <= per_tick, (shipped, per_tick)
    J64 = stospline.evaluate_table(p, exact64, path=False).J
    J = stospline.evaluate_table(p, sp, path=False).J
    assert abs(J - J64) <= 1e-8 * abs(J64)


@pytest.mark.parametrize("example, tol", CASES)
def test_rounded_latch_is_no_worse_at_other_starts(designs, example, tol):
    p, _, sp, nearest, _, _, _ = _tables(designs, example, tol)
    rng = np.random.default_rng(0)
    x0 = np.asarray(p.x0, dtype=float)
    for _ in range(4):
        q = replace(p, x0=x0 + rng.normal(0.0, 0.1 * (1 + np.abs(x0).max()), x0.shape))
        assert _residual(q, sp) <= 1.5 * _residual(q, nearest) + 1e-9


@pytest.mark.parametrize("example, tol", CASES)
def test_rounded_latch_moves_each_entry_little(designs, example, tol):
    _, _, sp, _, _, Lam, _ = _tables(designs, example, tol)
    L32 = sp.Lambda.astype(float)
    flushed = np.where(np.abs(Lam) < 1e-12 * np.abs(Lam).max(), 0.0, Lam)
    assert np.all(L32[flushed == 0] == 0)
    ulp = np.spacing(np.abs(flushed.astype(np.float32))).astype(float)
    steps = np.abs(L32 - flushed) / np.where(ulp > 0, ulp, 1.0)
    assert steps.max() <= spline_latch.FINE_STEPS + 0.5
    # Beyond one step past the nearest: the one finest entry of a row, at most.
    assert np.all((steps > 1.5).sum(axis=2) <= 1)


def test_first_latch_in_float32_reproduces_the_firmware_latch(designs):
    """The copy's oracle latches at x0 exactly the binary32 ``lambda0 + Lambda x0``."""
    p, _, sp, _, _, _, _ = _tables(designs, "robot_corridor", 1e-5)
    f = first_latch_in_float32(p, sp)
    x = spline_latch.start_state(p, sp)
    v = f.lambda0[0] + f.Lambda[0] @ x
    acc = sp.lambda0[0].copy()
    for j in range(x.size):
        acc = (acc + (sp.Lambda[0][:, j] * np.float32(x[j])).astype(np.float32)).astype(
            np.float32)
    np.testing.assert_allclose(v, acc.astype(float), rtol=0, atol=1e-15)
    assert np.any(acc.astype(float) != sp.lambda0[0] + sp.Lambda[0].astype(float) @ x)


def test_coupled_axes_exact_zeros_are_stored_as_zero(designs):
    p, _, exact = designs("coupled_axes")
    _, d, _ = designs("coupled_axes")
    sp = spline_table(p, exact, 1e-5, per_tick=d.table, varying_maps=mean_maps)
    Lam, lam0 = spline_latch.resolve_latch(p, sp, sp.spline, mean_maps)
    tiny = (np.abs(lam0) > 0) & (np.abs(lam0) < 1e-8 * np.abs(lam0).max())
    assert tiny.any()                     # the re-solve leaves them at 1e-10
    # Stored on their rows' grid (the float32 spacing at the multiplier's scale, ~1: a
    # multiple of 2^-24 here), a step or two at most (compensating Lambda's rounding at the
    # planned state): none of the 1e-10's digits.
    stored = sp.lambda0[tiny].astype(float)
    assert np.all(np.abs(stored) <= 2.0 ** -22)
    assert np.all(stored * 2.0 ** 24 == np.rint(stored * 2.0 ** 24))


def test_choices_do_not_move_with_the_inputs_last_bits(designs):
    """round_latch on the exact maps, the planned means and C2 Gamma perturbed by 1e-14
    relative gives the same bytes (the inputs are snapped to SNAP_BITS bits first)."""
    p, _, sp, _, _, Lam, lam0 = _tables(designs, "quadrotor", 1e-4)
    groups = spline_latch._groups(p, sp, sp.spline, mean_maps)
    base = spline_latch.round_latch(p, sp, groups, Lam, lam0)
    rng = np.random.default_rng(3)

    def jiggle(a):
        return None if a is None else a * (1 + 1e-14 * rng.uniform(-1, 1, np.shape(a)))
    for _ in range(3):
        moved = [(g[0], g[1], g[2], [jiggle(P) for P in g[3]], jiggle(g[4]), g[5])
                 for g in groups]
        out = spline_latch.round_latch(p, sp, moved, jiggle(Lam), jiggle(lam0))
        assert np.array_equal(out[0], base[0]) and np.array_equal(out[1], base[1])


def _one_tick_stage(rng, T=25):
    """A stage of T ticks whose spans are one tick (the last two): more coefficients than
    ticks, as coupled_axes' last stage at 1e-5."""
    breaks = np.r_[np.arange(0, T - 1), T].astype(np.int64)
    t = np.arange(T) / T
    YT = np.vstack([np.exp(3 * t), 1 / (1.05 - t), np.sin(7 * t)]) * 10.0
    return breaks, YT


def test_more_coefficients_than_ticks_fit_does_not_move_with_last_bits():
    rng = np.random.default_rng(0)
    breaks, YT = _one_tick_stage(rng)
    T = YT.shape[1]
    assert breaks.size + 2 > T and _ill_conditioned(breaks)
    sigma, N, N64, band = _Bases().get(T, breaks)
    peak = np.abs(YT).max(axis=1)
    fits, ridge = [], []
    for _ in range(4):
        Y = YT * (1 + 1e-14 * rng.uniform(-1, 1, YT.shape))
        fits.append(_coefficients(_min_norm(breaks, sigma, N64, Y), peak))
        ridge.append(_coefficients(_lsq(breaks, N64, Y, band), peak))
    assert all(np.array_equal(f, fits[0]) for f in fits)
    # The ridge's solve (condition ~1e13) moves them: why the least-norm fit is used.
    assert not all(np.array_equal(r, ridge[0]) for r in ridge)
    # And it fits: the float32 values at the ticks within float32 rounding of the data.
    from stospline.table.spline.fit import _combine
    G = _combine(sigma, N, fits[0]).astype(float)
    assert np.abs(G.T - YT).max() <= 1e-5 * peak.max()
