"""Exact sensitivities of a design's feed-forward ``k0(t)`` and latch offsets ``lambda0`` to
its runtime parameters (`stospline.problem.parameters`).

The gains ``K``, ``L``, ``Lambda`` come from the Riccati, ``N`` and ``W`` equations, which see
neither knot targets nor constraint values nor the drift ``f``; the linear terms ``p`` and
multiplier offsets ``m`` (continuous and exact zero-order hold alike) are the solution of
linear equations driven by those *sources* (targets, constraint values, ``f``, ``q``, ``r``,
the delayed plan's safe command), and ``k0``, ``lambda0`` are linear in ``p`` and ``m``. So
``k0`` and ``lambda0`` are linear in the source vector, and the column of parameter ``j`` is
the design of the problem whose only source is parameter ``j``'s unit (every other source
zero): the same backward recursion, with the same gains, run on that source alone. No
difference of two designs is taken, so nothing cancels. ``x0`` is not a source: the law does
not depend on it (only the cost and the means do).

A problem with bands (knot ``lower``/``upper`` rows, ``[[regions]]``) has a law whose active
set can change with the parameters. Its parametric design keeps the nominal's active set
(`stospline.oracle.parametric`): the column of parameter ``j`` is then the design of
`unit_problem` with the bands dropped, a fixed affine law, and the bands hold over the box
because the nominal is designed with them tightened by its worst-case shift
(`stospline.oracle.over_box`).
"""
from __future__ import annotations

from dataclasses import replace
from typing import Callable

import numpy as np

from stospline.errors import DesignError
from stospline.problem.model import Problem, Stage
from stospline.problem.series import sample_varying

__all__ = ["unit_problem", "source_designs", "check_parametric"]



class _Fixed:
    """Time-varying stage data with some fields held at constants (the sources replaced)."""

    def __init__(self, outer, fixed: dict):
        self.outer, self.fixed = outer, fixed

    def __call__(self, t: float) -> dict:
        d = dict(self.outer(t))
        d.update({k: v for k, v in self.fixed.items() if k in d})
        return d

    def many(self, times) -> dict:
        d = dict(sample_varying(self.outer, times))
        times = np.asarray(times, dtype=float)
        for k, v in self.fixed.items():
            if k in d:
                v = np.asarray(v, dtype=float)
                d[k] = np.broadcast_to(v, (times.size,) + v.shape).copy()
        return d


def _sourced_stage(stage: Stage, f: np.ndarray, q: np.ndarray) -> Stage:
    """`stage` with ``r = rho = 0``, linear cost term `q` and drift `f`, constant in time."""
    n, m = stage.B.shape
    fixed = {"q": q, "r": np.zeros(m), "rho": 0.0, "f": f}
    varying = None if stage.varying is None else _Fixed(stage.varying, fixed)
    return replace(stage, varying=varying, **fixed)


def unit_problem(problem: Problem, j: int) -> Problem:
    """The problem whose only source is parameter `j` at 1: every knot target and constraint
    value, ``q``, ``r``, ``rho``, ``f`` and the safe command zero, except the values parameter
    `j` sets, which are 1. A tracking path's offset ``i`` at 1 is the source
    ``q = -C'Qy e_i`` (the tracking cost's ``q`` is ``-C'Qy (y0(t) + offset)``; ``Q`` keeps its
    samples). Its design's ``k0`` and ``lambda0`` are parameter `j`'s columns."""
    n = problem.n
    knots = []
    for kn in problem.knots:
        pen, con = kn.penalty, kn.constraint
        if pen is not None:
            pen = replace(pen, target=np.zeros_like(pen.target))
        if con is not None:
            con = _equalities(con)
        knots.append(replace(kn, penalty=pen, constraint=con))
    f = [np.zeros(n) for _ in problem.stages]
    q = [np.zeros(n) for _ in problem.stages]
    for t in problem.parameters[j].targets:
        if t.kind == "value":
            knots[t.at].constraint.value[t.index] = t.scale   # the row as the reader scaled it
        elif t.kind == "target":
            knots[t.at].penalty.target[t.index] = 1.0
        elif t.kind == "f":
            f[t.at][t.index] = 1.0
        elif t.kind == "offset":
            C, Qy, _ = problem.stages[t.at].origin.tracking
            q[t.at] = q[t.at] - C.T @ Qy[:, t.index]
    stages = tuple(_sourced_stage(s, fk, qk) for s, fk, qk in zip(problem.stages, f, q))
    return replace(problem, knots=tuple(knots), stages=stages, u_hold=None,
                   x0=np.zeros(n), parameters=(), tick_regions=())


def _equalities(con):
    """The equality rows of `con` with value 0 (None if it has none), the band rows dropped
    (a band constraint has no ``value`` a parameter could set)."""
    if not con.is_band:
        return replace(con, value=np.zeros_like(con.value))
    lo, hi = con.bounds
    eq = lo == hi
    if not eq.any():
        return None
    return type(con)(con.C[eq], np.zeros(int(eq.sum())))


def source_designs(problem: Problem, design: Callable[[Problem], object]) -> list:
    """Per parameter, the tick gains ``(tick_hz, stages)`` of `design` (a function from a
    problem to a design with ``tick_gains``, e.g. ``lambda p: design_zoh(p, mode=...)``) run on
    its `unit_problem`; None for a parameter that sets only ``x0`` (its columns are zero)."""
    check_parametric(problem)
    out = []
    for j, par in enumerate(problem.parameters):
        if all(t.kind == "x0" for t in par.targets):
            out.append(None)
            continue
        out.append(design(unit_problem(problem, j)).tick_gains())
    return out


def check_parametric(problem: Problem) -> None:
    """DesignError unless the problem declares runtime parameters."""
    if not problem.parameters:
        raise DesignError("parameters", "the problem declares no runtime parameters")
