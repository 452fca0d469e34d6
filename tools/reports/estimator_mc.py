"""The three numbers of a problem with a [measurement] table: the oracle of the designed
filter, the oracle of the float32 tables as flashed, and a Monte Carlo through the compiled C
estimator controller (host/stospline/harness/estimator_loop.py), with the joint verdict.

    PYTHONPATH=host .venv/bin/python tools/reports/estimator_mc.py [FILE] [--paths N] [--seed S]

FILE defaults to examples/robot_position_sensor.toml. The verdict's z-scores use the sample's
own standard errors, which a heavy-tailed cost (multiplicative noise over a long plan: the
robot's cost has a sample kurtosis near 100 even with the full state) makes optimistic: read
the cost's sample kurtosis printed beside them.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from stospline import design_problem, load_problem
from stospline.estimator.ctable import estimator_table
from stospline.estimator.oracle import evaluate_estimator
from stospline.harness.estimator_loop import build_estimator_controller, simulate_estimator
from stospline.harness.montecarlo import compare_to_oracle


def main() -> None:
    root = Path(__file__).resolve().parents[2]
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("file", nargs="?", default=root / "examples" / "robot_position_sensor.toml")
    ap.add_argument("--paths", type=int, default=20_000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--substeps", type=int, default=4)
    args = ap.parse_args()
    problem = load_problem(args.file)
    d = design_problem(problem)
    designed = evaluate_estimator(problem, d.table)
    et = estimator_table(problem, d.table, designed)
    gains, pred = et.per_tick()
    flashed = evaluate_estimator(problem, d.table, gains=gains, predictor=pred)
    scheme = evaluate_estimator(problem, d.table, gains=gains, predictor=pred,
                                propagator="euler", substeps=args.substeps)
    ctl = build_estimator_controller(problem, d.table, et)
    mc, _ = simulate_estimator(problem, ctl, paths=args.paths, seed=args.seed,
                               substeps=args.substeps)
    mean, half = mc.cost_mean_ci(0.99)
    a = compare_to_oracle(mc, scheme.moments.J, scheme.moments.knot_mean, confidence=0.99,
                          knot_covs=scheme.moments.knot_cov)
    cm = mc.cost_moments              # streamed: no per-path costs kept
    kurt = float(cm.count * cm.m4[0] / cm.comoment[0, 0] ** 2 - 3.0)
    print(f"| {problem.name} | J |\n|---|---|")
    print(f"| oracle, designed filter (double) | {designed.moments.J:.6f} |")
    print(f"| oracle, flashed float32 tables | {flashed.moments.J:.6f} |")
    print(f"| oracle, flashed tables, plant scheme ({args.substeps} substeps) | "
          f"{scheme.moments.J:.6f} |")
    print(f"| Monte Carlo through C, {args.paths} paths, seed {args.seed} | {mean:.4f} "
          f"+- {half:.4f} (99 %) |")
    print(f"\nverdict: {'agree' if a.ok else 'disagree'} (max |z| {a.max_abs_z:.2f} of "
          f"{a.verdict.statistics}, limit {a.z_limit:.2f}; outside: "
          f"{', '.join(a.verdict.outside) or 'none'}); cost excess kurtosis {kurt:.0f}; "
          f"worst status {mc.worst_status}")
    for k, km in enumerate(mc.knot_moments):   # heavy tails make the variances' errors optimistic
        m2 = np.diag(km.comoment)
        print(f"  knot {k}: excess kurtosis per state "
              + ", ".join(f"{v:.0f}" for v in km.count * km.m4 / m2 ** 2 - 3.0))


if __name__ == "__main__":
    main()
