"""The drone through gates with its gate positions changed during the flight (a radio update,
stsp_set_params between two steps): the figures of docs/applications/drone_gates.md,
"Gates moved during the flight".

For each case, the Monte Carlo through the compiled C (stsp_set_params, stsp_param_step,
`simulate_params(..., change=(stage, theta2, tick))`) against the exact oracle of that change
(`evaluate_switched`): the joint verdict over the cost and every knot-mean component (99 %,
Bonferroni, the sample's own standard errors) and its largest |z|; how far the oracle's mean
passes from each gate at its new position (the gates after the change); and the highest
expected altitude of the plan against the 3.2 m ceiling, which the design over the box
guarantees for parameters set before tick 0, not for a change during the plan.
The drone's design is joint: it latches its multipliers once, at tick 0, so a change reaches
only the feed-forward (docs/theory/parameters.md, "Parameters changed during the plan").

Usage: PYTHONPATH=host .venv/bin/python tools/reports/drone_mid_plan.py [--paths N]
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from stospline import design_problem, load_problem
from stospline.harness.params_loop import build_params_controller, simulate_params
from stospline.oracle.parametric import (check_parametric_options, design_parametric,
                                         evaluate_at, evaluate_switched)

ROOT = Path(__file__).resolve().parents[2]
SEED = 20261201                 # the draws of the gate positions and the Monte Carlo
Y, Z = 2, 4                     # the state's lateral and vertical positions


def drone(build_dir):
    """The problem, its parametric table and the compiled parametric controller."""
    p = load_problem(ROOT / "examples" / "drone_gates.toml")
    opts = check_parametric_options(p)
    pt = design_parametric(p, mode=opts.mode).table
    table = design_problem(p, options=opts).table
    return p, pt, build_params_controller(pt, table, build_dir=build_dir)


def cases(p, pt):
    """(label, theta, theta2, stage, tick): seeded draws in the box changed between gates 1
    and 2, 2 and 3, 3 and the landing; gate 2 raised to its highest between gates 1 and 2."""
    rng = np.random.default_rng(SEED)
    lo = np.array([q.lower for q in p.parameters])
    hi = np.array([q.upper for q in p.parameters])
    start = pt.table.stage_start
    out = []
    for k, tick in ((1, 150), (2, 250), (3, 350)):
        theta, theta2 = rng.uniform(lo, hi), rng.uniform(lo, hi)
        assert start[k] <= tick < start[k + 1]
        out.append((f"random draws, after gate {k}", theta, theta2, k, tick))
    up = pt.nominal.copy()
    up[[q.name for q in p.parameters].index("gate2_z")] = hi[3]
    out.append(("gate 2 raised to 3.1 m, after gate 1", pt.nominal.copy(), up, 1, 150))
    return out


def miss(p, m, theta2, tick) -> str:
    """The oracle's mean at each gate after the change, its distance from the new gate."""
    out = []
    for k, kn in enumerate(p.knots[:3]):
        if round((kn.t - p.t0) * p.tick_hz) > tick:
            d = m.knot_mean[k][[Y, Z]] - theta2[2 * k:2 * k + 2]
            out.append(f"gate {k + 1}: {np.abs(d).max():.3f} m")
    return ", ".join(out) or "none after the change"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--paths", type=int, default=2000)
    args = ap.parse_args(argv)
    t = time.process_time()
    with tempfile.TemporaryDirectory() as tmp:
        p, pt, ctl = drone(tmp)
        print(f"drone_gates: design and build {time.process_time() - t:.1f} s CPU; Monte "
              f"Carlo {args.paths} paths per case, seed {SEED}")
        print()
        print("| case | change at tick | C vs oracle (99 %, max abs z) | mean's distance from "
              "the new gate | highest mean altitude (ceiling 3.2 m) | the same run vs the "
              "oracle of the change at the stage start |")
        print("|---|---|---|---|---|---|")
        for label, theta, theta2, stage, tick in cases(p, pt):
            run = simulate_params(p, ctl, theta, paths=args.paths, seed=SEED,
                                  change=(stage, theta2, tick))
            exact = evaluate_switched(p, pt, theta, stage, theta2, tick=tick, quantize=True,
                                      path=True)
            v = run.agreement(exact.J, exact.knot_mean)
            wrong = evaluate_switched(p, pt, theta, stage, theta2, quantize=True)
            w = run.agreement(wrong.J, wrong.knot_mean)
            top = float(np.max(exact.path_mean[:, Z]))
            print(f"| {label} | {tick} | {'agrees' if v.agree else 'DISAGREES'} "
                  f"({v.max_abs_z:.2f}; limit {v.z_limit:.2f}) | {miss(p, exact, theta2, tick)} "
                  f"| {top:.3f} m | {'agrees' if w.agree else 'disagrees'} "
                  f"({w.max_abs_z:.1f}) |")
        fixed = evaluate_at(p, pt, pt.nominal, quantize=True, path=True)
        print()
        print(f"nominal gates, no change: highest mean altitude "
              f"{float(np.max(fixed.path_mean[:, Z])):.3f} m")
    print(f"total {time.process_time() - t:.1f} s CPU")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
