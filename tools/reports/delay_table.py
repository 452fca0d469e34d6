"""The cost of ignoring a one-tick computation delay versus designing for it, on the robot.

For each rate: the ordinary design (made for a command applied at once) run with the command
applied a tick late (the fault oracle, ``Faults(delay_ticks=1)``), and the design for the delay
(``[design] delay_ticks = 1``), both as float32 tables; exact oracle costs and constraint
residuals, then Monte Carlo through the compiled C controller with its verdict against the
oracle (cost and knot means, 99 % jointly), and the per-path difference of the two runs (the
same plant noise). Prints a Markdown table.

Usage: PYTHONPATH=host .venv/bin/python tools/reports/delay_table.py [--paths 4000] [--seed 1]
"""
from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np

from stospline.pipeline import design_problem, simulate_problem, simulation_summary
from stospline.problem import load_problem
from stospline.problem.faults import Faults
from stospline.oracle.faults import evaluate_with_faults

ROOT = Path(__file__).resolve().parents[2]
RATES = [100, 1000]
SUBSTEPS = {100: 8, 1000: 1}      # what simulate's "auto" picks for 4000 paths


def residual(problem, moments) -> float:
    return max(float(np.abs(moments.knot_constraint[k] - kn.constraint.value).max())
               for k, kn in enumerate(problem.knots) if kn.constraint is not None)


def mc_cell(d, faults, paths, seed, substeps):
    """The Monte Carlo run and its cell: mean cost ± 95 % half-width, z, the verdict."""
    mc = simulate_problem(d, paths=paths, seed=seed, substeps=substeps, workers=1,
                          faults=faults, per_path=True)
    s = simulation_summary(d, mc, seed=seed)
    c, v = s["cost"], s["verdict"]
    half = (c["ci95"][1] - c["ci95"][0]) / 2
    return mc, (f"{c['mc_mean']:.3f} ± {half:.3f} (z {c['z']:+.2f}, "
                f"{'agrees' if v['agree'] else 'DISAGREES'})")


def paired_gap(a, b) -> str:
    """Mean ± 95 % half-width of the per-path cost difference: both runs draw the plant's
    noise from the same seed (common random numbers), so the difference is far more precise
    than either mean."""
    diff = a.cost - b.cost
    half = 1.959963984540054 * diff.std(ddof=1) / np.sqrt(len(diff))
    return f"{diff.mean():+.4f} ± {half:.4f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--paths", type=int, default=4000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--mode", default="stagewise", choices=["stagewise", "joint"])
    args = ap.parse_args()
    base = load_problem(ROOT / "examples" / "robot_corridor.toml")
    print(f"robot_corridor, {args.mode} multipliers, float32 tables; Monte Carlo "
          f"{args.paths} paths, seed {args.seed} (mean ± 95 % half-width; z against the "
          f"oracle of that loop)\n")
    print("| rate | no delay: oracle J | delay ignored: oracle J | residual | Monte Carlo | "
          "designed for it: predicted J0 | oracle J | residual | Monte Carlo | "
          "cost of ignoring: oracle | Monte Carlo (paired) |")
    print("|---:|---:|---:|---:|---|---:|---:|---:|---|---:|---:|")
    for hz in RATES:
        p = replace(base, tick_hz=hz)
        plain = design_problem(p, mode=args.mode, delay_ticks=0)
        late = evaluate_with_faults(p, plain.table, Faults(delay_ticks=1))
        aware = design_problem(p, mode=args.mode, delay_ticks=1)
        sub = SUBSTEPS[hz]
        run_late, mc_late = mc_cell(plain, Faults(delay_ticks=1), args.paths, args.seed, sub)
        run_aware, mc_aware = mc_cell(aware, Faults(), args.paths, args.seed, sub)
        gap = late.J - aware.implemented.J
        print(f"| {hz} Hz | {plain.implemented.J:.6f} | {late.J:.6f} | "
              f"{residual(p, late):.1e} | {mc_late} | {aware.design.J0:.6f} | "
              f"{aware.implemented.J:.6f} | {residual(p, aware.implemented):.1e} | "
              f"{mc_aware} | {gap:+.6f} ({gap / aware.implemented.J:+.3%}) | "
              f"{paired_gap(run_late, run_aware)} |")


if __name__ == "__main__":
    main()
