"""Which knots' constraints each latched multiplier vector covers, and where it is latched.

* ``stagewise``: stage k latches ``v = lambda_k`` for its own end knot k at its start, so the
  constraint holds conditionally on ``X(t_k)`` (the paper's dynamic programming).
* ``joint``: one vector ``v = [lambda_0; ...; lambda_{N-1}]`` for every constrained knot is
  latched at ``t0``, so ``E_{t0,x0}{C2 X(t_k)} = zeta_k`` holds exactly as problem (1) states.

Both designers run the same backward sweep: within a group the multiplier terms
``2 x'N lambda + 2 m'lambda - lambda'W lambda`` accumulate; at the group's latch stage the
maximising ``lambda = W^-1 (N'x + m)`` is substituted.
"""
from __future__ import annotations

from dataclasses import dataclass

from stospline.problem.model import Problem

__all__ = ["MODES", "LatchGroup", "latch_groups"]

MODES = ("stagewise", "joint")


@dataclass(frozen=True)
class LatchGroup:
    """Multipliers latched at the start of `latch_stage`, covering `knots` (ascending);
    ``offsets[i]`` is where knot ``knots[i]``'s multipliers start inside the vector."""
    latch_stage: int
    knots: tuple[int, ...]
    offsets: tuple[int, ...]
    size: int
    last_stage: int

    def offset_of(self, knot: int) -> int:
        return self.offsets[self.knots.index(knot)]


def latch_groups(problem: Problem, mode: str) -> tuple[list[LatchGroup], list[LatchGroup | None]]:
    """Return the groups and, per stage, the group whose multipliers act on that stage."""
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    for k, kn in enumerate(problem.knots):
        if kn.constraint is not None and kn.constraint.is_band:
            from stospline.errors import DesignError
            raise DesignError(f"knots[{k}].constraint", "a band (lower/upper) needs the joint "
                                                        "band design (stospline.design.bands; CLI "
                                                        "--mode joint)")
    constrained = [k for k, kn in enumerate(problem.knots) if kn.n_constraints]
    n_st = len(problem.knots)
    if mode == "stagewise":
        sets = [(k, [k], k) for k in constrained]
    else:
        sets = [(0, constrained, constrained[-1])] if constrained else []
    groups, of_stage = [], [None] * n_st
    for start, knots, last in sets:
        offs, acc = [], 0
        for k in knots:
            offs.append(acc)
            acc += problem.knots[k].n_constraints
        g = LatchGroup(start, tuple(knots), tuple(offs), acc, last)
        groups.append(g)
        for s in range(start, last + 1):
            of_stage[s] = g
    return groups, of_stage
