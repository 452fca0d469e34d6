"""Spline columns of a parametric table (`stospline.table.spline.params`,
`stospline.refine.spline_params`): the C test's expected values (tests/c/params_spline_expected.h)
are the float32 specification's; at the nominal the specification is the spline table's own
command bit for bit; the columns meet the spline tolerance and their error over the box is
the worst vertex's; the re-solved latch columns put the shift of every knot constraint on
its target, the per-tick design's do not."""
import sys

import numpy as np
import pytest

from conftest import EXAMPLES, REPO
from stospline.oracle.evaluate import evaluate_table
from stospline.oracle.over_box import vertices
from stospline.options import resolve_options
from stospline.problem import load_problem
from stospline.problem.parameters import problem_at
from stospline.refine.spline_params import _latch_columns, spline_parametric_of
from stospline.table.parametric import ParametricTable
from stospline.table.spline.fit import command as spline_command
from stospline.table.spline.params import command

sys.path.insert(0, str(REPO / "tests" / "c"))
import params_spline_reference  # noqa: E402


@pytest.fixture(scope="module")
def goal():
    problem = load_problem(EXAMPLES / "robot_goal.toml")
    return problem, spline_parametric_of(problem)


def test_expected_header_is_the_specification(goal):
    assert (REPO / "tests/c/params_spline_expected.h").read_text() == \
        params_spline_reference.expected(goal[1]), \
        "regenerate tests/c/params_spline_expected.h with tests/c/params_spline_reference.py"


def test_nominal_is_the_spline_command_and_d_moves_it(goal):
    _, sp = goal
    rng = np.random.default_rng(36)
    t = sp.table
    n, m, nl = t.dims
    d0 = np.zeros(len(sp.per_tick.parameters), np.float32)
    moved = 0
    for j in rng.integers(0, t.n_ticks, 12):
        x = rng.uniform(-1, 1, n).astype(np.float32)
        v = rng.uniform(-1, 1, nl).astype(np.float32)
        want = spline_command(t.spline, t.stage_start, int(j), x, v) + np.float32(0)
        got = command(t, sp.columns, int(j), x, v, d0) + np.float32(0)
        assert got.view(np.uint32).tolist() == want.view(np.uint32).tolist()
        d = np.float32([0.3, -0.4])
        exact = (sp.columns.S_k0[j].astype(float) @ d.astype(float))
        shifted = command(t, sp.columns, int(j), x, v, d).astype(float)
        # the columns' term as evaluated, to a few float32 roundings of the command
        np.testing.assert_allclose(want.astype(float) - shifted, exact, rtol=0,
                                   atol=1e-5 * (1 + np.abs(want).max()))
        moved += int(np.any(shifted != want))
    assert moved == 12


def test_columns_meet_the_tolerance_and_box_error_is_the_worst_vertex(goal):
    problem, sp = goal
    pt, cols = sp.per_tick, sp.columns
    peak = np.abs(pt.S_k0).max(axis=0)
    tol = resolve_options(problem).spline_tolerance
    assert np.all(cols.error <= tol * peak + 1e-300)
    assert cols.error.max() > 0            # a fit, not a copy
    D = cols.S_k0.astype(float) - pt.S_k0
    brute = max(np.abs(D @ (th - pt.nominal)).max(axis=0).max()
                for th in vertices(pt.parameters))
    assert cols.box_error.max() == pytest.approx(brute, rel=1e-12)


def _knot_shift(problem, ptable, theta):
    """C2 E x at each knot constraint at theta less at the nominal, less the value's shift."""
    def at(th):
        p2 = problem_at(problem, th)
        mean = evaluate_table(p2, ptable.at(th), path=True, output=np.eye(problem.n)).path_mean
        return np.concatenate([kn.constraint.C @ mean[int(round((kn.t - problem.t0)
                                                                * problem.tick_hz))]
                               - kn.constraint.value
                               for kn in p2.knots if kn.constraint is not None])
    return np.abs(at(theta) - at(ptable.nominal)).max()


def test_resolved_latch_columns_hold_the_constraints(goal):
    """In double precision (the columns unrounded) the re-solved latch columns move every
    knot constraint exactly with its value; the per-tick design's miss by the fit's error."""
    problem, sp = goal
    P = len(sp.per_tick.parameters)
    exact = _latch_columns(problem, sp.table, sp.columns.S_k0, P, rounded=False)
    theta = vertices(sp.per_tick.parameters)[-1]
    resolved = ParametricTable(sp.flashed.table, sp.flashed.S_k0, exact, sp.flashed.parameters)
    design = ParametricTable(sp.flashed.table, sp.flashed.S_k0, sp.per_tick.S_lambda0,
                             sp.flashed.parameters)
    good, bad = _knot_shift(problem, resolved, theta), _knot_shift(problem, design, theta)
    assert good < 1e-10 and bad > 30 * good, (good, bad)


def test_tables_without_spline_columns_are_refused(goal):
    from dataclasses import replace
    from stospline.errors import DesignError
    from stospline.refine.spline_params import spline_parametric
    problem, sp = goal
    for bad, what in ((replace(sp.table, spline=None), "float32 spline table"),
                      (replace(sp.table, delay_ticks=1), "delay")):
        with pytest.raises(DesignError, match=what) as info:
            spline_parametric(problem, sp.per_tick, bad)
        assert info.value.field == "design.table"
