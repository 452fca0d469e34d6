#!/usr/bin/env python3
"""How long the chance-constrained robot's certificate at eps = 1e-4 takes through C.

examples/robot_corridor_eps01.toml (the robot with running costs and a corridor that carries
a risk budget), designed as the file says, is simulated through its compiled C controller for
`--paths` paths (default 10^5) with the plant steps per tick that `stospline simulate` would
choose for that run, once with the plant step and corridor watch compiled for the problem
(`stospline.harness.plant_spec`, what the harness does) and once with the generic ones (the
baseline, in the same run). Each run's time is extrapolated to the certificate's
`--certify-paths` (default 3·10^6: a design whose exit probability is near eps needs that many
for a one-sided 99 % bound below it), also at the steps per tick chosen for that many paths
(the scheme's bias must then be smaller), measured on fewer paths. Prints wall and CPU time
(the command and its workers; wall time is meaningless on a loaded machine, CPU time over
the cores is what idle cores would take) and what a run under 10 minutes needs per path-tick.

    PYTHONPATH=host .venv/bin/python tools/bench/corridor_certificate.py [--paths 100000]
        [--certify-paths 3000000] [--workers N] [--seed 1]
"""
from __future__ import annotations

import argparse
import os
import resource
import time
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from stospline.harness import controller as controller_module  # noqa: E402
from stospline.harness.controller import build_controller  # noqa: E402
from stospline.harness.montecarlo import default_workers, simulate  # noqa: E402
from stospline.pipeline import design_problem, plan_substeps  # noqa: E402
from stospline.problem import load_problem  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
BUDGET = 600.0              # seconds: the certificate's target on this machine


def cpu_seconds() -> float:
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def timed_run(problem, ctl, paths: int, substeps: int, seed: int, workers: int):
    """(wall s, CPU s, exits) of one `simulate` (forked workers' CPU counted when they end)."""
    c, t = cpu_seconds(), time.perf_counter()
    mc = simulate(problem, ctl, paths=paths, seed=seed, substeps=substeps, workers=workers)
    return time.perf_counter() - t, cpu_seconds() - c, mc.exit_count(0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--paths", type=int, default=100_000)
    ap.add_argument("--certify-paths", type=int, default=3_000_000)
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    workers = args.workers or default_workers()
    problem = load_problem(ROOT / "examples" / "robot_corridor_eps01.toml")
    d = design_problem(problem)
    ticks = d.table.n_ticks
    run_steps = plan_substeps(d, paths=args.paths, seed=args.seed).substeps
    cert_steps = plan_substeps(d, paths=args.certify_paths, seed=args.seed).substeps
    print(f"robot_corridor_eps01, {ticks} ticks; {workers} worker process(es); plant steps "
          f"per tick chosen: {run_steps} for {args.paths} paths, {cert_steps} for "
          f"{args.certify_paths}")
    ctl = build_controller(d.table)
    simulate(problem, ctl, paths=64, seed=args.seed, substeps=run_steps, workers=1)   # build

    rows = {}
    rows["compiled plant and corridor"] = timed_run(problem, ctl, args.paths, run_steps,
                                                    args.seed, workers)
    real = controller_module.plant_source
    controller_module.plant_source = lambda *a: None        # the generic step and watch
    try:
        rows["generic plant and corridor"] = timed_run(problem, ctl, args.paths, run_steps,
                                                       args.seed, workers)
    finally:
        controller_module.plant_source = real
    # at the certificate's steps per tick, on as many path-steps as the runs above
    cert_paths = max(2048, args.paths * run_steps // cert_steps)
    rows[f"compiled, {cert_steps} steps per tick"] = timed_run(
        problem, ctl, cert_paths, cert_steps, args.seed, workers)
    print(f"\nrun, then extrapolated to the certificate's {args.certify_paths} paths "
          f"(CPU time over {workers} idle cores):")
    print(f"{'':34s} {'paths':>7s} {'steps':>5s} {'wall s':>7s} {'CPU s':>7s} {'exits':>6s} "
          f"{'ns/path-tick':>12s} {'certificate':>12s}")
    for (name, (wall, cpu, exits)), paths, steps in zip(
            rows.items(), (args.paths, args.paths, cert_paths),
            (run_steps, run_steps, cert_steps)):
        ns = cpu / (paths * ticks) * 1e9
        idle = ns * 1e-9 * args.certify_paths * ticks / workers
        print(f"{name:34s} {paths:7d} {steps:5d} {wall:7.1f} {cpu:7.1f} {exits:6d} "
              f"{ns:12.1f} {idle / 60:8.1f} min")
    need = BUDGET * workers / (args.certify_paths * ticks) * 1e9
    print(f"\nunder {BUDGET / 60:.0f} min on {workers} idle cores: at most {need:.1f} ns CPU per "
          f"path-tick (the certificate's serial work, design and oracle, not counted)")


if __name__ == "__main__":
    main()
