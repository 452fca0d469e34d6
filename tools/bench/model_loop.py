#!/usr/bin/env python3
"""The Monte Carlo loop on a ``[plant]`` model (`stospline.harness.user_plant.simulate_model`):
CPU time per path and tick of the unicycle (examples/nonlinear/robot_unicycle.toml, at
``--hz``), at 1 and 4 plant steps per tick, and the fixed and per-step parts they give (the
constants of the corridor design's time estimate, `stospline.nonlinear.corridor`).

    PYTHONPATH=host .venv/bin/python tools/bench/model_loop.py [--hz 200] [--paths 2000]
"""
from __future__ import annotations

import argparse
import time
import tomllib

import numpy as np
from bench_util import ROOT, median_time

from stospline.errors import ProblemError
from stospline.harness.controller import build_controller
from stospline.harness.user_plant import simulate_model
from stospline.nonlinear.iterate import fit_plant
from stospline.pipeline import design_problem


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hz", type=int, default=200)
    ap.add_argument("--paths", type=int, default=2000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    for name in ("hz", "paths", "repeat"):
        if getattr(args, name) < 1:
            ap.error(f"--{name} must be at least 1, not {getattr(args, name)}")
    if args.paths > 1_000_000:
        ap.error(f"--paths {args.paths}: at most 1000000 (the loop holds every path at once)")
    where = ROOT / "examples" / "nonlinear"
    doc = tomllib.loads((where / "robot_unicycle.toml").read_text())
    doc["tick_hz"] = args.hz
    try:
        problem, fit = fit_plant(doc, where)
    except ProblemError as exc:
        ap.error(f"--hz {args.hz}: {exc.field} {exc.reason}")
    d = design_problem(problem)
    controller = build_controller(d.table)
    ticks = int(np.sum(problem.ticks_per_stage))
    per = {}
    for steps in (1, 4):
        seconds, _ = median_time(
            lambda: simulate_model(problem, controller, fit.model, paths=args.paths, seed=1,
                                   substeps=steps),
            args.repeat, warm_up=True, clock=time.process_time)
        per[steps] = seconds / (args.paths * ticks)
        print(f"unicycle at {args.hz} Hz, {args.paths} paths, {steps} step(s) per tick: "
              f"{per[steps] * 1e6:.2f} us per path-tick")
    step = (per[4] - per[1]) / 3
    print(f"fixed part {(per[1] - step) * 1e6:.2f} us, per plant step {step * 1e6:.2f} us "
          f"per path-tick")


if __name__ == "__main__":
    main()
