"""What the sensor costs: a design run on a filter's estimate, from exact moments.

Prints a Markdown table for examples/robot_position_sensor.toml (or FILE, any problem with
[measurement]): the loop's cost, the spread at the end of the states the sensor measures, the
worst knot-constraint residual of the mean, for the full state measured exactly at every
tick, the full state measured with noise at the sensor's rate, and the file's own sensor;
then, with the start known exactly, the bound on what any better output-feedback law could
save (docs/theory/estimator.md).
Usage: .venv/bin/python tools/reports/sensor_costs.py [FILE] [--velocity-sd 0.05]
       [--label "position only"]
"""
from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np

from stospline.estimator.oracle import evaluate_estimator
from stospline.pipeline import design_problem
from stospline.problem import load_problem
from stospline.problem.measurement import Measurement

ROOT = Path(__file__).resolve().parents[2]


def residual(problem, moments) -> float:
    return max(float(np.abs(moments.knot_constraint[k] - kn.constraint.value).max())
               for k, kn in enumerate(problem.knots) if kn.constraint is not None)


def full_state_noisy(meas: Measurement, n: int, velocity_sd: float) -> Measurement:
    """Every state measured at the sensor's rate: the states the rows of C read with the
    sensor's variance, the others (velocities) with `velocity_sd`."""
    var = np.full(n, velocity_sd ** 2)
    for row, v in zip(meas.C, np.diag(meas.V)):
        var[np.flatnonzero(row)] = v
    return Measurement(np.eye(n), np.diag(var), meas.every, x0_cov=meas.x0_cov)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("file", nargs="?", default=str(ROOT / "examples" /
                                                    "robot_position_sensor.toml"))
    ap.add_argument("--velocity-sd", type=float, default=0.05,
                    help="standard deviation of a state the file's sensor does not read (a "
                         "velocity, m/s) when the full state is measured (default 0.05)")
    ap.add_argument("--label", default="position only",
                    help="the file's sensor in the table (default: position only)")
    args = ap.parse_args()
    problem = load_problem(args.file)
    meas = problem.measurement
    n = problem.n
    table = design_problem(problem).table
    pos = [int(np.flatnonzero(r)[0]) for r in meas.C]
    hz = problem.tick_hz / meas.every
    loops = [
        ("full state, exact, every tick", Measurement(np.eye(n), np.zeros((n, n)),
                                                      x0_cov=meas.x0_cov)),
        (f"full state, noisy, {hz:g} Hz", full_state_noisy(meas, n, args.velocity_sd)),
        (f"{args.label} ({problem.name}), {hz:g} Hz", meas),
    ]
    print(f"{problem.name}: the stage-wise design's float32 table on the estimate; the start "
          f"has the file's x0_cov; velocity sd {args.velocity_sd:g} where measured\n")
    print("| sensor | J | vs exact full state | sd at the end of the measured states | "
          "max mean-constraint residual |")
    print("|---|---:|---:|---:|---:|")
    base = None
    for label, sensor in loops:
        mom = evaluate_estimator(problem, table, sensor).moments
        base = mom.J if base is None else base
        sd = np.sqrt(np.diag(mom.knot_cov[-1])[pos])
        print(f"| {label} | {mom.J:.6f} | {100 * (mom.J / base - 1):+.2f} % | "
              f"{', '.join(f'{s:.4f}' for s in sd)} | {residual(problem, mom):.1e} |")
    known = replace(meas, x0_cov=None)
    J_sensor = evaluate_estimator(problem, table, known).moments.J
    J_joint = design_problem(problem, mode="joint").implemented.J
    print(f"\nWith the start known exactly: {args.label} J = {J_sensor:.6f}; the joint "
          f"full-state design, the least cost of any law meeting the mean constraints, "
          f"J = {J_joint:.6f}. A better output-feedback law could save at most "
          f"{100 * (1 - J_joint / J_sensor):.2f} %.")


if __name__ == "__main__":
    main()
