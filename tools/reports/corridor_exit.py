"""How likely is the robot to leave its corridor? The exact oracle's bounds and Monte Carlo
through the compiled C controller, for today's design of examples/robot_corridor.toml.

Designs the file as `stospline design` does (exact zero-order hold at 1 kHz), takes the exact
mean and covariance of the position at every tick (`evaluate_table(output=C)`), bounds the
probability of leaving the L-shaped corridor (`oracle.exit_bound`: Cantelli, valid; Gaussian, an
assumption), then runs PATHS paths of the compiled controller against the stochastic plant
and counts each path's first exit (tick and wall), with one-sided 99 % Clopper-Pearson upper
bounds. Prints Markdown (the tables of docs/evidence/corridor-exit.md).

Usage: .venv/bin/python tools/reports/corridor_exit.py [--paths N] [--seed S] [--workers W]
       [--substeps K] [--file FILE]
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from stospline.pipeline import design_problem
from stospline.problem import load_problem
from stospline.harness.controller import build_controller
from stospline.oracle.exit_bound import corridor_outputs
from stospline.harness.exit_stats import corridor_report
from stospline.harness.montecarlo import simulate

ROOT = Path(__file__).resolve().parents[2]
FILE = ROOT / "examples" / "robot_corridor.toml"


def _pct(x: float) -> str:
    return f"{100 * x:.4g} %"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--paths", type=int, default=1_000_000)
    ap.add_argument("--seed", type=int, default=20261125)
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--substeps", type=int, default=1)
    ap.add_argument("--file", type=Path, default=FILE)
    a = ap.parse_args()
    p = load_problem(a.file)
    d = design_problem(p)
    outputs = corridor_outputs(p, d.table)
    scheme = corridor_outputs(p, d.table, propagator="euler", substeps=a.substeps)
    ctl = build_controller(d.table)
    start = time.perf_counter()
    mc = simulate(p, ctl, paths=a.paths, seed=a.seed, substeps=a.substeps, workers=a.workers)
    wall_s = time.perf_counter() - start
    rep = corridor_report(p, d.table, mc.exits, outputs=outputs)
    rep_scheme = corridor_report(p, d.table, None, outputs=scheme)
    print(f"# {p.name}: design J = {d.implemented.J:.6g} (oracle), {mc.paths} Monte Carlo "
          f"paths, seed {a.seed}, {a.substeps} plant step(s) per tick, {wall_s:.0f} s "
          f"({mc.paths * d.table.n_ticks / wall_s:.3g} path-ticks/s), mean cost "
          f"{mc.cost_mean_ci()[0]:.6g}\n")
    for i, (r, rs) in enumerate(zip(rep, rep_scheme)):
        m, bc, bg = r["mc"], r["bound"]["cantelli"], r["bound"]["gaussian"]
        print(f"## Corridor {i}: t = [{r['t'][0]:g}, {r['t'][1]:g}] s, epsilon "
              f"{r['epsilon']}\n")
        print("| quantity | P(leave at some tick) | worst single tick |")
        print("|---|---|---|")
        print(f"| Monte Carlo estimate ({m['exits']} of {m['paths']} paths) | "
              f"{_pct(m['estimate'])} | |")
        print(f"| Monte Carlo one-sided 99 % upper bound (Clopper-Pearson) | "
              f"{_pct(m['upper99'])} | |")
        print(f"| Cantelli union bound (valid) | {bc['total']:.4g} (sum {bc['sum']:.4g}) | "
              f"{bc['worst_tick']:.4g} at t = {bc['worst_tick_t']:.3f} s |")
        print(f"| Gaussian union bound (assumes Gaussian y) | {bg['total']:.4g} (sum "
              f"{bg['sum']:.4g}) | {bg['worst_tick']:.4g} at t = {bg['worst_tick_t']:.3f} s |")
        gs = rs["bound"]["gaussian"]
        print(f"| the same, moments of the simulated plant scheme | {gs['total']:.4g} (sum "
              f"{gs['sum']:.4g}) | {gs['worst_tick']:.4g} |\n")
        print("| time bin (s) | MC exits | estimate | 99 % upper | Gaussian bound | "
              "Cantelli bound |")
        print("|---|---|---|---|---|---|")
        for (lo, hi), mb, gb, cb in zip(r["bins_t"], m["by_bin"], bg["by_bin"], bc["by_bin"]):
            print(f"| {lo:.3f} – {hi:.3f} | {mb['exits']} | {_pct(mb['estimate'])} | "
                  f"{_pct(mb['upper99'])} | {gb:.3g} | {cb:.3g} |")
        print("\n| wall (y0 = x, y1 = y) | rows | MC exits | estimate | 99 % upper | "
              "Gaussian bound share |")
        print("|---|---|---|---|---|---|")
        for pw, mw, gw in zip(r["physical_walls"], m["by_physical_wall"],
                              bg["by_physical_wall"]):
            print(f"| {pw['wall']} | {pw['rows']} | {mw['exits']} | {_pct(mw['estimate'])} | "
                  f"{_pct(mw['upper99'])} | {gw:.3g} |")
        print("\nFirst exiting paths (index, time, wall): "
              + ", ".join(f"({e['path']}, {e['t']:.3f} s, {e['wall']})" for e in m["examples"]))
        if mc.exit_count(i):
            q = np.array([mc.exits.tick_percentile(i, v) for v in (5, 50, 95)]) / p.tick_hz + p.t0
            print(f"\nExit times of the paths that leave: 5/50/95 % at {q[0]:.3f} / "
                  f"{q[1]:.3f} / {q[2]:.3f} s")


if __name__ == "__main__":
    main()
