"""A corridor with the estimator in the loop: what the sensor does to the spread and the exits.

For FILE (default examples/robot_corridor_position_sensor.toml; any problem with [measurement]
and corridors), optionally with the corridor-design weights (--strip W --rate WV, as
`stospline corridor-design` adds them), prints per corridor, from exact moments: the
cost, the largest spread of the output across a wall over the corridor's ticks, and the
Cantelli (valid) and Gaussian (estimate) union bounds of the exit probability, for the law
run on the exact state and on the flashed filter's estimate (harness.estimator_run); with
--paths N, the exits of N Monte Carlo paths of each loop through the compiled C (same seed),
with their one-sided 99 % Clopper-Pearson bounds and the process CPU time of each run; and
how far the sensor loop's output covariance exceeds the full state's (smallest eigenvalue
of the difference over the ticks) and its mean differs. With --table spline the design's
tables are splines and so is its filter's gain as flashed (what the "sensor" row runs);
beside it, without Monte Carlo, the same law on the per-sample filter, and how far the
spline moves the cost and the output covariance (largest relative change, Frobenius).
Usage: .venv/bin/python tools/reports/sensor_corridor.py [FILE] [--strip W --rate WV]
       [--paths N] [--seed S] [--table per-tick|spline]
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from stospline.corridor_search import with_weights
from stospline.design.corridor_design import stage_polygons
from stospline.estimator.ctable import estimator_table
from stospline.estimator.oracle import evaluate_estimator
from stospline.harness.controller import build_controller
from stospline.harness.estimator_run import count_sensor_exits, flashed_filter, sensor_outputs
from stospline.harness.exit_stats import clopper_pearson_upper
from stospline.harness.montecarlo import simulate
from stospline.oracle.evaluate import evaluate_table
from stospline.oracle.exit_bound import exit_bounds
from stospline.pipeline import design_problem
from stospline.problem import load_problem
from stospline.problem.reader import parse_problem
from stospline.problem.inputfile import decode_problem

ROOT = Path(__file__).resolve().parents[2]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("file", nargs="?",
                    default=str(ROOT / "examples/robot_corridor_position_sensor.toml"))
    ap.add_argument("--strip", type=float, default=0.0)
    ap.add_argument("--rate", type=float, default=0.0)
    ap.add_argument("--paths", type=int, default=0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--table", choices=("per-tick", "spline"), default="per-tick")
    a = ap.parse_args()
    problem = load_problem(a.file)
    if problem.measurement is None or not problem.corridors:
        raise SystemExit("sensor_corridor: the file needs [measurement] and [[corridors]]")
    design = problem
    if a.strip or a.rate:
        base = design_problem(problem)
        c = problem.corridors[0]
        ym = evaluate_table(problem, base.table, path=False, output=c.C).path_y_mean
        text = with_weights(problem, 0, stage_polygons(problem, c, ym), a.strip, a.rate)
        design = parse_problem(decode_problem(text.encode()))
    d = design_problem(design, table=a.table)
    flashed = flashed_filter(problem, d.table)
    per = (estimator_table(problem, d.table, evaluate_estimator(problem, d.table))
           if d.table.spline is not None else None)
    print(f"{Path(a.file).name}, w = {a.strip:g}, wv = {a.rate:g}; sensor every "
          f"{problem.measurement.every} ticks, sd {np.sqrt(np.diag(problem.measurement.V))}")
    print("| corridor | loop | J | largest spread across a wall | Cantelli | Gaussian |"
          + (" MC exits | upper99 | CPU s |" if a.paths else ""))
    print("|---|---|---:|---:|---:|---:|" + ("---:|---:|---:|" if a.paths else ""))
    for i, c in enumerate(problem.corridors):
        full = evaluate_table(problem, d.table, path=False, output=c.C)
        rows = [("full state", full.J, full.path_y_mean, full.path_y_cov),
                ("sensor", *sensor_outputs(problem, d.table, c.C, flashed))]
        if per is not None:
            rows.append(("sensor, per-sample filter",
                         *sensor_outputs(problem, d.table, c.C, (per, *per.per_tick()))))
        for label, J, ym, yc in rows:
            b = exit_bounds(c, ym, yc, problem.t0, problem.tick_hz)
            lo, hi = b["cantelli"].ticks
            A, _ = c.unit_walls()
            spread = np.sqrt(np.einsum("wp,tpq,wq->tw", A, yc[lo:hi + 1], A).max())
            line = (f"| {i} | {label} | {J:.6f} | {spread:.4f} | {b['cantelli'].total:.4g} | "
                    f"{b['gaussian'].total:.4g} |")
            if a.paths and label == "sensor, per-sample filter":
                line += " - | - | - |"        # the C runs the tables as flashed only
            elif a.paths:
                t = time.process_time()
                if label == "sensor":
                    k = count_sensor_exits(problem, d.table, i, paths=a.paths, seed=a.seed)
                else:
                    k = simulate(problem, build_controller(d.table, plant=problem),
                                 paths=a.paths, seed=a.seed, substeps=1).exit_count(i)
                line += (f" {k} / {a.paths} | {clopper_pearson_upper(k, a.paths):.4g} | "
                         f"{time.process_time() - t:.1f} |")
            print(line)
        gap = rows[1][3] - rows[0][3]
        print(f"\ncorridor {i}: the sensor loop's output covariance less the full state's, "
              f"smallest eigenvalue over all ticks {np.linalg.eigvalsh(gap).min():.3g}; the "
              f"means differ by at most {np.abs(rows[1][2] - rows[0][2]).max():.2g}\n")
        if per is not None:
            (_, J, _, yc), (_, Jp, _, ycp) = rows[1:]
            change = (np.linalg.norm(yc - ycp, axis=(1, 2))
                      / np.linalg.norm(ycp, axis=(1, 2)))[1:]
            print(f"corridor {i}: the filter's gain spline against its per-sample gains: J "
                  f"{(J - Jp) / Jp:+.2g} relative, output covariance at most {change.max():.2g} "
                  f"relative (Frobenius, over the ticks)\n")


if __name__ == "__main__":
    main()
