"""Robot designs that keep the paths inside the L-shaped corridor with probability 1 - eps, at
the least extra cost along one knob (`stospline.design.corridor_design`: a running cost
``w |a'y - c|^2`` towards the centre line of the leg each stage runs in).

For each weight of a grid: design (exact ZOH, 1 kHz), the exact oracle's cost of the law in
the *original* cost functional and its corridor bounds, and Monte Carlo through the compiled
C controller (SEARCH paths, seed S). For each eps the least weight of the grid whose
one-sided 99 % Clopper-Pearson upper bound is at most eps is chosen, then *certified* by a
fresh run (CERTIFY paths, another seed): selecting on one sample and certifying on the same
would bias the bound. Prints Markdown (docs/evidence/corridor-exit.md).

Usage: .venv/bin/python tools/reports/corridor_design.py [--search N] [--certify N]
       [--workers W] [--eps 0.1,0.05,0.01,0.001]
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from stospline.design.corridor_design import stage_polygons, strip_weights_problem
from stospline.pipeline import design_problem
from stospline.problem import load_problem
from stospline.sim.controller import build_controller
from stospline.sim.exit_bound import corridor_outputs, exit_bounds
from stospline.sim.exit_stats import clopper_pearson_upper
from stospline.sim.montecarlo import simulate
from stospline.sim.oracle import evaluate_table

ROOT = Path(__file__).resolve().parents[2]
FILE = ROOT / "examples" / "robot_corridor.toml"
WEIGHTS = [0.0, 1.0, 2.0, 3.0, 4.0, 6.0, 8.0, 11.0, 16.0, 22.0, 32.0, 45.0, 64.0]
SEARCH_SEED, CERTIFY_SEED = 20261126, 20261127


def evaluate(p, corridor, polys, w, paths, seed, workers):
    """(J in the original cost, Cantelli total, Gaussian total, exits, paths) of weight w."""
    d = design_problem(strip_weights_problem(p, corridor, polys, w))
    J = evaluate_table(p, d.table, path=False).J
    ((ym, yc),) = corridor_outputs(p, d.table)
    b = exit_bounds(corridor, ym, yc, p.t0, p.tick_hz)
    mc = simulate(p, build_controller(d.table), paths=paths, seed=seed, substeps=1,
                  workers=workers)
    exits = int(np.sum(mc.exit_tick[0] >= 0))
    return J, b["cantelli"].total, b["gaussian"].total, exits, paths


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--search", type=int, default=100_000)
    ap.add_argument("--certify", type=int, default=1_000_000)
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--eps", default="0.1,0.05,0.01,0.001")
    a = ap.parse_args()
    eps_list = [float(e) for e in a.eps.split(",")]
    p = load_problem(FILE)
    (corridor,) = p.corridors
    base = design_problem(p)
    ((ym, _),) = corridor_outputs(p, base.table)
    polys = stage_polygons(p, corridor, ym)
    start = time.perf_counter()
    print(f"Stage polygons (the leg each stage's mean runs in): {polys}; search {a.search} "
          f"paths (seed {SEARCH_SEED}), certification {a.certify} paths (seed "
          f"{CERTIFY_SEED}), 1 plant step per tick\n")
    print("| w | J (original cost) | extra | Cantelli bound | Gaussian bound | MC exits | "
          "estimate | 99 % upper |")
    print("|---|---|---|---|---|---|---|---|")
    grid = {}
    for w in WEIGHTS:
        J, bc, bg, k, n = grid[w] = evaluate(p, corridor, polys, w, a.search, SEARCH_SEED,
                                             a.workers)
        print(f"| {w:g} | {J:.4f} | {J - base.implemented.J:+.4f} | {bc:.3g} | {bg:.3g} | "
              f"{k} | {k / n:.3g} | {clopper_pearson_upper(k, n):.3g} |", flush=True)
    print("\n| eps | w | J | extra cost | Cantelli bound | Gaussian bound | certified MC "
          "estimate | 99 % upper | meets eps |")
    print("|---|---|---|---|---|---|---|---|---|")
    for eps in eps_list:
        ok = [w for w in WEIGHTS
              if clopper_pearson_upper(grid[w][3], grid[w][4]) <= eps]
        if not ok:
            print(f"| {eps:g} | none of the grid | | | | | | | no |")
            continue
        w = ok[0]
        J, bc, bg, k, n = evaluate(p, corridor, polys, w, a.certify, CERTIFY_SEED, a.workers)
        up = clopper_pearson_upper(k, n)
        print(f"| {eps:g} | {w:g} | {J:.4f} | {J - base.implemented.J:+.4f} "
              f"({100 * (J / base.implemented.J - 1):.2g} %) | {bc:.3g} | {bg:.3g} | "
              f"{k} / {n} = {k / n:.3g} | {up:.3g} | {'yes' if up <= eps else 'NO'} |",
              flush=True)
    print(f"\n({time.perf_counter() - start:.0f} s)")


if __name__ == "__main__":
    main()
