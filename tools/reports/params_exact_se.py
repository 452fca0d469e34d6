"""The parametric loop's Monte Carlo through the compiled C (`harness.params_loop`) judged by
the exact standard errors of its run (`oracle.parametric.tails_at`: the loop's moments up to
the fourth under the plant scheme) beside the sample's own: theta fixed, changed at the
stage-1 start, and changed inside stage 0 and inside stage 1.

    PYTHONPATH=host .venv/bin/python tools/reports/params_exact_se.py [FILE] [--paths N]
        [--seed S] [--theta A,B] [--theta2 A,B]

FILE defaults to examples/robot_goal.toml, theta and theta2 to those of
tests/python/sim/test_params_monte_carlo.py. Prints, per case, the run's mean cost against
the oracle's, the cost's exact and sample standard deviations, and the joint verdict over the
cost and every knot-mean component (99 %, Bonferroni) with either standard errors; the CPU
time of the fourth-moment oracle beside the run's.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from stospline import design_problem, load_problem
from stospline.harness.params_loop import build_params_controller, simulate_params
from stospline.oracle.parametric import (design_parametric, evaluate_at, evaluate_switched,
                                         tails_at)

SUBSTEPS = 4


def _vector(text: str) -> np.ndarray:
    return np.array([float(v) for v in text.split(",")])


def main() -> None:
    root = Path(__file__).resolve().parents[2]
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("file", nargs="?", default=root / "examples" / "robot_goal.toml")
    ap.add_argument("--paths", type=int, default=20_000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--theta", type=_vector, default=np.array([-0.7, 5.3]))
    ap.add_argument("--theta2", type=_vector, default=np.array([-1.4, 4.6]))
    args = ap.parse_args()
    problem = load_problem(args.file)
    table = design_problem(problem).table
    pt = design_parametric(problem).table
    ctl = build_params_controller(pt, table)
    th, th2 = args.theta, args.theta2
    starts = [int(s) for s in pt.table.stage_start]
    cases = [("theta fixed", None, None)]
    cases += [(f"changed at stage {k}'s start (tick {starts[k]})", k, None)
              for k in range(1, pt.table.n_stages)]
    cases += [(f"changed inside stage {k} (tick {(starts[k] + starts[k + 1]) // 2})", k,
               (starts[k] + starts[k + 1]) // 2) for k in range(pt.table.n_stages)]
    print(f"{problem.name}: {args.paths} paths, seed {args.seed}, theta {th.tolist()}, "
          f"theta2 {th2.tolist()}, {SUBSTEPS} plant steps per tick (CPU seconds under load)\n")
    print("| case | MC cost | oracle | std exact / sample | max abs z exact (sample), limit "
          "| verdict exact (sample) | CPU oracle / run |\n|---|---|---|---|---|---|---|")
    for name, stage, tick in cases:
        c0 = time.process_time()
        if stage is None:
            run = simulate_params(problem, ctl, th, paths=args.paths, seed=args.seed,
                                  substeps=SUBSTEPS)
        else:
            change = (stage, th2) if tick is None else (stage, th2, tick)
            run = simulate_params(problem, ctl, th, paths=args.paths, seed=args.seed,
                                  substeps=SUBSTEPS, change=change)
        c1 = time.process_time()
        if stage is None:
            exact = evaluate_at(problem, pt, th, quantize=True)
            tails = tails_at(problem, pt, th, substeps=SUBSTEPS, quantize=True)
        else:
            exact = evaluate_switched(problem, pt, th, stage, th2, tick=tick, quantize=True)
            tails = tails_at(problem, pt, th, substeps=SUBSTEPS, stage=stage, theta2=th2,
                             tick=tick, quantize=True)
        c2 = time.process_time()
        v_exact = run.agreement(exact.J, exact.knot_mean, exact_se=tails)
        v_sample = run.agreement(exact.J, exact.knot_mean)
        word = {True: "agree", False: "disagree"}
        print(f"| {name} | {run.cost.mean():.4f} | {exact.J:.4f} | "
              f"{np.sqrt(tails.cost_var):.4g} / {run.cost.std(ddof=1):.4g} | "
              f"{v_exact.max_abs_z:.2f} ({v_sample.max_abs_z:.2f}), {v_exact.z_limit:.2f} | "
              f"{word[v_exact.agree]} ({word[v_sample.agree]}) | {c2 - c1:.2f} / "
              f"{c1 - c0:.2f} |")


if __name__ == "__main__":
    main()
