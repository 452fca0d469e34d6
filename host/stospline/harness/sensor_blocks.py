"""The sensor loop's Monte Carlo (`estimator_loop.simulate_estimator`) in blocks of paths, on
every core or a Dask cluster, as `montecarlo.simulate` runs the full-state loop.

Block i of a run holds paths ``[i B, (i + 1) B)`` (B = `SENSOR_BLOCK_PATHS`) and draws every
random number of its paths (the start, the sensor's noise, the plant's) from its own stream,
`montecarlo.block_seed` (block 0 from the seed's own, so a run of at most B paths is
`simulate_estimator`'s with that seed). Each block summarises itself (`path_stats.RunStats`)
and the summaries merge in block order, so the result depends on the seed and the paths only,
not on how many processes ran the blocks.

B is larger than the full-state harness's `montecarlo.BLOCK_PATHS`: the sensor loop makes a
few numpy and C calls per tick for the whole block (the sensor's readings, the filter's step,
the plant), about 55 µs a tick on this machine, which 2048 paths (~0.5 µs a path-tick) make
a few per cent of a block's time (`tools/bench/sensor_loop_rate.py` prints the rate).
"""
from __future__ import annotations

from dataclasses import dataclass

from stospline import progress
from stospline.estimator.ctable import EstimatorTable
from stospline.harness.estimator_loop import build_estimator_controller, simulate_estimator
from stospline.harness.montecarlo import (MonteCarloResult, _Block, _dask_blocks, _Gather,
                                          _parallel_blocks, block_counts, block_seed,
                                          check_counts, usable_workers)
from stospline.harness.path_stats import CorridorExits, RunStats

__all__ = ["SENSOR_BLOCK_PATHS", "simulate_sensor_blocks"]

SENSOR_BLOCK_PATHS = 2048
# Below this many path-ticks a run stays in this process (the full-state harness's threshold
# over the ratio of the two loops' path-tick costs, ~20).
_PARALLEL_WORK = 100_000


@dataclass(frozen=True)
class _SensorJob:
    """What every block of a sensor run shares."""
    problem: object
    seed: object
    substeps: int
    est: EstimatorTable
    block_paths: int


def _sensor_block(job: _SensorJob, ctl, block: int, paths: int, *,
                  report: bool = False) -> _Block:
    """Block `block` of a `paths`-path run of the sensor loop, as a `montecarlo._Block`."""
    start = block * job.block_paths
    count = min(job.block_paths, paths - start)
    mc, rec = simulate_estimator(job.problem, ctl, paths=count,
                                 seed=block_seed(job.seed, block), substeps=job.substeps)
    exits = mc.exits
    if exits is not None and start:        # the examples' path indices are the run's
        exits = CorridorExits(exits.paths, exits.by_tick, exits.by_wall,
                              [[(p + start, t, w) for p, t, w in ex] for ex in exits.examples])
    stats = RunStats(count, mc.cost_moments, mc.knot_moments, rec["x_sum"], mc.worst_status,
                     mc.saturated_tick_count, mc.saturated_path_count, mc.u_low, mc.u_high,
                     mc.cost_sample, exits)
    out = _Block(stats)
    if block == 0:
        out.sample_x, out.sample_u = mc.sample_x, mc.sample_u
    return out


def _dask_sensor_block(job: _SensorJob, table, block: int, paths: int) -> _Block:
    """One block on a Dask worker: the estimator controller from the worker's build cache."""
    ctl = build_estimator_controller(job.problem, table, job.est)
    return _sensor_block(job, ctl, block, paths)


def simulate_sensor_blocks(problem, ctl, *, paths: int, seed, substeps: int = 1,
                           workers: int | None = None, scheduler: str | None = None,
                           force_workers: bool = False,
                           block_paths: int = SENSOR_BLOCK_PATHS) -> MonteCarloResult:
    """`paths` paths of the sensor loop through `ctl` (`estimator_loop.EstimatorController`)
    in blocks of `block_paths`, each with its own stream (`montecarlo.block_seed`).

    `workers`, `scheduler` and `force_workers` as `montecarlo.simulate`'s: forked processes
    (runs below ~1e5 path-ticks stay in this process), or a Dask cluster (an address, or
    ``"local"``) whose workers compile the same tables (or load them from their cache). The
    result is the same for any number of workers. Returns the merged statistics: cost and
    knot moments, the mean path, statuses, saturation, block 0's first path, and with
    corridors the true state's exits (`simulate_estimator`'s; no per-path records and no
    estimation-error moments)."""
    check_counts(paths=paths, substeps=substeps, block_paths=block_paths)
    table = ctl.table
    job = _SensorJob(problem, seed, int(substeps), ctl.est, int(block_paths))
    blocks = -(-paths // block_paths)
    workers = usable_workers(workers, force_workers)
    parallel = (workers > 1 and blocks > 1
                and paths * table.n_ticks * substeps >= _PARALLEL_WORK)
    bar = progress.start(f"sensor loop ({paths} paths)", paths * table.n_ticks,
                         unit="path-tick")
    try:
        if scheduler is not None:
            parts = _dask_blocks(scheduler, job, table, paths, workers, run=_dask_sensor_block,
                                 block_paths=block_paths)
        elif parallel:
            parts = _parallel_blocks(job, ctl, paths, workers, run=_sensor_block,
                                     block_paths=block_paths)
        else:
            parts = _in_process(job, ctl, paths, table.n_ticks)
        run = _Gather(False)
        for part in parts:
            run.add(part)
    finally:
        progress.finish(bar)
    return run.result(problem, table, int(substeps), problem.faults)


def _in_process(job: _SensorJob, ctl, paths: int, ticks: int):
    for i, _, count in block_counts(paths, job.block_paths):
        yield _sensor_block(job, ctl, i, paths)
        progress.advance(count * ticks)
