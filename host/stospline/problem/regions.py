"""Band knots added to a problem: what ``[[regions]]`` expand to, and the working set of the
every-tick design (`stospline.design.every_tick`)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from stospline.problem.model import Constraint, Knot, Problem

__all__ = ["merge_constraints", "with_bands"]


def merge_constraints(a: Constraint | None, b: Constraint) -> Constraint:
    """The rows of `b` appended to `a` (an equality if every row is one)."""
    if a is None:
        return b
    (alo, ahi), (blo, bhi) = a.bounds, b.bounds
    C = np.vstack([a.C, b.C])
    lo, hi = np.concatenate([alo, blo]), np.concatenate([ahi, bhi])
    return Constraint(C, lo.copy()) if np.array_equal(lo, hi) else Constraint(C, None, lo, hi)


def with_bands(problem: Problem, bands: dict[int, Constraint]) -> Problem:
    """`problem` with a band at each tick index (from t0) of `bands`: rows added to the knot
    at that tick, else a new knot without penalty that splits the stage it falls in (both
    pieces keep that stage's data, which is a function of absolute time)."""
    t0, hz = problem.t0, problem.tick_hz
    at = {int(round((kn.t - t0) * hz)): k for k, kn in enumerate(problem.knots)}
    knot_ticks = np.array(sorted(at))
    entries = {j: (problem.knots[k], problem.stages[k]) for j, k in at.items()}
    for j, con in bands.items():
        if j in entries:
            kn, st = entries[j]
            entries[j] = (Knot(kn.t, kn.penalty, merge_constraints(kn.constraint, con)), st)
        else:
            # The stage of the first knot at or after tick j.
            k = at[int(knot_ticks[np.searchsorted(knot_ticks, j)])]
            entries[j] = (Knot(t0 + j / hz, None, con), problem.stages[k])
    order = sorted(entries)
    return replace(problem, knots=tuple(entries[j][0] for j in order),
                   stages=tuple(entries[j][1] for j in order))
