"""Monte Carlo through the compiled spline parametric controller (stsp_param_step with a spline
table and its spline columns, parameter table format 2) against the exact oracle of that
table as flashed (`stospline.refine.spline_params`), beside the per-tick parametric
controller timed in the same run.

Usage: PYTHONPATH=host .venv/bin/python tools/bench/params_spline_mc.py [--paths 4000]
           [--seed 20261128] [--example robot_goal]

At theta = (-0.7, 5.3) (robot_goal; for another example the upper corner of the box) both
controllers run `--paths` paths (`stospline.harness.params_loop.simulate_params`, the same
seed); each is compared with the oracle of its own table at theta (cost and every knot-mean
component, joint 99 % limits on the sample's own standard errors) and with the oracle of the
nominal, which it must reject. Prints the verdicts, the largest |z| and the CPU seconds of
each run (the per-tick controller's is the baseline).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools"))


def main(argv=None) -> int:
    from params_tables import spline_files
    from stospline import design_problem, load_problem
    from stospline.harness.params_loop import _build, build_params_controller, simulate_params
    from stospline.oracle.evaluate import evaluate_table
    from stospline.oracle.over_box import vertices
    from stospline.problem.parameters import problem_at

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--paths", type=int, default=4000)
    ap.add_argument("--seed", type=int, default=20261128)
    ap.add_argument("--example", default="robot_goal")
    args = ap.parse_args(argv)
    problem = load_problem(ROOT / "examples" / f"{args.example}.toml")
    files, sp = spline_files(problem, f"{args.example}.toml")
    theta = (np.array([-0.7, 5.3]) if args.example == "robot_goal"
             else vertices(sp.per_tick.parameters)[-1])
    name = sp.table.name
    controllers = {
        "per-tick": (build_params_controller(sp.per_tick, design_problem(problem).table),
                     sp.per_tick, True),
        "spline": (_build(files, name, sp.table, "float32", None, True), sp.flashed, False),
    }
    for kind, (ctl, ptable, quantize) in controllers.items():
        t0 = time.process_time()
        run = simulate_params(problem, ctl, theta, paths=args.paths, seed=args.seed)
        cpu = time.process_time() - t0
        table = ptable.at(theta, quantize=quantize)
        exact = evaluate_table(problem_at(problem, theta), table, path=False)
        nominal = evaluate_table(problem, ptable.at(ptable.nominal, quantize=quantize),
                                 path=False)
        good = run.agreement(exact.J, exact.knot_mean)
        bad = run.agreement(nominal.J, nominal.knot_mean)
        print(f"{kind}: {args.paths} paths at theta {theta.tolist()}, worst status "
              f"{run.worst_status}, CPU {cpu:.2f} s; against its oracle at theta: "
              f"{'agrees' if good.agree else 'DISAGREES'} (max |z| {good.max_abs_z:.2f}, "
              f"limit {good.z_limit:.2f}); against the nominal's: "
              f"{'rejected' if not bad.agree else 'NOT REJECTED'} (max |z| {bad.max_abs_z:.1f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
