"""Dense bands keep the robot's expected path inside a narrow corridor at every tick.

Designs examples/robot_narrow_corridor.toml twice at its tick rate (exact zero-order hold,
joint multipliers): with its [[regions]] bands and without them (same knots otherwise), then
asks the oracle for the expected path at every tick and measures how far it leaves the
corridor. Prints the figures and writes docs/figures/corridor_bands.png.
Usage: .venv/bin/python tools/reports/corridor_bands.py
"""
from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np

from stospline.oracle.evaluate import evaluate_table
from stospline.pipeline import design_problem
from stospline.problem import load_problem, parse_problem
from stospline.oracle.region_distance import distance_outside

ROOT = Path(__file__).resolve().parents[2]
FILE = ROOT / "examples" / "robot_narrow_corridor.toml"


# The corridor's legs (its walls, as bounds on (x, y)); the file's bands keep 0.05 inside them.
LEGS = [(0.0, 3.0, [-np.inf, 0.5], [-0.5, 1.5]), (3.0, 6.0, [-1.5, 0.5], [-0.5, np.inf])]


def main() -> None:
    banded = load_problem(FILE)
    doc = tomllib.loads(FILE.read_text())
    doc.pop("regions")
    doc["knots"][0]["constraint"] = {"C": [[1, 0, 1, 0]], "value": [0.0]}
    free = parse_problem(doc)
    out = {}
    for label, prob in (("with dense bands", banded), ("without bands", free)):
        d = design_problem(prob, mode="joint")
        m = evaluate_table(prob, d.table)
        xy = m.path_mean[:, [0, 2]]
        dist = distance_outside(m.path_t, xy, LEGS)
        out[label] = (m, xy, d)
        n_bands = sum(kn.constraint.is_band for kn in prob.knots if kn.constraint is not None)
        print(f"{label:>17}: {len(prob.knots)} knots ({n_bands} with bands), J0 = "
              f"{d.design.J0:.6g}, oracle J = {m.J:.6g}, max distance outside the corridor "
              f"over {len(m.path_t)} ticks = {dist.max():.3g}")
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6, 6))
    for wall in banded.plot["walls"]:
        w = np.asarray(wall)
        ax.plot(w[:, 0], w[:, 1], color="0.2", lw=2)
    for (label, (m, xy, _)), style in zip(out.items(), ("-", "--")):
        ax.plot(xy[:, 0], xy[:, 1], style, lw=2, label=f"expected path, {label}")
    ax.plot(-5, 1, "o", color="tab:green", label="start")
    ax.plot(-1, 5, "s", color="tab:red", label="goal")
    ax.set_aspect("equal")
    ax.set_xlim(-5.5, 0.5)
    ax.set_ylim(0, 5.5)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)
    ax.set_title("robot, narrow corridor: oracle expected path at every tick")
    fig.tight_layout()
    target = ROOT / "docs" / "figures" / "corridor_bands.png"
    fig.savefig(target, dpi=100)
    print(f"wrote {target}")


if __name__ == "__main__":
    main()
