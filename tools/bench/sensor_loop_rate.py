#!/usr/bin/env python3
"""CPU time per path-tick of the sensor loop's Monte Carlo against the full-state harness's,
in the same run, and the budget's constants for it (`stospline.budget`: SENSOR_PATH_TICK,
SENSOR_TICK).

Both run `--file` (default examples/robot_corridor_position_sensor.toml: the robot, 6000
ticks at 1 kHz, a position sensor at 50 Hz, a corridor) designed as the file says, one plant
step per tick, in this process (one worker; CPU time, so a loaded machine changes the figures
less than wall time would):

* **full state**: `harness.montecarlo.simulate` of the compiled C controller on the exact
  state (the file without its [measurement]), `--full-paths` paths;
* **sensor loop**: `harness.sensor_blocks.simulate_sensor_blocks` of the compiled C estimator
  controller (the law on the flashed filter's estimate, the sensor's readings drawn in numpy),
  `--paths` paths in blocks of `SENSOR_BLOCK_PATHS`, and `--small-paths` paths in blocks of
  `--small-block`: the difference gives the per-tick cost of a block (numpy and cffi calls),
  the rest the cost per path-tick.

Prints CPU ns per path-tick of each and their ratio, the two constants, and the budget's
Monte Carlo estimate of each loop (with the constants it holds) beside the measured time.

    PYTHONPATH=host .venv/bin/python tools/bench/sensor_loop_rate.py [--paths 4096]
        [--full-paths 20000] [--small-paths 512] [--small-block 64] [--file F]
"""
from __future__ import annotations

import argparse
import os
import time
from dataclasses import replace
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from stospline import budget  # noqa: E402
from stospline.harness.controller import build_controller  # noqa: E402
from stospline.harness.estimator_loop import build_estimator_controller  # noqa: E402
from stospline.harness.estimator_run import flashed_filter  # noqa: E402
from stospline.harness.montecarlo import simulate  # noqa: E402
from stospline.harness.sensor_blocks import (SENSOR_BLOCK_PATHS,  # noqa: E402
                                             simulate_sensor_blocks)
from stospline.pipeline import design_problem  # noqa: E402
from stospline.problem import load_problem  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


def cpu(run) -> float:
    start = time.process_time()
    run()
    return time.process_time() - start


def mc_seconds(problem, paths: int) -> float:
    """The budget's Monte Carlo term (and exit watch) for `paths` paths, one worker."""
    terms = budget.monte_carlo_terms(problem, paths=paths, substeps=1, workers=1)
    return sum(t.seconds for t in terms
               if t.what.startswith(("Monte Carlo", "the paths' exit watch")))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--file", default=str(ROOT / "examples/robot_corridor_position_sensor.toml"))
    ap.add_argument("--paths", type=int, default=2 * SENSOR_BLOCK_PATHS)
    ap.add_argument("--full-paths", type=int, default=20000)
    ap.add_argument("--small-paths", type=int, default=512)
    ap.add_argument("--small-block", type=int, default=64)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()

    problem = load_problem(args.file)
    if problem.measurement is None:
        raise SystemExit(f"{args.file}: no [measurement] table")
    full = replace(problem, measurement=None)
    d = design_problem(problem)
    T = d.table.n_ticks
    tables, _, _ = flashed_filter(problem, d.table)
    ectl = build_estimator_controller(problem, d.table, tables)
    fctl = build_controller(d.table, plant=full)
    # warm both (first-call costs: the plant's step compiled for the problem, imports)
    simulate(full, fctl, paths=64, seed=args.seed, substeps=1, workers=1)
    simulate_sensor_blocks(problem, ectl, paths=64, seed=args.seed, workers=1)

    c_full = cpu(lambda: simulate(full, fctl, paths=args.full_paths, seed=args.seed,
                                  substeps=1, workers=1))
    c_sensor = cpu(lambda: simulate_sensor_blocks(problem, ectl, paths=args.paths,
                                                  seed=args.seed, workers=1))
    c_small = cpu(lambda: simulate_sensor_blocks(problem, ectl, paths=args.small_paths,
                                                 seed=args.seed, workers=1,
                                                 block_paths=args.small_block))
    big_blocks = -(-args.paths // SENSOR_BLOCK_PATHS)
    small_blocks = -(-args.small_paths // args.small_block)
    # c = tick * T * blocks + path_tick * paths * T, from the two sensor runs
    a11, a12, b1 = T * big_blocks, args.paths * T, c_sensor
    a21, a22, b2 = T * small_blocks, args.small_paths * T, c_small
    det = a11 * a22 - a12 * a21
    tick = (b1 * a22 - a12 * b2) / det
    path_tick = (a11 * b2 - a21 * b1) / det
    r_full = c_full / (args.full_paths * T)
    r_sensor = c_sensor / (args.paths * T)
    print(f"{Path(args.file).name}: {T} ticks, one plant step per tick, one process, CPU time "
          f"(measured in this run)")
    print(f"  full state   ({args.full_paths} paths, blocks of 512): {c_full:.2f} s CPU, "
          f"{1e9 * r_full:.1f} ns per path-tick")
    print(f"  sensor loop  ({args.paths} paths, blocks of {SENSOR_BLOCK_PATHS}): "
          f"{c_sensor:.2f} s CPU, {1e9 * r_sensor:.1f} ns per path-tick")
    print(f"  sensor loop  ({args.small_paths} paths, blocks of {args.small_block}): "
          f"{c_small:.2f} s CPU")
    print(f"  ratio sensor / full state per path-tick: {r_sensor / r_full:.1f}")
    # the budget's full-state work per path-tick (C controller and plant, exit watch), which
    # its sensor term adds to SENSOR_PATH_TICK
    from stospline.harness.montecarlo import BLOCK_PATHS
    P = 10 ** 6
    c_work = (mc_seconds(full, P) - (budget.SIM_TICK * T + budget.SIM_BLOCK)
              * -(-P // BLOCK_PATHS)) / (P * T)
    print(f"  fitted: {1e6 * tick:.1f} us per tick and block (SENSOR_TICK), "
          f"{1e9 * path_tick:.1f} ns per path-tick, of which {1e9 * (path_tick - c_work):.1f} "
          f"beyond the {1e9 * c_work:.1f} ns of the full state's work the budget counts "
          f"(SENSOR_PATH_TICK)")
    for name, prob, paths, measured in (("full state", full, args.full_paths, c_full),
                                        ("sensor loop", problem, args.paths, c_sensor)):
        est = mc_seconds(prob, paths)
        print(f"  budget's Monte Carlo estimate, {name}: {est:.2f} s (measured {measured:.2f} s,"
              f" ratio {est / measured:.2f})")
    print(f"  budget constants now: SENSOR_TICK = {budget.SENSOR_TICK:.3g} s, "
          f"SENSOR_PATH_TICK = {budget.SENSOR_PATH_TICK:.3g} s")


if __name__ == "__main__":
    main()
