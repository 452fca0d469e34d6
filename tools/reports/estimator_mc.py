"""The three numbers of a problem with a [measurement] table: the oracle of the designed
filter, the oracle of the float32 tables as flashed, and a Monte Carlo through the compiled C
estimator controller (host/stospline/harness/estimator_loop.py), with the joint verdict.

    PYTHONPATH=host .venv/bin/python tools/reports/estimator_mc.py [FILE] [--paths N] [--seed S]
        [--measurement TABLE] [--fault KEY=VALUE ...]

FILE defaults to examples/robot_position_sensor.toml. ``--measurement`` gives (or replaces)
FILE's ``[measurement]`` table as a TOML inline table, e.g. ``'{C = [[1.0]], V = {t = [0, 10],
values = [[[1.0]], [[0.01]]]}, every = 3}'`` (a sensor on a file with time-varying data, its V
sampled in time). ``--fault`` sets a key of FILE's ``[faults]`` (as ``stospline simulate
--fault``): the filter is flashed without the faults, and the oracle rows are the loop's with
them. The verdict's z-scores divide by the
exact standard errors of the run (`estimator.tails`: the cost's variance and each knot
component's variance and fourth central moment under the plant scheme, with the faults and a
sampled V); the verdict with the sample's own standard errors, which the heavy tails of
multiplicative noise make too small, is printed beside it, with the sample excess kurtosis of
the cost and the exact one of the knot states. Where the exact standard errors are not
evaluated (time-varying stage data, a loop too large) the verdict uses the sample's.
"""
from __future__ import annotations

import argparse
import dataclasses
import time
import tomllib
from pathlib import Path

import numpy as np

from stospline import design_problem, load_problem
from stospline.estimator.ctable import estimator_table
from stospline.estimator.oracle import evaluate_estimator
from stospline.estimator.tails import estimator_tails_unsupported, evaluate_estimator_tails
from stospline.problem.faults import parse_faults
from stospline.problem.reader import parse_problem
from stospline.harness.estimator_loop import build_estimator_controller, simulate_estimator
from stospline.harness.montecarlo import compare_to_oracle


def main() -> None:
    root = Path(__file__).resolve().parents[2]
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("file", nargs="?", default=root / "examples" / "robot_position_sensor.toml")
    ap.add_argument("--paths", type=int, default=20_000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--substeps", type=int, default=4)
    ap.add_argument("--measurement", help="the [measurement] table, TOML inline")
    ap.add_argument("--fault", action="append", default=[], metavar="KEY=VALUE")
    args = ap.parse_args()
    problem = load_problem(args.file)
    if args.measurement:
        doc = tomllib.loads(Path(args.file).read_text())
        doc["measurement"] = tomllib.loads(f"m = {args.measurement}")["m"]
        problem = parse_problem(doc)
    if args.fault:
        given = dict(tomllib.loads(f"{k} = {v}").popitem() for k, v in
                     (f.split("=", 1) for f in args.fault))
        problem = dataclasses.replace(problem, faults=parse_faults(
            {**problem.faults.as_dict(), **given}, problem.n, problem.m))
    faults = problem.faults
    d = design_problem(problem)
    designed = evaluate_estimator(problem, d.table)
    et = estimator_table(problem, d.table, designed)
    gains, pred = et.per_tick()
    flashed = evaluate_estimator(problem, d.table, gains=gains, predictor=pred)
    scheme = evaluate_estimator(problem, d.table, gains=gains, predictor=pred,
                                propagator="euler", substeps=args.substeps, faults=faults)
    ctl = build_estimator_controller(problem, d.table, et)
    c0 = time.process_time()
    mc, _ = simulate_estimator(problem, ctl, paths=args.paths, seed=args.seed,
                               substeps=args.substeps)
    c1 = time.process_time()
    mean, half = mc.cost_mean_ci(0.99)
    tails = None
    why = estimator_tails_unsupported(problem, d.table, faults)
    if why is None:
        tails = evaluate_estimator_tails(problem, d.table, scheme, predictor=pred,
                                         substeps=args.substeps, faults=faults)
    c2 = time.process_time()
    a_sample = compare_to_oracle(mc, scheme.moments.J, scheme.moments.knot_mean,
                                 confidence=0.99, knot_covs=scheme.moments.knot_cov)
    verdicts = [("sample", a_sample)]
    if tails is not None:
        verdicts.insert(0, ("exact", compare_to_oracle(
            mc, scheme.moments.J, scheme.moments.knot_mean, confidence=0.99,
            knot_covs=scheme.moments.knot_cov, exact_se=tails)))
    cm = mc.cost_moments
    kurt = float(cm.m4[0] * cm.count / cm.comoment[0, 0] ** 2 - 3)
    print(f"| {problem.name} | J |\n|---|---|")
    print(f"| oracle, designed filter (double) | {designed.moments.J:.6f} |")
    print(f"| oracle, flashed float32 tables | {flashed.moments.J:.6f} |")
    print(f"| oracle, full state (the design's law on x) | {d.implemented.J:.6f} |")
    if faults.any:
        faulty = evaluate_estimator(problem, d.table, gains=gains, predictor=pred, faults=faults)
        print(f"| oracle, flashed tables, faults {faults.label()} | {faulty.moments.J:.6f} |")
    print(f"| oracle, flashed tables{', faults' if faults.any else ''}, plant scheme "
          f"({args.substeps} substeps) | {scheme.moments.J:.6f} |")
    print(f"| Monte Carlo through C, {args.paths} paths, seed {args.seed} | {mean:.4f} "
          f"+- {half:.4f} (99 %) |")
    for name, v in verdicts:
        print(f"\nverdict, {name} standard errors: {'agree' if v.ok else 'disagree'} (max |z| "
              f"{v.max_abs_z:.2f} ({v.verdict.max_abs_z_of}) of {v.verdict.statistics}, limit "
              f"{v.z_limit:.2f}; outside: {', '.join(v.verdict.outside) or 'none'})")
    if tails is not None:
        knot_kurt = max(float(tails.knot_excess_kurtosis(k).max())
                        for k in range(len(tails.knot_mean)))
        print(f"\ncost: sample excess kurtosis {kurt:.0f}, exact standard deviation "
              f"{np.sqrt(tails.cost_var):.4g} (sample {mc.cost_std():.4g}); knot states: exact "
              f"excess kurtosis up to {knot_kurt:.3g}; worst status {mc.worst_status}")
        print(f"CPU seconds: exact standard errors {c2 - c1:.1f}, the Monte Carlo run "
              f"{c1 - c0:.1f}")
    else:
        print(f"\ncost: sample excess kurtosis {kurt:.0f}, sample standard deviation "
              f"{mc.cost_std():.4g}; worst status {mc.worst_status}; no exact standard "
              f"errors: {why}")


if __name__ == "__main__":
    main()
