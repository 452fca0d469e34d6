"""A parametric gain table: the nominal per-tick table and, per runtime parameter, the
sensitivity columns of its feed-forward and latch offsets, so that at a parameter vector
``theta``

    k0(theta)      = k0_nom      + S_k0      (theta - theta_nom)      (per tick)
    lambda0(theta) = lambda0_nom + S_lambda0 (theta - theta_nom)      (per stage)

while ``K``, ``L``, ``Lambda`` stay the nominal's. The columns are the tables of the designs
whose only source is one parameter (`stospline.design.sensitivity`), assembled by
`build_table` exactly as the nominal is, so a table that latches the state (more
multipliers than states) folds ``L lambda0`` into ``k0`` for the columns too.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from stospline.problem.parameters import check_theta
from stospline.table.format import GainTable, build_table

__all__ = ["ParametricTable", "parametric_table"]


@dataclass(frozen=True)
class ParametricTable:
    """The nominal table in double precision and its sensitivity columns.

    ``S_k0`` is (n_ticks, m, P), ``S_lambda0`` (n_stages, n_latch, P); ``parameters`` the
    problem's (`stospline.problem.parameters.Parameter`), in the columns' order."""
    table: GainTable
    S_k0: np.ndarray
    S_lambda0: np.ndarray
    parameters: tuple

    @property
    def nominal(self) -> np.ndarray:
        return np.array([p.nominal for p in self.parameters])

    def at(self, theta, *, quantize: bool = False) -> GainTable:
        """The table with the parameters set to `theta` (ValueError naming a parameter that
        is not finite or outside its range); float32 as the firmware stores it with
        ``quantize=True``, else double precision."""
        d = check_theta(self.parameters, theta) - self.nominal
        t = replace(self.table, k0=self.table.k0 + self.S_k0 @ d,
                    lambda0=self.table.lambda0 + self.S_lambda0 @ d)
        return t.quantized() if quantize else t


def parametric_table(problem, tick_hz: int, nominal: list[tuple], columns: list,
                     *, delay_ticks: int = 0) -> ParametricTable:
    """Assemble a `ParametricTable` from the nominal design's per-stage gains ``(K, k0, L,
    Lambda, lambda0)`` and, per parameter, the per-stage gains of its source design
    (`stospline.design.sensitivity.source_designs`; None: zero columns)."""
    table = build_table(problem, tick_hz, nominal, quantize=False, delay_ticks=delay_ticks)
    P = len(problem.parameters)
    S_k0 = np.zeros(table.k0.shape + (P,))
    S_lam = np.zeros(table.lambda0.shape + (P,))
    for j, col in enumerate(columns):
        if col is None:
            continue
        hz, stages = col
        if int(hz) != int(tick_hz):
            raise ValueError(f"column {j} is at {hz} Hz, the nominal at {tick_hz} Hz")
        unit = build_table(problem, tick_hz, stages, quantize=False, delay_ticks=delay_ticks)
        if unit.k0.shape != table.k0.shape or unit.lambda0.shape != table.lambda0.shape:
            raise ValueError(f"column {j} has another table layout than the nominal")
        S_k0[..., j], S_lam[..., j] = unit.k0, unit.lambda0
    return ParametricTable(table, S_k0, S_lam, tuple(problem.parameters))
