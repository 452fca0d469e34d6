"""Headline numbers of the robot corridor example, each recomputed here (docs/evidence/results.md).

Usage: .venv/bin/python tools/reports/results.py [--paths 10000] [--seed 1]
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from stospline.design.continuous import design_continuous
from stospline.design.zoh import design_zoh
from stospline.harness.montecarlo import compare_to_oracle
from stospline.oracle.evaluate import evaluate_continuous, evaluate_table
from stospline.pipeline import design_problem, simulate_problem
from stospline.problem import load_problem

ROOT = Path(__file__).resolve().parents[2]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--paths", type=int, default=10000)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    p = load_problem(ROOT / "examples" / "robot_corridor.toml")

    print("== continuous-time stage-wise design (paper's Corollary 1 / Proposition 3, corrected)")
    cont = design_continuous(p)
    mc = evaluate_continuous(p, cont)
    print(f"predicted J0 {cont.J0:.10f}   oracle of the continuous law {mc.J:.10f}   "
          f"relative difference {abs(mc.J - cont.J0) / cont.J0:.1e}")
    res = max(np.abs(mc.knot_constraint[k] - kn.constraint.value).max()
              for k, kn in enumerate(p.knots))
    print(f"max |E C2 x(t_k) - zeta_k| of the continuous law: {res:.1e}")

    print("\n== Remark 2: the design that ignores the noise, applied to the noisy robot")
    naive = design_continuous(p, noise=False)
    mn = evaluate_continuous(p, naive)
    print(f"expected cost: stochastic design {mc.J:.6f}, noise-ignoring design {mn.J:.6f} "
          f"(+{100 * (mn.J / mc.J - 1):.1f}%); the noise-ignoring design predicts {naive.J0:.6f}")
    for k in range(len(p.knots)):
        print(f"knot {k}: trace of state covariance {np.trace(mc.knot_cov[k]):.6f} vs "
              f"{np.trace(mn.knot_cov[k]):.6f}; output variance (x, y) "
              f"{mc.knot_cov[k][0, 0]:.6f}, {mc.knot_cov[k][2, 2]:.6f} vs "
              f"{mn.knot_cov[k][0, 0]:.6f}, {mn.knot_cov[k][2, 2]:.6f}")

    print("\n== joint multipliers (constraints as problem (1) states them)")
    joint = design_continuous(p, mode="joint")
    zj, zs = design_zoh(p, mode="joint"), design_zoh(p)
    print(f"continuous: joint J0 {joint.J0:.6f} < stage-wise {cont.J0:.6f};  exact ZOH at "
          f"{p.tick_hz} Hz: joint {zj.J0:.6f} < stage-wise {zs.J0:.6f}")

    print(f"\n== the product default: exact zero-order-hold design at {p.tick_hz} Hz, float32 table")
    d = design_problem(p)
    print(f"predicted J0 {d.design.J0:.10f}   oracle of the float64 law {d.law.J:.10f}   "
          f"oracle of the float32 table {d.implemented.J:.10f}")
    sim = simulate_problem(d, paths=args.paths, seed=args.seed)
    mean = sim.cost_mean_ci()[0]
    se = sim.cost_std() / np.sqrt(sim.paths)
    agree = compare_to_oracle(sim, d.implemented.J, d.implemented.knot_mean)
    print(f"Monte Carlo through the compiled C controller, {sim.paths} paths, seed {args.seed}: "
          f"mean cost {mean:.4f} ± {1.96 * se:.4f} (95%), z = {(mean - d.implemented.J) / se:+.2f}; "
          f"max |z| over cost and knot means {agree.max_abs_z:.2f} (99% joint limit "
          f"{agree.z_limit:.2f}): {'agree' if agree.ok else 'DISAGREE'}")
    euler = evaluate_table(p, d.table, propagator="euler", substeps=sim.substeps, path=False)
    print(f"plant scheme bias ({sim.substeps} substeps/tick, chosen automatically, computed "
          f"exactly): {euler.J - d.implemented.J:+.5f} "
          f"= {(euler.J - d.implemented.J) / se:+.3f} Monte Carlo standard errors")


if __name__ == "__main__":
    main()
