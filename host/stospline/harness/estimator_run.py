"""One Monte Carlo run of the loop on a sensor, with the exact numbers it is compared with:
the flashed float32 filter tables (`estimator.ctable`), the compiled C controller that runs
them (`estimator_loop`), the plant steps per tick, and the estimator oracle of those tables
with the exact plant and with the plant scheme.

The plant steps per tick are chosen as `plant_scheme.choose_substeps` chooses them: the
fewest (a power of two) whose exact bias in the expected cost is at most `TOLERANCE` Monte
Carlo standard errors of the run, the standard error predicted by a pilot on a stream of its
own.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from stospline.estimator.ctable import EstimatorTable, estimator_table
from stospline.estimator.oracle import (EstimatorLoop, estimator_faults_unsupported,
                                        evaluate_estimator)
from stospline.harness.estimator_loop import build_estimator_controller, simulate_estimator
from stospline.harness.montecarlo import MonteCarloResult
from stospline.harness.plant_scheme import PILOT_PATHS, TOLERANCE, SubstepChoice
from stospline.harness.sensor_blocks import SENSOR_BLOCK_PATHS, simulate_sensor_blocks

__all__ = ["SensorRun", "run_sensor_loop", "sensor_loop_unsupported", "flashed_filter",
           "sensor_outputs", "sensor_path_mean", "count_sensor_exits"]

_SAFETY = 0.8            # as plant_scheme's: the pilot's spread has a sampling error
_PILOT_STREAM = 2**32 - 1
SUBSTEP_LIMIT = 1024


@dataclass
class SensorRun:
    """``mc`` the run; ``record`` the recorded paths and the knot estimation errors
    (`simulate_estimator`); ``exact`` and ``scheme`` the estimator oracle of the flashed
    tables with the exact plant and with the run's plant scheme; ``tables`` the filter's;
    with faults, ``nominal`` the exact oracle of the flashed tables without them."""
    mc: MonteCarloResult
    record: dict
    exact: EstimatorLoop
    scheme: EstimatorLoop
    tables: EstimatorTable
    nominal: EstimatorLoop | None = None


def sensor_loop_unsupported(problem, table) -> tuple[str, str] | None:
    """``(field, reason)`` when the sensor loop's Monte Carlo cannot run `table` on
    `problem`, else None."""
    why = estimator_faults_unsupported(problem.faults)
    if why:
        return why
    if getattr(table, "delay_ticks", 0):
        return "delay_ticks", ("a table designed for a one-tick delay has no estimator form; "
                               "the sensor loop runs without a delay")
    if table.band_qp is not None:
        return "knots", ("a band constraint (lower/upper) latches by a QP on the estimate, "
                         "which the sensor loop does not run")
    if getattr(table, "arith", "float32") != "float32":
        return "arith", "the estimator's firmware is float32"
    return None


def _choose(problem, ctl, tables_loop, gains, pred, table, *, paths: int,
            seed: int) -> tuple[SubstepChoice, EstimatorLoop]:
    pilot_paths = min(paths, PILOT_PATHS)
    pilot_seed = np.random.SeedSequence(seed, spawn_key=(_PILOT_STREAM,))
    pilot, _ = simulate_estimator(problem, ctl, paths=pilot_paths, seed=pilot_seed, substeps=1)
    stderr = (pilot.cost_std() if pilot_paths > 1 else 0.0) / math.sqrt(paths)
    exact_J = tables_loop.moments.J
    target = max(TOLERANCE * _SAFETY * stderr, 1e-9 * max(1.0, abs(exact_J)))

    def scheme(s: int) -> EstimatorLoop:
        return evaluate_estimator(problem, table, gains=gains, predictor=pred,
                                  propagator="euler", substeps=s, faults=problem.faults)
    substeps, loop = 1, scheme(1)
    if abs(loop.moments.J - exact_J) > target:
        # The bias falls as 1/substeps: jump to the predicted power of two, then double.
        substeps = min(SUBSTEP_LIMIT, 2 ** math.ceil(math.log2(
            abs(loop.moments.J - exact_J) / target)))
        loop = scheme(substeps)
        while abs(loop.moments.J - exact_J) > target and substeps < SUBSTEP_LIMIT:
            substeps = min(SUBSTEP_LIMIT, 2 * substeps)
            loop = scheme(substeps)
    bias = loop.moments.J - exact_J
    return SubstepChoice(substeps, bias, target, stderr, pilot_paths, abs(bias) <= target,
                         loop.moments), loop


def run_sensor_loop(problem, table, *, paths: int, seed: int, substeps: int | str = "auto",
                    record: int = 0, build_dir=None,
                    spline_tolerance: float | None = None) -> SensorRun:
    """`paths` paths of `table`'s law on the estimate of the filter of
    ``problem.measurement``, through the compiled C, with the oracle of the flashed tables
    (in the loop with ``problem.faults``, which the filter is designed without); the filter's
    gains as a spline fitted to `spline_tolerance`, by default a spline table's own (what
    ``stospline design`` writes for it: `flashed_filter`).

    Raises ValueError (`sensor_loop_unsupported`) for a loop the run does not support."""
    why = sensor_loop_unsupported(problem, table)
    if why:
        raise ValueError(f"{why[0]}: {why[1]}")
    tables, gains, pred = flashed_filter(problem, table,   # the filter knows no faults
                                         spline_tolerance=spline_tolerance)
    exact = evaluate_estimator(problem, table, gains=gains, predictor=pred, path=True,
                               faults=problem.faults)
    ctl = build_estimator_controller(problem, table, tables, build_dir=build_dir)
    choice = None
    if substeps == "auto":
        choice, scheme = _choose(problem, ctl, exact, gains, pred, table, paths=paths, seed=seed)
        substeps = choice.substeps
    else:
        scheme = evaluate_estimator(problem, table, gains=gains, predictor=pred,
                                    propagator="euler", substeps=int(substeps),
                                    faults=problem.faults)
    mc, rec = simulate_estimator(problem, ctl, paths=paths, seed=seed, substeps=int(substeps),
                                 record=record)
    mc.substep_choice = choice
    nominal = (evaluate_estimator(problem, table, gains=gains, predictor=pred)
               if problem.faults.any else None)
    return SensorRun(mc, rec, exact, scheme, tables, nominal)


def flashed_filter(problem, table, *, spline_tolerance: float | None = None
                   ) -> tuple[EstimatorTable, np.ndarray, np.ndarray]:
    """``(tables, gains, predictor)``: the filter of `table`'s loop on ``problem.measurement``
    as flashed (`estimator.ctable`: LMMSE gains from the loop's exact moments, rounded to
    float32, or their spline fitted to `spline_tolerance`) and its per-tick gains and
    predictor maps. `spline_tolerance` defaults to a spline table's own
    (``table.spline_tolerance``, the design's ``spline_tolerance``): a spline design flashes
    its filter's gains as a spline too (`pipeline`), so every consumer of this function (the
    Monte Carlo run, `sensor_outputs`, `sensor_path_mean`, `count_sensor_exits`) sees that
    loop; a per-tick table's filter has per-sample gains."""
    if spline_tolerance is None and getattr(table, "spline", None) is not None:
        spline_tolerance = getattr(table, "spline_tolerance", None)
    tables = estimator_table(problem, table, evaluate_estimator(problem, table),
                             spline_tolerance=spline_tolerance)
    gains, pred = tables.per_tick()
    return tables, gains, pred


def sensor_outputs(problem, table, C: np.ndarray, flashed=None
                   ) -> tuple[float, np.ndarray, np.ndarray]:
    """``(J, y_mean, y_cov)`` of the sensor loop as flashed: its exact cost and the exact mean
    (ticks + 1, p) and covariance (ticks + 1, p, p) of the *true* output ``C x`` at every
    tick (`evaluate_estimator` with the flashed gains and predictor), for
    `oracle.exit_bound.exit_bounds`. The mean is the full-state loop's (the filter is
    unbiased, docs/theory/estimator.md) up to the float32 predictor's rounding; the spread is
    the larger one of a loop that acts on an estimate. `flashed`: `flashed_filter`'s result,
    if already made."""
    _, gains, pred = flashed if flashed is not None else flashed_filter(problem, table)
    loop = evaluate_estimator(problem, table, gains=gains, predictor=pred, output=C)
    return loop.moments.J, loop.moments.path_y_mean, loop.moments.path_y_cov


def sensor_path_mean(problem, table) -> np.ndarray | None:
    """The true state's mean at every tick (ticks + 1, n) of `table`'s law run on the estimate
    of the flashed filter of ``problem.measurement`` (`flashed_filter`), for
    `refine.every_tick.every_tick_check`; None without a sensor or for a table the sensor loop
    does not run (`sensor_loop_unsupported`)."""
    if problem.measurement is None or sensor_loop_unsupported(problem, table):
        return None
    _, gains, pred = flashed_filter(problem, table)
    return evaluate_estimator(problem, table, gains=gains, predictor=pred,
                              path=True).moments.path_mean


def count_sensor_exits(problem, table, corridor: int, *, paths: int, seed: int,
                       substeps: int = 1, build_dir=None, workers: int | None = None,
                       scheduler: str | None = None, force_workers: bool = False,
                       block_paths: int = SENSOR_BLOCK_PATHS) -> int:
    """How many of `paths` paths of the sensor loop (`table`'s law on the flashed filter's
    estimate, through the compiled C) leave corridor `corridor` of `problem` at some tick of
    its interval. The paths run in blocks of `block_paths`, each with its own stream, on
    `workers` processes or a Dask `scheduler` (`harness.sensor_blocks`): the count is the
    same for any number of workers. Raises ValueError (`sensor_loop_unsupported`) as
    `run_sensor_loop`."""
    why = sensor_loop_unsupported(problem, table)
    if why:
        raise ValueError(f"{why[0]}: {why[1]}")
    tables, _, _ = flashed_filter(problem, table)
    ctl = build_estimator_controller(problem, table, tables, build_dir=build_dir)
    mc = simulate_sensor_blocks(problem, ctl, paths=paths, seed=seed, substeps=substeps,
                                workers=workers, scheduler=scheduler,
                                force_workers=force_workers, block_paths=block_paths)
    return mc.exit_count(corridor)
