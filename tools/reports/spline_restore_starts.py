"""Spline tables of designs that latch the state (`stospline.table.spline.restore`): the worst
constraint violation over every row (knot rows, region rows at every tick) from the design's
x0 and from other starts, for the per-tick float32 table, the spline table and the plain fit
(the restoration skipped), by the exact oracle; also as a multiple of each row's float32 floor
(`spline_restore.float32_floor`).

The restoration holds the rows for the design's x0 only (as the per-tick table's active-set
latch does: the latched state enters the feed-forward through L, the design's active set's
affine map of x0, exact for starts that keep that active set). The other starts are x0 plus
seeded normal perturbations of the given scales (float32, as the controller measures them).

Usage: PYTHONPATH=host .venv/bin/python tools/reports/spline_restore_starts.py
           [--examples robot_monotone,robot_narrow_corridor] [--tolerances 1e-5,1e-2]
           [--starts 4] [--scales 0.01,0.1] [--seed 3]
"""
from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np

import stospline
from stospline.oracle.evaluate import evaluate_table
from stospline.table.spline import restore as sr
from stospline.table.format import table_of

ROOT = Path(__file__).resolve().parents[2]


def worst(problem, table, x0):
    """``(worst violation, worst violation / floor)`` over every row from x0."""
    moved = replace(problem, x0=np.asarray(x0, dtype=float))
    rows = sr.constraint_rows(moved, table)
    path = evaluate_table(moved, table, path=True).path_mean
    viol = rows.violation(np.einsum("rn,rn->r", rows.C, path[rows.tick]))
    floor = sr.float32_floor(moved, table, rows, moved.x0)
    return float(viol.max()), float(np.max(viol / floor))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--examples", default="robot_monotone,robot_narrow_corridor")
    ap.add_argument("--tolerances", default="1e-5,1e-2")
    ap.add_argument("--starts", type=int, default=4)
    ap.add_argument("--scales", default="0.01,0.1")
    ap.add_argument("--seed", type=int, default=3)
    args = ap.parse_args()
    print("| example | tolerance | start | per-tick worst | / floor | spline worst | / floor | "
          "plain fit worst | / floor |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in args.examples.split(","):
        p = stospline.load_problem(ROOT / "examples" / f"{name}.toml")
        d = stospline.design_problem(p, mode="joint")
        exact = table_of(d.design, quantize=False)
        rng = np.random.default_rng(args.seed)
        starts = [("x0", d.problem.x0)]
        for scale in (float(s) for s in args.scales.split(",")):
            for k in range(args.starts):
                x = d.problem.x0 + rng.normal(scale=scale, size=d.problem.n)
                starts.append((f"x0 + N(0, {scale:g}^2) #{k + 1}",
                               np.asarray(x, np.float32).astype(float)))
        for tol in (float(t) for t in args.tolerances.split(",")):
            tables = []
            for correct in (True, False):
                spline, K, k0, L, _ = sr.restore(d.problem, exact, d.table, tol,
                                                 correct=correct)
                tables.append(replace(d.table.with_arrays(K=K, k0=k0, L=L), spline=spline))
            for label, x0 in starts:
                cells = [worst(d.problem, t, x0) for t in (d.table, *tables)]
                print(f"| {name} | {tol:g} | {label} | "
                      + " | ".join(f"{a:.2e} | {r:.3g}" for a, r in cells) + " |", flush=True)


if __name__ == "__main__":
    main()
