"""The fault table of a ``[plant]`` problem on the model itself: each fault of the standard
sweep (`stospline.harness.fault_sweep.default_levels`, levels relative to the plan and to the
model's fault-free commands) is a Monte Carlo run of the compiled controller against the model
in that loop (`stospline.harness.user_plant.simulate_model`, the same seed for every row),
beside the fault oracle of the linearisation. A fault the loop around a model cannot apply
(`model_faults_unsupported`: the linear plant's A and B scaled) leaves its row out, with the
reason."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stospline.harness.controller import build_controller
from stospline.harness.fault_sweep import FaultRow, default_levels, fault_row
from stospline.harness.montecarlo import z_value
from stospline.harness.user_plant import model_faults_unsupported, simulate_model

__all__ = ["LeftOut", "model_fault_table"]


@dataclass(frozen=True)
class LeftOut:
    """A row of the standard sweep not run around the model, and why."""
    fault: str
    level: str
    reason: str


def _row(problem, table, fault: str, level: str, run) -> FaultRow:
    """The fault table's row of the model's run `run` (`PlantRun`)."""
    paths = run.paths
    cost = (float(run.cost.mean()), z_value(0.95) * float(run.cost.std(ddof=1)) / np.sqrt(paths))
    covs = [np.atleast_2d(np.cov(X, rowvar=False)) for X in run.knots]
    ticks = run.sample_u.shape[0]
    return fault_row(problem, table, fault, level, run.faults, cost=cost,
                     means=[X.mean(axis=0) for X in run.knots], covs=covs,
                     saturation=run.saturated / (paths * ticks) if ticks else 0.0, paths=paths)


def model_fault_table(d, model, *, paths: int, seed: int, substeps: int
                      ) -> tuple[list[FaultRow], list[LeftOut]]:
    """``(rows, left_out)``: the fault table of design `d` (the linearisation's) on `model`,
    `paths` paths of `substeps` model steps per tick per row, and the rows left out."""
    problem = d.problem
    controller = build_controller(d.table)
    nominal = simulate_model(problem, controller, model, paths=paths, seed=seed,
                             substeps=substeps)
    rows, left_out = [], []
    for fault, level, faults in default_levels(problem, d.table, nominal):
        why = model_faults_unsupported(faults)
        if why:
            left_out.append(LeftOut(fault, level, f"{why[0]} {why[1]}"))
            continue
        run = nominal if not faults.any else simulate_model(
            problem, controller, model, paths=paths, seed=seed, substeps=substeps,
            faults=faults)
        rows.append(_row(problem, d.table, fault, level, run))
    return rows, left_out
