"""Corridor exits of a Monte Carlo run beside the oracle's bounds: counts, one-sided
Clopper-Pearson bounds overall, by time bin and by wall, as plain numbers for JSON.

The exits are those of the compiled C controller's paths (`montecarlo.simulate` counts each
path's first exit by tick and wall, `path_stats.CorridorExits`); the bounds are `exit_bound.exit_bounds` from the exact
moments of the implemented law. Clopper-Pearson intervals are exact for a binomial count
(conservative), so ``upper`` is a valid one-sided bound at its confidence for each number
on its own (the bins and walls are not corrected for being many).
"""
from __future__ import annotations

import numpy as np

from stospline.precision import verbatim
from stospline.oracle.exit_bound import exit_bounds
from stospline.harness.path_stats import EXIT_EXAMPLES, CorridorExits

__all__ = ["clopper_pearson_upper", "clopper_pearson_lower", "corridor_report",
           "corridor_outputs_of", "CONFIDENCE", "TIME_BINS"]

CONFIDENCE = 0.99      # one-sided
TIME_BINS = 6          # equal bins of the corridor's ticks in the reports


def clopper_pearson_upper(k: int, n: int, confidence: float = CONFIDENCE) -> float:
    """One-sided upper bound on a binomial probability after `k` successes in `n` trials:
    ``P(p <= upper) >= confidence`` (1 when k = n)."""
    # scipy.stats.beta.ppf's function (the same bits), without importing scipy.stats (~1 s)
    from scipy.special import betaincinv
    return 1.0 if k >= n else float(betaincinv(k + 1, n - k, confidence))


def clopper_pearson_lower(k: int, n: int, confidence: float = CONFIDENCE) -> float:
    """One-sided lower bound (0 when k = 0)."""
    from scipy.special import betaincinv
    return 0.0 if k <= 0 else float(betaincinv(k, n - k + 1, 1 - confidence))


# The last problem's and table's corridor outputs: (problem, table, outputs), held so that
# their ids are not reused while kept.
_OUTPUTS: list = []


def corridor_outputs_of(problem, table):
    """`exit_bound.corridor_outputs` of `problem` and `table`, kept for the same two objects
    (the last pair): `pipeline.simulate_problem` computes them while the paths run, and the
    run's summary (`corridor_report`) finds them."""
    from stospline.oracle.exit_bound import corridor_outputs
    hit = _OUTPUTS[0] if _OUTPUTS else None
    if hit is not None and hit[0] is problem and hit[1] is table:
        return hit[2]
    out = corridor_outputs(problem, table)
    _OUTPUTS[:] = [(problem, table, out)]
    return out


def _counted(k: int, n: int) -> dict:
    return {"exits": int(k), "estimate": k / n, "upper99": clopper_pearson_upper(k, n)}


def corridor_report(problem, table, exits: "CorridorExits | None", *, outputs=None,
                    with_bounds: bool = True, bins: int = TIME_BINS,
                    examples: int = EXIT_EXAMPLES) -> list[dict]:
    """One dict per corridor: its interval, epsilon, the analytic bounds (Cantelli: valid;
    Gaussian: an assumption) overall, at the worst tick, by time bin and by wall (each row of
    each polygon, and by physical wall: the rows on one line together), and, with a
    run's exits (`path_stats.CorridorExits`, ``MonteCarloResult.exits``), the Monte Carlo
    exits likewise with one-sided 99 % Clopper-Pearson upper bounds and the first `examples`
    (at most `EXIT_EXAMPLES`) exiting paths (index, time, wall). `outputs`: `exit_bound.corridor_outputs` if already computed;
    `with_bounds` False: no oracle bounds (``bound`` None; a table designed for a delay has
    no output moments)."""
    from stospline.problem.corridors import corridor_ticks
    if with_bounds and outputs is None:
        outputs = corridor_outputs_of(problem, table)
    h = 1.0 / problem.tick_hz
    out = []
    for i, c in enumerate(problem.corridors):
        bounds = (exit_bounds(c, *outputs[i], problem.t0, problem.tick_hz) if with_bounds
                  else None)
        lo, hi = corridor_ticks(c, problem.t0, problem.tick_hz)
        # Equal bins of whole seconds when they divide (0-999, 1000-1999, ...); the last
        # takes the closing tick.
        edges = np.unique(np.append(np.rint(np.linspace(lo, hi, bins + 1))[:-1], hi + 1)
                          ).astype(int)
        names = c.wall_names()
        physical = c.physical_walls()
        entry = {
            "t": verbatim(list(c.t)), "epsilon": verbatim(c.epsilon), "walls": names,
            "physical_walls": [{"wall": label, "rows": rows} for label, rows in physical],
            "bins_t": [[problem.t0 + a * h, problem.t0 + (b - 1) * h]
                       for a, b in zip(edges[:-1], edges[1:])],
            "bound": None if bounds is None else {
                tail: {"total": b.total, "sum": float(b.per_tick.sum()),
                       "worst_tick": b.worst_tick,
                       "worst_tick_t": problem.t0 + (lo + int(np.argmax(b.per_tick))) * h,
                       "by_bin": b.by_bins(edges), "by_wall": b.per_wall,
                       "by_physical_wall": [float(b.per_wall[rows].sum()) for _, rows in physical]}
                for tail, b in bounds.items()},
        }
        if exits is not None:
            n, by_tick, by_wall = exits.paths, exits.by_tick[i], exits.by_wall[i]
            entry["mc"] = {
                "paths": int(n), "confidence": CONFIDENCE, **_counted(int(by_tick.sum()), n),
                "by_bin": [_counted(int(by_tick[a:b].sum()), n)
                           for a, b in zip(edges[:-1], edges[1:])],
                "by_wall": [_counted(int(by_wall[w]), n) for w in range(len(names))],
                "by_physical_wall": [_counted(int(by_wall[rows].sum()), n)
                                     for _, rows in physical],
                "examples": [{"path": p, "t": problem.t0 + tick * h, "wall": wall}
                             for p, tick, wall in exits.examples[i][:examples]],
            }
            if c.epsilon is not None:
                entry["mc"]["meets_epsilon"] = entry["mc"]["upper99"] <= c.epsilon
        if c.epsilon is not None and bounds is not None:
            entry["bound"]["cantelli"]["meets_epsilon"] = bounds["cantelli"].total <= c.epsilon
        out.append(entry)
    return out
