"""Spline tables: the host's mirror of the firmware's evaluation, the fit, and the
latch maps re-solved for the fitted gains.

* `evaluate` is the spec's binary32 evaluation (docs: ``spline_spec.md``): bit for bit a
  scalar transcription of the spec (numpy float32 scalars, one rounding per operation), and
  scipy's float64 B-splines to float32 precision; its basis sums to 1 within rounding;
* `fit_spline` meets its tolerance on every stored entry, stores no structural zero, and
  refuses what it cannot meet, naming the first stage that misses; stages fitted together
  are fitted bit for bit as alone; a law without multipliers is fitted too;
* `resolve_latch` makes a perturbed law meet its constraints again (by the oracle, to float64
  rounding), reproduces the design's latch maps for the design's own gains, and refuses what it
  cannot do exactly; the oracle check catches a wrong re-solve.
"""
import tomllib
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.interpolate import BSpline

import stospline
from stospline.design.latch import latch_groups
from stospline.design.varying import mean_maps
from stospline.design.zoh import _tick_data, design_zoh
from stospline.errors import DesignError
from stospline.problem import parse_problem
from stospline.oracle.evaluate import evaluate_table
from stospline.table.format import BandQP, table_of
from stospline.table.spline.fit import (MIN_TOLERANCE, SplineBudgetError, SplineGains, _Bases,
                                    _basis, _coefficients, _column_peaks, _fit_stage,
                                    _fit_stages, _lsq, _refined, _solve_banded, _span_excess, _stage_entries, command,
                                    evaluate, fit_spline, max_relative_error)
from stospline.table.spline.compress import compress
from stospline.table.spline.latch import latch_groups_of_table, mean_tick_map, resolve_latch

from support.problems import BASE, edit

F32 = np.float32
EPS32 = float(np.finfo(np.float32).eps)


def _settings(n):
    return settings(derandomize=True, database=None, max_examples=n, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])


# ---------------------------------------------------------------------------------------
# The mirror


def _random_spline(rng, T):
    """One stage of T ticks, one input, nx = 2, one multiplier: K[0][0], k0 and L[0][0]
    stored (cols 0, 2, 3) with random integer breakpoints and coefficients."""
    S = int(rng.integers(1, min(T, 9) + 1))
    inner = np.sort(rng.choice(np.arange(1, T), size=S - 1, replace=False)) if S > 1 else []
    knot = np.concatenate([[0] * 4, inner, [T] * 4])
    coef = (rng.normal(size=(3, S + 3)) * 10.0 ** rng.integers(-3, 4)).astype(F32)
    return SplineGains(knot_start=[0, knot.size], knot=knot, row_start=[0, 3], col=[0, 2, 3],
                       coef_start=[0, coef.size], coef=coef.ravel(), nu=1, nx=2, n_latch=1)


def _spec_gain(U, c, tick):
    """The spec's evaluation, transcribed literally with float32 scalars."""
    U = [F32(u) for u in U]
    tau = F32(tick)
    sigma = next(s for s in range(len(U) - 7) if U[s + 3] <= tau < U[s + 4])
    i = sigma + 3
    left = [None] + [F32(tau - U[i + 1 - j]) for j in (1, 2, 3)]
    right = [None] + [F32(U[i + j] - tau) for j in (1, 2, 3)]
    N = [F32(1), F32(0), F32(0), F32(0)]
    for j in (1, 2, 3):
        saved = F32(0)
        for r in range(j):
            temp = F32(N[r] / F32(right[r + 1] + left[j - r]))
            N[r] = F32(saved + F32(right[r + 1] * temp))
            saved = F32(left[j - r] * temp)
        N[j] = saved
    g = F32(N[0] * c[sigma])
    for r in (1, 2, 3):
        g = F32(g + F32(N[r] * c[sigma + r]))
    return g


@_settings(40)
@given(seed=st.integers(0, 2 ** 32 - 1), T=st.integers(1, 60))
def test_the_mirror_is_the_spec_bit_for_bit_and_the_float64_spline_to_float32(seed, T):
    sp = _random_spline(np.random.default_rng(seed), T)
    K, k0, L = evaluate(sp, [0, T])
    assert K.dtype == k0.dtype == L.dtype == np.float32
    assert not K[:, 0, 1].any()                    # not stored: exactly zero
    U, C = sp.knots(0), sp.coefficients(0)
    for got, c in zip((K[:, 0, 0], k0[:, 0], L[:, 0, 0]), C):
        spec = np.array([_spec_gain(U, c, t) for t in range(T)], dtype=F32)
        np.testing.assert_array_equal(got.view(np.uint32), spec.view(np.uint32))
        ref = BSpline(U.astype(float), c.astype(float), 3)(np.arange(T, dtype=float))
        assert np.abs(got - ref).max() <= 8 * EPS32 * np.abs(c).max()
    again = evaluate(sp, [0, T])
    assert all(np.array_equal(a, b) for a, b in zip((K, k0, L), again))


@_settings(30)
@given(seed=st.integers(0, 2 ** 32 - 1), T=st.integers(1, 400))
def test_the_basis_sums_to_one_within_rounding(seed, T):
    U = _random_spline(np.random.default_rng(seed), T).knots(0)
    tau = np.arange(T, dtype=F32)
    _, N32 = _basis(U, tau)
    assert np.abs(np.sum(N32, axis=0, dtype=float) - 1).max() <= 8 * EPS32
    _, N64 = _basis(U.astype(float), tau.astype(float))
    assert np.abs(sum(N64) - 1).max() <= 1e-14
    assert min(n.min() for n in N32) >= 0


def _spec_command(U, C, tick, x, v):
    """The firmware's command from the spec, literally: per coefficient the feed-forward folded
    as (+0 - c_k0 * 1) - c_L * v, its spline's value, minus the gain of x times x."""
    fold = [F32(F32(F32(0) - F32(C[1][r] * F32(1))) - F32(C[2][r] * v))
            for r in range(C.shape[1])]
    return F32(_spec_gain(U, np.array(fold, F32), tick) - F32(_spec_gain(U, C[0], tick) * x))


@_settings(40)
@given(seed=st.integers(0, 2 ** 32 - 1), T=st.integers(1, 60))
def test_the_command_folds_the_feed_forward_and_is_the_law_to_rounding(seed, T):
    """`command` (the firmware's order: k0 + L v folded into one spline per span, then the
    gains of x) is the spec's fold bit for bit, and -(K x + k0 + L v) of `evaluate`'s gains in
    float64 to a few roundings of the terms: the fold changes the command's rounding only."""
    rng = np.random.default_rng(seed)
    sp = _random_spline(rng, T)
    K, k0, L = evaluate(sp, [0, T])
    U, C = sp.knots(0), sp.coefficients(0)
    for t in range(T):
        x = rng.normal(size=2).astype(F32) * F32(10.0 ** rng.integers(-2, 3))
        v = rng.normal(size=1).astype(F32) * F32(10.0 ** rng.integers(-2, 3))
        u = command(sp, [0, T], t, x, v)
        assert u.dtype == np.float32
        assert u.view(np.uint32)[0] == np.array(_spec_command(U, C, t, x[0], v[0]),
                                                F32).view(np.uint32)
        law = -(float(K[t, 0, 0]) * float(x[0]) + float(k0[t, 0])
                + float(L[t, 0, 0]) * float(v[0]))
        scale = (np.abs(C[0]).max() * abs(float(x[0])) + np.abs(C[1]).max()
                 + np.abs(C[2]).max() * abs(float(v[0])))
        assert abs(float(u[0]) - law) <= 16 * EPS32 * scale


def test_the_columns_of_a_row_must_increase():
    sp = _random_spline(np.random.default_rng(2), 20)
    with pytest.raises(ValueError, match="increase"):
        replace(sp, col=np.array([0, 3, 2], np.uint8))
    with pytest.raises(ValueError, match="increase"):
        replace(sp, col=np.array([0, 2, 2], np.uint8))


def test_evaluate_refuses_a_spline_of_other_stages():
    sp = _random_spline(np.random.default_rng(1), 30)
    with pytest.raises(ValueError, match="spans 30 ticks"):
        evaluate(sp, [0, 31])
    with pytest.raises(ValueError, match="stages"):
        evaluate(sp, [0, 10, 30])


# ---------------------------------------------------------------------------------------
# The fit


@pytest.fixture(scope="module")
def robot_exact(robot_zoh):
    return table_of(robot_zoh.design, quantize=False)


@pytest.mark.parametrize("tolerance", [1e-3, 1e-5])
def test_the_fit_meets_the_tolerance_on_every_entry_and_stores_no_zero(robot_exact, tolerance):
    exact = robot_exact
    sp = fit_spline(exact, tolerance)
    K, k0, L = evaluate(sp, exact.stage_start)
    got = np.concatenate([K, k0[..., None], L], axis=2).astype(float)
    want = np.concatenate([exact.K, exact.k0[..., None], exact.L], axis=2)
    n = exact.dims[0]
    for s in range(exact.n_stages):
        a, b = exact.stage_start[s], exact.stage_start[s + 1]
        peak = np.abs(want[a:b]).max(axis=0)
        err = np.abs(got[a:b] - want[a:b]).max(axis=0)
        stored = np.zeros(peak.shape, dtype=bool)
        stored[sp.entries(s)] = True
        assert np.all(err[stored] <= tolerance * peak[stored])
        assert not got[a:b][:, ~stored].any()      # not stored: exactly zero
        # ... and only the zeros are missing: the robot's axes are decoupled (K and the
        # multipliers of the other axis are 0), stage 0 has one multiplier of four.
        assert np.all(peak[~stored] <= 1e-12 * peak[:, :n].max())
    assert [sp.spans(s) < 200 for s in range(sp.n_stages)] == [True, True]
    assert sp.n_entries == 8 + 10
    assert max_relative_error(sp, exact) <= tolerance
    assert sp.nbytes < 4000                         # the per-tick float32 table: 432 000


def test_a_budget_that_cannot_be_met_is_refused(robot_exact):
    with pytest.raises(SplineBudgetError) as exc:
        fit_spline(robot_exact, 1e-6, max_spans=4)
    assert isinstance(exc.value, DesignError) and isinstance(exc.value, ValueError)
    assert exc.value.field == "design.spline_tolerance" and "4 spans" in exc.value.reason
    for bad in (MIN_TOLERANCE / 2, 0.0, float("nan"), 1.0):
        with pytest.raises(SplineBudgetError, match="tolerance"):
            fit_spline(robot_exact, bad)


def test_the_banded_solver_is_the_dense_one():
    rng = np.random.default_rng(3)
    nb = 450                                     # above the dense solver's limit
    band = np.vstack([rng.uniform(4, 5, nb), rng.uniform(-1, 1, (3, nb))])
    A = np.diag(band[0])
    for d in (1, 2, 3):
        A += np.diag(band[d, :nb - d], d) + np.diag(band[d, :nb - d], -d)
    rhs = rng.normal(size=(nb, 3))
    np.testing.assert_allclose(_solve_banded(band, rhs), np.linalg.solve(A, rhs),
                               rtol=1e-11, atol=1e-12)


def test_the_least_squares_fit_recovers_a_spline_of_many_spans():
    """A spline on 420 spans (the banded path) sampled at its ticks is fitted back exactly,
    one-tick spans (whose last basis function no tick reaches) included."""
    rng = np.random.default_rng(4)
    T = 1200
    breaks = np.unique(np.r_[0, np.sort(rng.choice(np.arange(1, T - 3), 415, replace=False)),
                             T - 3, T - 2, T - 1, T])
    U = np.concatenate([[0.0] * 3, breaks, [float(T)] * 3])
    c = rng.normal(size=(breaks.size + 2, 2))
    tau = np.arange(T, dtype=float)
    Y = BSpline(U, c, 3)(tau)
    _, N = _basis(U, tau)
    fitted = BSpline(U, _lsq(breaks, N, Y.T).T, 3)(tau)
    np.testing.assert_allclose(fitted, Y, atol=1e-9)


# The fit's fast paths compute what the plain numpy they replace computes, bit for bit (the
# shipped spline tables must regenerate byte for byte).


@_settings(60)
@given(st.integers(1, 300), st.integers(1, 6), st.integers(0, 2 ** 32 - 1))
def test_column_peaks_are_numpys(T, k, seed):
    g = np.random.default_rng(seed).normal(size=(T, k)) * 10.0 ** np.arange(k)
    np.testing.assert_array_equal(_column_peaks(g), np.abs(g).max(axis=0))


@_settings(60)
@given(st.integers(2, 3000), st.integers(1, 40), st.integers(0, 2 ** 32 - 1))
def test_the_refined_breakpoints_are_linspaces(T, spans, seed):
    rng = np.random.default_rng(seed)
    inner = rng.choice(np.arange(1, T), size=min(spans, T) - 1, replace=False)
    breaks = np.unique(np.r_[0, inner, T]).astype(np.int64)
    excess = rng.uniform(0, 2, breaks.size - 1) ** rng.uniform(1, 30)
    length = np.diff(breaks)
    most = np.r_[length[:-1], max(1, length[-1] // 2)]  # the last span: pieces of 2 ticks
    pieces = np.zeros(length.size, dtype=np.int64)     # as _refined decides them
    for s in np.flatnonzero(excess > 1):
        if most[s] > 1:
            pieces[s] = max(pieces[s], 2, int(np.ceil(1.25 * excess[s] ** 0.25)))
        else:
            pieces[max(0, s - 3):s + 4] = np.maximum(pieces[max(0, s - 3):s + 4], 2)
    pieces = np.minimum(pieces, most)
    want = np.unique(np.concatenate(
        [breaks] + [np.rint(np.linspace(breaks[s], breaks[s + 1], pieces[s] + 1)[1:-1])
                    .astype(np.int64) for s in np.flatnonzero(pieces > 1)]))
    got = _refined(breaks, excess)
    np.testing.assert_array_equal(got, want)
    assert got[-1] - got[-2] >= min(2, T - breaks[-2])   # the last span keeps two ticks


def test_the_coefficients_are_on_the_float32_grid_of_their_entrys_peak():
    """Each entry's coefficients are the nearest multiples of the float32 spacing at its
    peak (in the peak's binade, float32 rounding itself; below it, coarser than their own
    float32 neighbours), so a coefficient far below the peak moves only when the fit's value
    crosses a midpoint of that grid, not with its own last bits."""
    rng = np.random.default_rng(5)
    peak = np.array([4.7e-3, 78.0, 1.0])
    C = rng.normal(size=(3, 40)) * peak[:, None] * 10.0 ** rng.uniform(-9, 0.2, (3, 40))
    got = _coefficients(C, peak)
    assert got.dtype == np.float32
    q = np.ldexp(1.0, np.frexp(peak)[1] - 24)[:, None]       # 2^-31, 2^-17, 2^-23
    np.testing.assert_array_equal(q[:, 0], [2.0 ** -31, 2.0 ** -17, 2.0 ** -23])
    np.testing.assert_array_equal(got.astype(float), np.rint(C / q) * q)
    inside = np.abs(C) >= np.ldexp(1.0, np.frexp(peak)[1] - 1)[:, None]   # the peak's binade
    np.testing.assert_array_equal(got[inside], C[inside].astype(np.float32))
    tiny = np.abs(C) < q / 2
    assert tiny.any() and np.all(got[tiny] == 0)


def test_a_jump_at_the_last_tick_leaves_the_fit_well_posed():
    """A stage ending on a jump (a delayed design's last tick outputs the safe command): the
    refinement keeps two ticks in the last span, whose last basis function a tick then
    reaches, so the least squares is well posed: last bits of the gains (1e-14) move the
    coefficients by as little (relative to the entry), not by the 1e-5 of a one-tick last
    span, where only the ridge holds two coefficients."""
    T = 1000
    t = np.arange(T, dtype=float)
    YT = np.vstack([np.where(t < T - 1, 1.0 - t / T, 0.0), np.where(t < T - 1, -5.0, -9.81)])
    breaks, C, G = _fit_stage(YT, 1e-5, 1024, 8, 0)
    assert breaks[-1] - breaks[-2] == 2 and np.any(np.diff(breaks)[-10:] == 1)
    assert np.all(np.abs(G.T - YT) <= 1e-5 * np.abs(YT).max(axis=1)[:, None])
    _, _, N64, band = _Bases().get(T, breaks)
    rng = np.random.default_rng(3)
    C0 = _lsq(breaks, N64, YT, band)
    C1 = _lsq(breaks, N64, YT * (1 + 1e-14 * rng.uniform(-1, 1, YT.shape)), band)
    assert np.max(np.abs(C1 - C0) / np.abs(YT).max(axis=1)[:, None]) < 1e-11
    # One-tick spans to the end instead (what the refinement made before): two directions
    # held by the ridge only.
    one = np.r_[breaks[breaks < T - 8], np.arange(T - 8, T + 1)]
    _, _, N64, band = _Bases().get(T, one)
    C0 = _lsq(one, N64, YT, band)
    C1 = _lsq(one, N64, YT * (1 + 1e-14 * rng.uniform(-1, 1, YT.shape)), band)
    assert np.max(np.abs(C1 - C0) / np.abs(YT).max(axis=1)[:, None]) > 1e-8


@pytest.mark.parametrize("nb", [4, 5, 27, 400])
def test_the_dense_solve_assembles_the_banded_matrix(nb):
    rng = np.random.default_rng(nb)
    band = np.vstack([rng.uniform(4, 5, nb), rng.uniform(-1, 1, (3, nb))])
    A = np.diag(band[0])
    for d in (1, 2, 3):
        A += np.diag(band[d, :nb - d], d) + np.diag(band[d, :nb - d], -d)
    rhs = rng.normal(size=(nb, 3))
    np.testing.assert_array_equal(_solve_banded(band, rhs), np.linalg.solve(A, rhs))


def test_the_span_errors_are_the_scaled_per_tick_errors():
    rng = np.random.default_rng(7)
    Y = rng.normal(size=(500, 5)) * 10.0 ** np.arange(5)
    G = (Y * (1 + rng.normal(size=Y.shape) * 1e-5)).astype(np.float32)
    scale = 1.0 / (1e-4 * np.abs(Y).max(axis=0))
    breaks = np.array([0, 7, 8, 100, 333, 500])
    per_tick = (np.abs(G - Y) * scale).max(axis=1)
    np.testing.assert_array_equal(
        _span_excess(G, np.ascontiguousarray(Y.T), scale, breaks).max(axis=0),
        np.maximum.reduceat(per_tick, breaks[:-1]))


def test_the_bases_kept_across_stages_change_no_fit(robot_exact):
    """Stages fitted with the bases of earlier stages (equal lengths: the robot's two 3 s
    legs) give what each stage fitted alone gives; the store drops the oldest bases beyond
    its bound and never keeps one longer than it."""
    start = robot_exact.stage_start
    assert start[1] - start[0] == start[2] - start[1]
    shared = _Bases()
    for s in range(robot_exact.n_stages):
        YT = _stage_entries(robot_exact, int(start[s]), int(start[s + 1]))[1]
        for got, want in zip(_fit_stage(YT, 1e-5, 1024, 8, s, shared),
                             _fit_stage(YT, 1e-5, 1024, 8, s)):
            np.testing.assert_array_equal(got, want)
    assert {T for T, _ in shared._cache} == {int(start[1])} and len(shared._cache) >= 2
    small = _Bases()
    small.KEEP_TICKS = 100
    for T in (40, 60, 30, 200):
        small.get(T, np.array([0, T]))
    assert [T for T, _ in small._cache] == [60, 30]



def test_stages_fitted_together_are_fitted_as_alone():
    """`_fit_stages` (stages of one length at the same breakpoints batched) gives each stage
    bit for bit what `_fit_stage` gives it alone, whatever the other stages refine to."""
    t = np.arange(25.0)
    YTs = [np.vstack([np.sin(t / (3 + k) + j) * (1 + j) for j in range(6)]) for k in range(7)]
    YTs.append(np.zeros((0, 25)))                       # a stage that stores nothing
    YTs.append(YTs[0][:3, :20].copy())                  # another length
    together = _fit_stages(YTs, list(range(len(YTs))), 1e-5, 1024, 8, _Bases())
    assert len({together[s][0].tobytes() for s in range(7)}) > 1   # they refine differently
    for s, YT in enumerate(YTs):
        for got, want in zip(together[s], _fit_stage(YT, 1e-5, 1024, 8, s)):
            np.testing.assert_array_equal(got, want)


def test_the_first_stage_that_misses_is_named():
    """Stages are fitted in windows and together, but the error is the first failing
    stage's, as when they were fitted one after the other."""
    T, stages = 40, 6
    tau = np.arange(stages * T) % T / T
    K = np.stack([1 + tau + tau ** 3, 2 - tau ** 2], axis=1)[:, None, :]   # cubics: 1 span
    noise = np.random.default_rng(5).normal(size=(T, 1, 2))
    for s in (2, 4):
        K[s * T:(s + 1) * T] += noise
    table = SimpleNamespace(dims=(2, 1, 0), stage_start=np.arange(stages + 1) * T,
                            n_stages=stages, K=K, k0=np.ones((stages * T, 1)),
                            L=np.zeros((stages * T, 1, 0)))
    with pytest.raises(SplineBudgetError, match="^.*stage 2: the gains need more than 4 spans"):
        fit_spline(table, 1e-5, max_spans=4)
    K[2 * T:3 * T] -= noise
    with pytest.raises(SplineBudgetError, match="stage 4: "):
        fit_spline(table, 1e-5, max_spans=4)
    K[4 * T:5 * T] -= noise
    assert fit_spline(table, 1e-5, max_spans=4).n_stages == stages



def test_a_law_without_multipliers_gets_a_spline_table():
    """A problem with penalties and no constraint latches nothing (n_latch = 0): its spline
    table is fitted (an entry kind with no column once failed to reshape) and costs J0."""
    text = edit(BASE, ("constraint = { C = [[1, 0]], value = [1.0] }\n", ""),
                ("constraint = { C = [[1, 0], [0, 1]], value = [0.0, 0.0] }\n",
                 "penalty = { C = [[1, 0]], target = [0.0], weight = 1.0 }\n"))
    d = stospline.design_problem(parse_problem(tomllib.loads(text)), table="spline")
    assert d.table.dims[2] == 0 and d.table.spline is not None
    assert abs(d.certificate["excess_over_J0"]) <= 1e-9


# ---------------------------------------------------------------------------------------
# The latch re-solve


def _parse(text):
    return parse_problem(tomllib.loads(text))


FAST = edit(BASE, ("tick_hz = 10", "tick_hz = 100"))
# Knot 0 penalised only, knots 1 and 2 constrained (one row each): stage 0 latches nothing in
# the stage-wise design, and the joint vector (2 rows) is no wider than the state.
THREE_EDITS = (("constraint = { C = [[1, 0]], value = [1.0] }\n", ""),
               ("constraint = { C = [[1, 0], [0, 1]], value = [0.0, 0.0] }",
                "constraint = { C = [[1, 0]], value = [0.0] }\n\n[[knots]]\nt = 3.0\n"
                "constraint = { C = [[0, 1]], value = [0.5] }"))
THREE = edit(FAST, *THREE_EDITS)


def _residual(problem, table) -> float:
    mom = evaluate_table(problem, table, path=False)
    return max(float(np.abs(mom.knot_constraint[k] - kn.constraint.value).max())
               for k, kn in enumerate(problem.knots) if kn.constraint is not None)


# (FAST's joint table latches the state, 3 rows > 2 states: refused below.)
@pytest.mark.parametrize("text, mode", [(FAST, "stagewise"), (THREE, "stagewise"),
                                        (THREE, "joint")],
                         ids=["two knots", "three knots", "three knots joint"])
def test_the_re_solve_makes_a_perturbed_law_meet_its_constraints(text, mode):
    problem = _parse(text)
    exact = table_of(design_zoh(problem, mode=mode), quantize=False)
    # The design's own gains: the design's latch maps, found another way.
    Lam, lam0 = resolve_latch(problem, exact)
    np.testing.assert_allclose(Lam, exact.Lambda, rtol=1e-8, atol=1e-9)
    np.testing.assert_allclose(lam0, exact.lambda0, rtol=1e-8, atol=1e-9)
    # Gains off by 2 % (a coarse fit, say): the design's latch misses, the re-solved one not.
    off = replace(exact, K=exact.K * 1.02, k0=exact.k0 + 0.01, L=exact.L * 0.98)
    assert _residual(problem, off) > 1e-3
    Lam, lam0 = resolve_latch(problem, off)
    assert _residual(problem, replace(off, Lambda=Lam, lambda0=lam0)) < 1e-11
    # The check catches a wrong re-solve (here a sign error in lambda0 = G^-1 (zeta - C psi)).
    assert _residual(problem, replace(off, Lambda=Lam, lambda0=-lam0)) > 1e-3


# Time-varying data (A, B and the drift f change within the stages, A with a kink inside
# stage 0) and a law designed for a one-tick delay (its state [x; p] carries the command).
VARYING = edit(FAST, ("A = [[0, 1], [0, 0]]",
                      "A = { t = [0, 0.4, 3], values = [[[0, 1], [0, 0]], [[0, 1], [-3, -0.5]], "
                      "[[0, 1], [1, 0]]] }"),
               ("B = [[0], [1]]", "B = { t = [0, 3], values = [[[0], [1]], [[0], [2.5]]] }\n"
                                  "f = { t = [0, 3], values = [[0, -1], [0.5, 0]] }"))


@pytest.mark.parametrize("text, mode, delay", [(VARYING, "stagewise", 0),
                                               (edit(VARYING, *THREE_EDITS), "joint", 0),
                                               (FAST, "stagewise", 1), (THREE, "joint", 1)],
                         ids=["time-varying", "time-varying joint", "delay", "delay joint"])
def test_the_re_solve_is_exact_for_time_varying_data_and_a_delay(text, mode, delay):
    """The mean over a tick is the oracle's: for time-varying data its Gauss-point
    discretisation tick by tick (`design.varying.mean_maps`), with a delay the map of the state
    ``[x; p]``. The design's own gains give back the design's latch maps (found by the
    designer's own recursion), and a perturbed law meets its constraints to rounding."""
    problem = _parse(text)
    exact = table_of(design_zoh(problem, mode=mode, delay_ticks=delay), quantize=False)
    assert exact.delay_ticks == delay and exact.dims[0] == 2 + delay
    if text is not FAST and text is not THREE:     # the table layer has no mean maps of its own
        with pytest.raises(DesignError, match="time-varying data without the per-tick"):
            resolve_latch(problem, exact)
    Lam, lam0 = resolve_latch(problem, exact, varying_maps=mean_maps)
    np.testing.assert_allclose(Lam, exact.Lambda, rtol=1e-8, atol=1e-9)
    np.testing.assert_allclose(lam0, exact.lambda0, rtol=1e-8, atol=1e-9)
    off = replace(exact, K=exact.K * 1.02, k0=exact.k0 + 0.01, L=exact.L * 0.98)
    assert _residual(problem, off) > 1e-3
    Lam, lam0 = resolve_latch(problem, off, varying_maps=mean_maps)
    assert _residual(problem, replace(off, Lambda=Lam, lambda0=lam0)) < 1e-11
    assert _residual(problem, replace(off, Lambda=Lam, lambda0=-lam0)) > 1e-3


def test_the_varying_mean_maps_are_the_exact_ones_of_data_linear_on_each_tick():
    """Data linear in time on each tick are their own Gauss-point interpolant, so the maps of
    `mean_maps` are the exact mean maps, here integrated independently (DOP853 on the data,
    `tick_moments._tick_varying`); 5 Hz with |A| up to 9 makes the series take sub-steps."""
    from stospline.oracle.tick_moments import _tick_varying
    problem = _parse(edit(VARYING, ("tick_hz = 100", "tick_hz = 5"),
                          ("[[0, 1], [-3, -0.5]]", "[[0, 1], [-9, -2]]")))
    stage, h = problem.stages[0], 0.2
    F = mean_maps(stage, 0.0, h, 5)
    assert F.shape == (5, 2, 4)
    for j in range(5):
        _, _, want = _tick_varying(stage, np.zeros((4, 4)), j * h, h, 2, 1)
        np.testing.assert_allclose(F[j], want, rtol=1e-10, atol=1e-11)


@pytest.mark.parametrize("mode", ["stagewise", "joint"])
def test_the_table_latch_groups_are_the_designers(mode):
    problem = _parse(THREE)
    table = table_of(design_zoh(problem, mode=mode))
    groups, _ = latch_groups(problem, mode)
    assert latch_groups_of_table(problem, table) == [(g.latch_stage, list(g.knots))
                                                     for g in groups]


def test_the_mean_map_is_the_designers():
    problem = _parse(edit(FAST, ("B = [[0], [1]]", "B = [[0], [1]]\nf = [0.3, -9.81]")))
    stage = problem.stages[0]
    np.testing.assert_allclose(mean_tick_map(stage, 0.01), _tick_data(stage, 0.01).F,
                               rtol=1e-13, atol=1e-15)


def test_what_is_not_re_solved_exactly_is_refused():
    problem = _parse(FAST)
    cases = {
        "latches the state": (problem, table_of(design_zoh(problem, mode="joint"))),
    }
    plain = table_of(design_zoh(problem))
    cases["band"] = (problem, replace(plain, band_qp=BandQP(np.zeros((1, 2)), np.zeros(1),
                                                            np.eye(1), np.zeros(1),
                                                            np.zeros(1))))
    cases["stages do not match"] = (_parse(edit(FAST, ("\nt = 2.0", "\nt = 2.5"))), plain)
    for words, (p, table) in cases.items():
        with pytest.raises(DesignError) as exc:
            resolve_latch(p, table)
        assert exc.value.field == "design.table", words
        assert words in exc.value.reason, exc.value.reason


# ---------------------------------------------------------------------------------------
# Everything together on the robot


def test_compress_gives_the_firmwares_gains_and_latch_maps(robot_problem, robot_zoh,
                                                           robot_exact):
    q = robot_zoh.table
    sp, K, k0, L, Lam, lam0 = compress(robot_problem, robot_exact, q, 1e-3)
    for got, want in zip((K, k0, L), evaluate(sp, q.stage_start)):
        np.testing.assert_array_equal(got, want)
    assert Lam.dtype == lam0.dtype == np.float32 and Lam.shape == q.Lambda.shape
    implemented = q.with_arrays(K=K, k0=k0, L=L)
    # Exact before rounding; after it, at the float32 floor (|lambda0| ~ 5, ulp 4.8e-7) as
    # the per-tick table is (4.3e-8).
    Lam64, lam0_64 = resolve_latch(robot_problem, implemented)
    assert _residual(robot_problem, replace(implemented, Lambda=Lam64, lambda0=lam0_64)) < 1e-11
    law = replace(implemented, Lambda=Lam, lambda0=lam0)
    assert _residual(robot_problem, law) < 2e-7
    J = evaluate_table(robot_problem, law, path=False).J
    assert J == pytest.approx(robot_zoh.implemented.J, rel=1e-6)


def test_on_a_coarse_spline_only_the_re_solved_latch_meets_the_constraints(robot_problem,
                                                                          robot_zoh,
                                                                          robot_exact):
    """Two spans a stage (10 % gain error): the design's latch maps miss the constraints by
    6e-4; re-solved, they meet them as the per-tick table does. (Least-squares errors are
    orthogonal to smooth functions, so fine fits barely move the constraints at all.)"""
    q = robot_zoh.table
    sp, K, k0, L, Lam, lam0 = compress(robot_problem, robot_exact, q, 0.5, initial_spans=2)
    assert [sp.spans(s) for s in range(sp.n_stages)] == [2, 2]
    assert _residual(robot_problem, q.with_arrays(K=K, k0=k0, L=L)) > 1e-4
    assert _residual(robot_problem, q.with_arrays(K=K, k0=k0, L=L, Lambda=Lam,
                                                  lambda0=lam0)) < 2e-7
