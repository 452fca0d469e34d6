"""The fixed-point estimator's error against the double loop: bound and measurement.

For examples/robot_position_sensor.toml (or FILE), Q15 and Q31: the per-tick error bound of
`stospline.estimator.qformat.error_bound` on x̂+ and on the command (its largest over the
plan, per component), the largest error measured over PATHS paths of readings drawn with the
loop's innovation covariance (`measured_error`, the same readings fed to the Q loop and the
double loop), and their ratio: how loose the bound is. Then the CPU time of the bound and of
the measurement, with the exact moment oracle of the sensor loop timed in the same run as the
baseline.
Usage: .venv/bin/python tools/reports/estimator_q_error.py [FILE] [--paths 16] [--ticks N]
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from stospline.estimator.filter_kernel import with_table_filter
from stospline.estimator.oracle import evaluate_estimator
from stospline.estimator.qformat import (error_bound, estimator_state_range, measured_error,
                                         quantize_estimator)
from stospline.pipeline import design_problem, double_table, fixed_point_table
from stospline.problem import load_problem

ROOT = Path(__file__).resolve().parents[2]


def fmt(a) -> str:
    return "[" + ", ".join(f"{v:.3g}" for v in a) + "]"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("file", nargs="?", default=ROOT / "examples" / "robot_position_sensor.toml")
    ap.add_argument("--paths", type=int, default=16)
    ap.add_argument("--ticks", type=int, default=None, help="the first ticks only")
    args = ap.parse_args()
    problem = load_problem(args.file)
    d = design_problem(problem)
    exact = double_table(d)
    t0 = time.process_time()
    loop = with_table_filter(evaluate_estimator(problem, exact, path=True), problem, d.table)
    t_oracle = time.process_time() - t0
    x_range = estimator_state_range(problem, exact, loop)
    print("| arith | on | bound (max over the plan) | measured (max) | measured / bound |")
    print("|---|---|---|---|---|")
    times = []
    for arith in ("q15", "q31"):
        ft = fixed_point_table(d, arith, x_range=x_range)
        qt = quantize_estimator(problem, ft, loop)
        ticks = ft.n_ticks if args.ticks is None else min(args.ticks, ft.n_ticks)
        t0 = time.process_time()
        xb, ub = error_bound(ft, qt, ticks=ticks)
        t1 = time.process_time()
        xe, ue, clamped = measured_error(ft, qt, loop.innovation_cov, ticks, paths=args.paths)
        t2 = time.process_time()
        times.append((arith, t1 - t0, t2 - t1))
        note = " (saturated: the bound does not apply)" if clamped else ""
        for what, b, e in (("x̂+", xb, xe), ("u", ub, ue)):
            print(f"| {arith} | {what} | {fmt(b.max(0))} | {fmt(e.max(0))} | "
                  f"{fmt(e.max(0) / b.max(0))}{note} |")
    print(f"\nCPU seconds ({ticks} ticks, {args.paths} paths): exact oracle of the sensor loop "
          f"{t_oracle:.2f} (baseline)")
    for arith, tb, tm in times:
        print(f"  {arith}: bound {tb:.2f} ({tb / t_oracle:.2f}x the oracle), "
              f"measurement {tm:.2f} ({tm / t_oracle:.2f}x)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
