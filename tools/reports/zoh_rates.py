"""Exact sampled-data design vs sampled continuous-time gains on the robot, per tick rate.

Prints a Markdown table (predicted and oracle cost, constraint residuals) and writes
docs/figures/zoh_rates.png. Usage: .venv/bin/python tools/reports/zoh_rates.py [--mode joint]
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from stospline.design.continuous import design_continuous
from stospline.design.zoh import design_zoh
from stospline.oracle.evaluate import evaluate_table
from stospline.problem import load_problem
from stospline.table.format import table_of

ROOT = Path(__file__).resolve().parents[2]
RATES = [10, 20, 50, 100, 1000]


def residual(problem, moments) -> float:
    return max(float(np.abs(moments.knot_constraint[k] - kn.constraint.value).max())
               for k, kn in enumerate(problem.knots) if kn.constraint is not None)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mode", default="stagewise", choices=["stagewise", "joint"])
    ap.add_argument("--figure", default=str(ROOT / "docs" / "figures" / "zoh_rates.png"))
    args = ap.parse_args()
    problem = load_problem(ROOT / "examples" / "robot_corridor.toml")
    cont = design_continuous(problem, mode=args.mode)
    rows = []
    print(f"robot_corridor, {args.mode} multipliers; continuous-time J0 = {cont.J0:.10g}\n")
    print("| rate (Hz) | exact-ZOH predicted J | oracle J | relative diff | max constraint "
          "residual | sampled continuous: oracle J | residual |")
    print("|---:|---:|---:|---:|---:|---:|---:|")
    for hz in RATES:
        z = design_zoh(problem, hz, mode=args.mode)
        ex = evaluate_table(problem, table_of(z, quantize=False), path=False)
        sm = evaluate_table(problem, table_of(cont, hz, quantize=False), path=False)
        rows.append((hz, z.J0, ex.J, residual(problem, ex), sm.J, residual(problem, sm)))
        print(f"| {hz} | {z.J0:.10g} | {ex.J:.10g} | {abs(ex.J - z.J0) / z.J0:.1e} | "
              f"{residual(problem, ex):.1e} | {sm.J:.10g} | {residual(problem, sm):.2e} |")
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    r = np.array(rows)
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4))
    a1.semilogx(r[:, 0], r[:, 2], "o-", label="exact ZOH design (oracle)")
    a1.semilogx(r[:, 0], r[:, 4], "s--", label="sampled continuous gains (oracle)")
    a1.axhline(cont.J0, color="k", lw=0.8, label="continuous-time J0")
    a1.set_xlabel("controller rate [Hz]")
    a1.set_ylabel("expected cost")
    a1.legend()
    a1.grid(alpha=0.3)
    a2.loglog(r[:, 0], np.maximum(r[:, 3], 1e-16), "o-", label="exact ZOH design")
    a2.loglog(r[:, 0], r[:, 5], "s--", label="sampled continuous gains")
    a2.set_xlabel("controller rate [Hz]")
    a2.set_ylabel("max |E C2 x(t_k) - zeta_k|")
    a2.legend()
    a2.grid(alpha=0.3)
    fig.suptitle(f"robot corridor, {args.mode} multipliers")
    fig.tight_layout()
    fig.savefig(args.figure, dpi=100)
    print(f"\nwrote {args.figure}")


if __name__ == "__main__":
    main()
