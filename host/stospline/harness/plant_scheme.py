"""How many plant steps per controller tick: enough that the plant is truth, not a second
source of error.

The harness advances the plant by exponential Euler–Maruyama steps (`montecarlo.simulate`):
exact for the mean, with an O(1/substeps) error in the second moments and so in the expected
cost. That error is known exactly: the oracle evaluates the same scheme
(``evaluate_table(..., propagator="euler")``). `choose_substeps` picks the fewest steps (a
power of two) whose bias in the expected cost is at most `tolerance` Monte Carlo standard
errors of the run being planned, the standard error predicted from a small pilot run on a
random stream of its own (the run's own streams are untouched).

With ``scheme="weak2"`` the plant runs the weak-order-two substitute of each stage
(`harness.weak_scheme`, `scheme_problem`), whose bias falls as 1/substeps^2; its bias is
computed the same way, by the oracle of the steps the harness runs.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from stospline.problem.faults import Faults
from stospline.problem.model import Problem
from stospline.harness.controller import CompiledController
from stospline.oracle.faults import evaluate_with_faults, has_exact_oracle
from stospline.harness.montecarlo import simulate
from stospline.harness.weak_scheme import scheme_problem
from stospline.oracle.evaluate import Moments, evaluate_table
from stospline.table.format import GainTable

__all__ = ["SubstepChoice", "choose_substeps", "scheme_bias", "scheme_moments", "PILOT_PATHS",
           "TOLERANCE"]

PILOT_PATHS = 256     # paths of the run that predicts the cost's standard deviation
TOLERANCE = 0.1       # bias allowed, in Monte Carlo standard errors of the planned run
# The pilot's standard deviation has a relative sampling error of a few per cent (256 paths);
# aiming at 0.8 of the predicted standard error keeps the bound for the run itself.
_SAFETY = 0.8
# The pilot's stream: a child of SeedSequence(seed) that no run's block uses (block i >= 1
# uses child i - 1, montecarlo.block_seed).
_PILOT_STREAM = 2**32 - 1


@dataclass(frozen=True)
class SubstepChoice:
    """The plant steps per tick chosen for a run, and why."""
    substeps: int
    bias: float           # the scheme's exact bias in the expected cost at `substeps`
    target: float         # the bound |bias| had to meet: tolerance x predicted standard error
    stderr: float         # predicted Monte Carlo standard error of the run's mean cost
    pilot_paths: int
    met: bool             # False when even the largest allowed number misses the target
    scheme: Moments       # the oracle of the plant scheme at `substeps` (bias = scheme.J - J)


def scheme_moments(problem: Problem, table: GainTable, substeps: int,
                   faults: Faults | None = None, scheme: str = "euler") -> Moments:
    """The oracle of `table` with the plant scheme's `substeps` steps per tick, in the loop
    with `faults` when they are linear (`fault_oracle`); nonlinear faults have no oracle, and
    the fault-free loop's scheme stands in for them (the plant's error, not the faults').
    `scheme` "weak2": the steps of `weak_scheme.scheme_problem` (without faults only)."""
    if scheme != "euler":
        if faults is not None and faults.any:
            raise ValueError(f"scheme {scheme}: a loop with faults is not supported")
        return evaluate_table(scheme_problem(problem, substeps, scheme), table,
                              propagator="euler", substeps=substeps, path=False)
    if faults is not None and faults.any and has_exact_oracle(table, faults):
        return evaluate_with_faults(problem, table, faults, propagator="euler",
                                    substeps=substeps)
    return evaluate_table(problem, table, propagator="euler", substeps=substeps, path=False)


def scheme_bias(problem: Problem, table: GainTable, substeps: int, exact_cost: float) -> float:
    """Expected cost under the plant scheme with `substeps` steps per tick, minus the exact
    one (`exact_cost`, the oracle's cost of the same table with the exact plant)."""
    return scheme_moments(problem, table, substeps).J - exact_cost


def choose_substeps(problem: Problem, controller: CompiledController, exact_cost: float, *,
                    paths: int, seed: int, tolerance: float = TOLERANCE,
                    limit: int = 10_000, faults: Faults | None = None,
                    scheme: str = "euler") -> SubstepChoice:
    """The fewest plant steps per tick (1, 2, 4, ...; at most `limit`) whose exact bias in
    the expected cost is at most `tolerance` standard errors of a `paths`-path run.

    The standard error is predicted from a pilot run of ``min(paths, PILOT_PATHS)`` paths with
    one step per tick, on a child stream of ``SeedSequence(seed)`` that no block of the run
    uses (so the run seeded with `seed` is the same whatever the pilot did). Without noise
    (every pilot path alike) the target is rounding: 1e-9 of the cost's magnitude. With
    `faults` (default ``problem.faults``) the pilot and the scheme's oracle include them;
    `exact_cost` is then the exact cost of the faulty loop (`scheme_moments`). With `scheme`
    "weak2" the pilot and the oracle run its steps (`weak_scheme`); its bias falls as
    1/substeps^2, which the first jump assumes (the doubling after it checks)."""
    faults = problem.faults if faults is None else faults
    table = controller.table
    pilot_paths = min(paths, PILOT_PATHS)
    pilot_seed = np.random.SeedSequence(seed, spawn_key=(_PILOT_STREAM,))
    pilot = simulate(scheme_problem(problem, 1, scheme), controller, paths=pilot_paths,
                     seed=pilot_seed, substeps=1, faults=faults)
    spread = pilot.cost_std() if pilot_paths > 1 else 0.0
    stderr = spread / math.sqrt(paths)
    target = max(tolerance * _SAFETY * stderr, 1e-9 * max(1.0, abs(exact_cost)))

    substeps = 1
    order = 1 if scheme == "euler" else 2
    moments = scheme_moments(problem, table, substeps, faults, scheme)
    if abs(moments.J - exact_cost) > target:
        # The bias falls as 1/substeps^order: jump to the predicted power of two, then double.
        ratio = (abs(moments.J - exact_cost) / target) ** (1.0 / order)
        substeps = min(limit, 2 ** math.ceil(math.log2(ratio)))
        moments = scheme_moments(problem, table, substeps, faults, scheme)
        while abs(moments.J - exact_cost) > target and substeps < limit:
            substeps = min(limit, 2 * substeps)
            moments = scheme_moments(problem, table, substeps, faults, scheme)
    bias = moments.J - exact_cost
    return SubstepChoice(substeps, bias, target, stderr, pilot_paths, abs(bias) <= target,
                         moments)
