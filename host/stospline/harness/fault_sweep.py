"""The fault table of a design: each fault of the loop at a few levels -> cost, worst constraint
bias, knot variance and saturation, from the fault oracle where the fault is linear and from
Monte Carlo through the compiled C controller always.

The levels are relative to the plan, so one sweep fits any problem: sensor noise and the
quantizer's step as fractions of each state's range (``max_t |E x_j| + 3 std x_j``, the
fault-free oracle), actuator noise as a fraction of each input's largest command in the
fault-free run, one tick of delay, a missed-tick probability, and the plant's B and
diffusion scaled.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stospline.problem.faults import Faults
from stospline.problem.model import Problem
from stospline.harness.controller import CompiledController
from stospline.oracle.faults import evaluate_with_faults, has_exact_oracle
from stospline.harness.montecarlo import MonteCarloResult, simulate
from stospline.oracle.evaluate import Moments, state_range
from stospline.table.format import GainTable

__all__ = ["FaultRow", "default_levels", "fault_table", "fault_table_markdown", "SWEEP_ROWS",
           "FAULT_COLUMNS", "fault_row_cells", "fault_row"]

SWEEP_ROWS = 12      # runs in the standard sweep (`default_levels`), for budget estimates


@dataclass(frozen=True)
class FaultRow:
    """One fault level: the oracle's numbers (None without an exact oracle) and Monte Carlo's
    (mean cost with its 95 % half-width)."""
    fault: str
    level: str
    faults: Faults
    oracle_cost: float | None
    mc_cost: float
    mc_cost_hw95: float
    oracle_constraint_bias: float | None
    mc_constraint_bias: float
    oracle_knot_variance: float | None
    mc_knot_variance: float
    saturation: float            # fraction of (path, tick) steps on which a command clamped
    paths: int = 0


def default_levels(problem: Problem, table: GainTable, nominal: MonteCarloResult
                   ) -> list[tuple[str, str, Faults]]:
    """``(fault, level, Faults)`` for the standard sweep (the module docstring), starting with
    the fault-free loop; `nominal`: the fault-free run (its ``u_low`` and ``u_high``, as a
    model's `user_plant.PlantRun` has them too)."""
    r = state_range(problem, table, sigmas=3.0)
    u = np.maximum(np.abs(nominal.u_low), np.abs(nominal.u_high))
    u = np.where(np.isfinite(u) & (u > 0), u, 1.0)
    rows = [("none", "-", Faults())]
    for frac in (0.001, 0.01):
        rows.append(("sensor noise", f"{100 * frac:g}% of range", Faults(sensor_noise=frac * r)))
    for bits in (12, 8):
        rows.append(("sensor quantization", f"{bits}-bit over +-range",
                     Faults(sensor_quantum=2 * r / 2 ** bits)))
    rows.append(("computation delay", "1 tick", Faults(delay_ticks=1)))
    for p in (0.01, 0.1):
        rows.append(("missed ticks", f"p = {p:g}", Faults(miss_probability=p)))
    for frac in (0.01, 0.1):
        rows.append(("actuator noise", f"{100 * frac:g}% of the largest command",
                     Faults(actuator_noise=frac * u)))
    rows.append(("model mismatch", "B x 0.9", Faults(plant_B_scale=0.9)))
    rows.append(("model mismatch", "noise x 1.5", Faults(plant_noise_scale=1.5)))
    assert len(rows) == SWEEP_ROWS
    return rows


def _outputs(problem: Problem, k: int) -> np.ndarray | None:
    kn = problem.knots[k]
    if kn.constraint is not None:
        return kn.constraint.C
    if kn.penalty is not None:
        return kn.penalty.C
    return None


def _bias(problem: Problem, means) -> float:
    """The largest |E{C x} - value| over constrained knots (for a band, the distance of the
    mean outside it)."""
    worst = 0.0
    for k, kn in enumerate(problem.knots):
        c = kn.constraint
        if c is None:
            continue
        y = c.C @ means[k]
        lo, hi = c.bounds
        worst = max(worst, float(np.max(np.maximum(lo - y, 0) + np.maximum(y - hi, 0))))
    return worst


def _variance(problem: Problem, covs) -> float:
    """The largest variance of a constrained (else penalised) output at a knot."""
    worst = 0.0
    for k in range(len(problem.knots)):
        C = _outputs(problem, k)
        if C is not None:
            worst = max(worst, float(np.max(np.diag(C @ covs[k] @ C.T))))
    return worst


def fault_table(problem: Problem, controller: CompiledController, *, paths: int, seed: int,
                substeps: int, workers: int | None = None, scheduler: str | None = None,
                levels=None) -> list[FaultRow]:
    """The fault table of `controller`'s table on `problem` (`default_levels` unless `levels`
    is given as ``(fault, level, Faults)``), each level a Monte Carlo run of `paths` paths
    with the same seed (common random numbers: the rows differ by the fault, not the
    sample)."""
    table = controller.table
    nominal = simulate(problem, controller, paths=paths, seed=seed, substeps=substeps,
                       workers=workers, scheduler=scheduler, faults=Faults())
    rows = []
    for fault, level, faults in (levels or default_levels(problem, table, nominal)):
        mc = nominal if not faults.any else simulate(
            problem, controller, paths=paths, seed=seed, substeps=substeps, workers=workers,
            scheduler=scheduler, faults=faults)
        means = [mc.knot_mean_se(k)[0] for k in range(len(problem.knots))]
        covs = [np.atleast_2d(mc.knot_cov(k)) for k in range(len(problem.knots))]
        rows.append(fault_row(problem, table, fault, level, faults, cost=mc.cost_mean_ci(0.95),
                              means=means, covs=covs, saturation=mc.saturated_fraction,
                              paths=mc.paths))
    return rows


def fault_row(problem: Problem, table: GainTable, fault: str, level: str, faults: Faults, *,
              cost: tuple[float, float], means, covs, saturation: float, paths: int
              ) -> FaultRow:
    """The row of one run with `faults`: its mean cost with the 95 % half-width (`cost`),
    knot means and covariances, and saturated fraction, beside the fault oracle of `table` on
    `problem` where the faults have one."""
    exact: Moments | None = None
    if has_exact_oracle(table, faults):
        exact = evaluate_with_faults(problem, table, faults)
    return FaultRow(
        fault, level, faults, None if exact is None else exact.J, cost[0], cost[1],
        None if exact is None else _bias(problem, exact.knot_mean), _bias(problem, means),
        None if exact is None else _variance(problem, exact.knot_cov),
        _variance(problem, covs), saturation, paths)


FAULT_COLUMNS = ("fault", "level", "cost (oracle)", "cost (MC, 95% CI)",
                 "constraint bias (oracle / MC)", "knot variance (oracle / MC)",
                 "saturated ticks")


def fault_row_cells(r: FaultRow) -> list[str]:
    """The text of each of `FAULT_COLUMNS` for one row (``-`` where there is no exact
    oracle): the Markdown table and the report's HTML one."""
    def g(v, fmt="{:.5g}"):
        return "-" if v is None else fmt.format(v)
    return [r.fault, r.level, g(r.oracle_cost), f"{r.mc_cost:.5g} ± {r.mc_cost_hw95:.2g}",
            f"{g(r.oracle_constraint_bias, '{:.2e}')} / {r.mc_constraint_bias:.2e}",
            f"{g(r.oracle_knot_variance)} / {r.mc_knot_variance:.5g}",
            f"{100 * r.saturation:.3g}%"]


def fault_table_markdown(rows: list[FaultRow]) -> str:
    """The table as Markdown."""
    out = ["| " + " | ".join(FAULT_COLUMNS) + " |", "|" + "---|" * len(FAULT_COLUMNS)]
    out += ["| " + " | ".join(fault_row_cells(r)) + " |" for r in rows]
    return "\n".join(out) + "\n"
