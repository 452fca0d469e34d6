"""Bands re-planned on the target: the robot_bands example started away from the design's x0.

The table of examples/robot_bands.toml carries the band dual; the firmware re-solves it from
the measured start state at the t0 latch. For the design's start and a few moved starts this
prints, from the exact oracle of the float32 table: the expected band outputs at t = 3 and
their worst distance outside the bands with the on-target re-solve and with the design's
affine latch map (the table without the dual), the cost of each, and the optimal cost of a
design made from scratch for that start. For the last start it also runs Monte Carlo through
the compiled C controller (cffi) and compares it with the oracle.
Usage: .venv/bin/python tools/reports/band_replan.py [--paths N] [--seed S]
"""
from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np

from stospline.design.bands import design_bands
from stospline.harness.controller import build_controller
from stospline.harness.montecarlo import compare_to_oracle, simulate
from stospline.oracle.evaluate import evaluate_table
from stospline.table.format import table_of
from stospline.problem import load_problem

ROOT = Path(__file__).resolve().parents[2]
FILE = ROOT / "examples" / "robot_bands.toml"
STARTS = ([-5.0, 0.0, 1.0, 0.0], [-4.5, 0.3, 1.8, 0.2], [-5.0, 0.5, 1.0, -0.5],
          [-5.4, 0.1, 2.0, 0.4])


def outside(problem, moments) -> float:
    """Largest distance of an expected band output outside its band (0 inside)."""
    lo, hi = problem.knots[0].constraint.bounds
    y = moments.knot_constraint[0]
    return float(max(np.max(lo - y), np.max(y - hi), 0.0))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--paths", type=int, default=8000)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    problem = load_problem(FILE)
    b = design_bands(problem, tick_hz=problem.tick_hz)
    resolved, affine = table_of(b), table_of(b, on_target_qp=False)
    print(f"robot_bands: {problem.tick_hz} Hz, {len(b.lower)} dual rows "
          f"({int(np.sum(b.lower != b.upper))} bands), bands at t = 3: x + y in [-0.1, 0.1], "
          f"y in [0.5, 1.5]")
    for x0 in STARTS:
        moved = replace(problem, x0=np.array(x0))
        m_q, m_a = evaluate_table(moved, resolved, path=False), evaluate_table(moved, affine,
                                                                                 path=False)
        best = design_bands(moved, tick_hz=problem.tick_hz)
        at = ",".join(a["at"][0] for a in best.active_set()[:2])
        print(f"x0 = {x0}: re-solved (x+y, y) = {np.round(m_q.knot_constraint[0], 4)}, "
              f"outside {outside(moved, m_q):.1e}, J {m_q.J:.6f} (optimum {best.J0:.6f}, "
              f"bands {at});  affine map: outside {outside(moved, m_a):.3g}, J {m_a.J:.6f}")
    mc = simulate(moved, build_controller(resolved), paths=args.paths, seed=args.seed,
                  substeps=8)
    agree = compare_to_oracle(mc, m_q.J, m_q.knot_mean)
    mean, half = mc.cost_mean_ci()
    y_mc = problem.knots[0].constraint.C @ mc.knot_mean_se(0)[0]
    print(f"Monte Carlo through the compiled C controller from x0 = {STARTS[-1]}, "
          f"{args.paths} paths, seed {args.seed}: mean cost {mean:.4f} ± {half:.4f} (95%), "
          f"oracle {m_q.J:.4f}; sample (x+y, y) at t = 3 {np.round(y_mc, 4)}; max |z| over "
          f"cost and knot means {agree.max_abs_z:.2f} (99% joint limit {agree.z_limit:.2f}): "
          f"{'agree' if agree.ok else 'DISAGREE'}")


if __name__ == "__main__":
    main()
