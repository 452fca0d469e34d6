"""The figure of `stospline plot` on a [plant] problem: the Monte Carlo on the model itself
(`stospline.nonlinear.simulate.run_on_model`) beside the oracle of the linearisation it was
designed on, or its fault oracle in a loop with faults that have one, drawn as
`plot.plot_corridor` draws the linear harness's run."""
from __future__ import annotations

from pathlib import Path

from stospline.report.plot import Labels, oracle_with_path, plot_corridor

__all__ = ["plot_plant", "plant_labels"]

RUN = "Monte Carlo on the [plant] model"


def plant_labels(d, summary: dict) -> Labels:
    """The names of the model's run (`summary`: its `plant_summary`) and its prediction."""
    f, c, p = summary["faults"], summary["cost"], summary["plant"]
    levels = " ".join(f"{k}={v}" for k, v in f["levels"].items())
    oracle = "oracle of the linearisation"
    if levels:
        oracle = f"fault {oracle}" if f["exact_oracle"] else f"{oracle} without the faults"
    title = (f"{d.problem.name}: {RUN} ({p['paths']} paths, {p['substeps']} substeps per "
             f"tick)\nmean cost {c['mc']:.4g} ± {c['halfwidth']:.2g} ({p['confidence']:.0%} "
             f"joint, scheme bias {c['scheme_bias']:.2g}); {oracle} {c['oracle']:.4g}"
             + (f"\nfaults around the model: {levels}" if levels else ""))
    return Labels(run=RUN, oracle=oracle, title=title)


def plot_plant(d, r, summary: dict, out: str | Path) -> None:
    """Draw the model's run `r` (`ModelRun`, `summary` its `plant_summary`) of design `d` (the
    linearisation's) to `out`."""
    plot_corridor(d, r.run, out, oracle_with_path(d, r.run.faults), plant_labels(d, summary))
