"""A parametric table in spline form, and what it guarantees over the box.

`spline_parametric` fits the sensitivity columns of a parametric design on its spline gain
table's knots (`stospline.table.spline.params`), re-solves the latch offsets' columns for the
spline's law, and returns the parametric table *as flashed*: the spline table's float32 gains
and latch maps, the columns as the firmware evaluates them. `certify_over_box` runs the
over-the-box oracle (`stospline.oracle.over_box`) on that table, so that its margins and
exit bounds are those of the spline law with its columns, not of the per-tick design: the
compression's error enters through the table itself, exactly, rather than as a bound added
afterwards. The arithmetic is double precision on the stored values (the float32 rounding of
each product and sum in the firmware is not counted, as for every table's certificate).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from stospline.design.sensitivity import unit_problem
from stospline.errors import DesignError
from stospline.oracle.over_box import band_margins, box_moments
from stospline.table.format import _to_float32
from stospline.table.parametric import ParametricTable
from stospline.table.spline.latch import _groups
from stospline.table.spline.params import SplineColumns, box_error, fit_columns
from stospline.table.spline.restore import is_state_latching

__all__ = ["CERTIFIED", "SplineParametric", "spline_parametric", "spline_parametric_of",
           "spline_parametric_c", "certify_over_box"]


@dataclass(frozen=True)
class SplineParametric:
    """``table`` the float32 spline gain table, ``columns`` its `SplineColumns`, ``flashed``
    the `ParametricTable` of both (what the oracle evaluates), ``per_tick`` the design's."""
    table: object
    columns: SplineColumns
    flashed: ParametricTable
    per_tick: ParametricTable


def _latch_columns(problem, stable, evaluated: np.ndarray, P: int, *, rounded: bool = True
                   ) -> np.ndarray:
    """The latch offsets' columns re-solved for the spline's law: parameter p's source alone
    (`unit_problem`, from x0 = 0: the shift of the mean per unit of d_p) under the spline's
    K, L, its stored (float32) Lambda and the column's feed-forward as evaluated. At each
    latch, in order, the column puts the shift of the latch group's constraints on the shift
    of their values, for the mean the earlier columns give at the latch tick (the stored
    Lambda acts on it: its rounding is compensated). `rounded`: each column rounded to
    float32 on the grid of its largest entry before the next latch's mean is taken (the
    table as flashed)."""
    from stospline.oracle.evaluate import evaluate_table
    n = stable.dims[0]
    S = np.zeros(np.shape(stable.lambda0) + (P,))
    if stable.dims[2] == 0 or is_state_latching(stable):
        return S
    Lam = np.asarray(stable.Lambda, float)
    for p in range(P):
        unit = unit_problem(problem, p)
        law = replace(stable, k0=np.asarray(evaluated[..., p], float),
                      Lambda=Lam, lambda0=np.zeros(np.shape(stable.lambda0)))
        for latch, width, _, _, CW, zeta in _groups(unit, law, None, None):
            if latch is None:
                continue
            tick = int(stable.stage_start[latch])
            x = evaluate_table(unit, replace(law, lambda0=S[..., p]), path=True,
                               output=np.eye(n)).path_mean[tick] if tick > 0 else np.zeros(n)
            G = CW[:, n:n + width]
            col = np.linalg.solve(G, zeta - CW[:, -1] - (CW[:, :n] + G @ Lam[latch, :width]) @ x)
            if rounded:
                # on the float32 grid of the column's largest entry (as the gains'
                # coefficients, `fit._coefficients`): an exact zero that the solve leaves at
                # 1e-10 keeps none of the digits that move with the design's last bits
                q = np.ldexp(1.0, np.frexp(np.abs(col).max())[1] - 24)
                col = (np.rint(col / q) * q).astype(np.float32)
            S[latch, :width, p] = col
    return S


def spline_parametric(problem, ptable: ParametricTable, stable) -> SplineParametric:
    """The spline form of parametric table `ptable` on the spline gain table `stable`
    (`stospline.table.spline.spline_table` of ``ptable.table``, float32).

    Raises
    ------
    DesignError
        ``design.table`` for a spline table with a band dual (its dual would need columns of
        its own) or a fixed-point one, a design for a delay, time-varying stage data.
    """
    if getattr(stable, "spline", None) is None or getattr(stable, "arith", "float32") \
            != "float32":
        raise DesignError("design.table", "spline columns need a float32 spline table")
    if stable.band_qp is not None:
        raise DesignError("design.table", "a spline table with a band dual has no spline "
                                          "columns (its dual would need columns of its own)")
    if getattr(stable, "delay_ticks", 0) or any(st.varying is not None
                                                for st in problem.stages):
        raise DesignError("design.table", "spline columns are re-solved for designs without a "
                                          "delay and with constant stage data only")
    P = len(ptable.parameters)
    coef, evaluated, error = fit_columns(stable.spline, stable.stage_start, ptable.S_k0,
                                         ptable.parameters)
    S_lam = _latch_columns(problem, stable, evaluated, P)
    S_lam32 = np.stack([_to_float32(S_lam[..., j]) for j in range(P)], -1) if P else S_lam
    cols = SplineColumns(coef, evaluated, np.asarray(S_lam32, np.float32), error,
                         box_error(evaluated, ptable.S_k0, ptable.parameters))
    flashed = ParametricTable(
        replace(stable, K=np.asarray(stable.K, float), k0=np.asarray(stable.k0, float),
                L=np.asarray(stable.L, float), Lambda=np.asarray(stable.Lambda, float),
                lambda0=np.asarray(stable.lambda0, float)),
        evaluated.astype(float), cols.S_lambda0.astype(float), ptable.parameters)
    return SplineParametric(stable, cols, flashed, ptable)


def spline_parametric_of(problem, options=None, *, ptable: ParametricTable | None = None,
                         stable=None) -> SplineParametric:
    """`spline_parametric` of a problem with parameters: its parametric design with
    `options` (`stospline.options.DesignOptions`, default the file's ``[design]``) or
    `ptable`, the design's `ParametricTable` when already made, on the float32 spline table
    `stable` (default the spline of the design's table at the options' ``spline_tolerance``;
    `stospline.pipeline.spline_parametric_files` passes the designed one)."""
    from stospline.oracle.parametric import design_parametric
    from stospline.options import resolve_options
    from stospline.table.spline import spline_table
    opts = options if options is not None else resolve_options(problem)
    pt = ptable if ptable is not None else design_parametric(
        problem, discretization=opts.discretization, mode=opts.mode,
        delay_ticks=opts.delay_ticks, noise=opts.noise).table
    if stable is None:
        stable = spline_table(problem, pt.table, opts.spline_tolerance,
                              per_tick=pt.table.quantized())
    return spline_parametric(problem, pt, stable)


def spline_parametric_c(sp: SplineParametric, stem: str, source_name: str = ""
                        ) -> dict[str, str]:
    """``{"<stem>_params.h": ..., "<stem>_params.c": ...}``: the format-2 parameter table of
    `sp`'s spline columns (`stospline.table.parametric_c.generate_spline_parametric_c`),
    beside the spline gain table ``<stem>.{h,c}``."""
    from stospline.table.parametric_c import generate_spline_parametric_c
    header, source = generate_spline_parametric_c(sp.table, sp.columns, sp.per_tick.parameters,
                                                  source_name=source_name)
    return {f"{stem}_params.h": header, f"{stem}_params.c": source}


# The tables `certify_over_box` certifies (its keys), the flashed spline table's first.
CERTIFIED = ("spline", "per_tick", "per_tick_float32", "spline_design_columns")


def certify_over_box(problem, sp: SplineParametric, keys=CERTIFIED) -> dict:
    """The guarantees of the flashed spline parametric table over the box: every band row's
    worst margin over the box (`band_margins`: ``worst_band_margin``, ``bands_hold``, and
    each row's `RowMargin.as_dict` in ``bands``), every corridor's Cantelli bound over the
    box (`stospline.oracle.exit_bound.exit_bounds_over_box`: the largest per tick, and the
    sum), the same of the per-tick design in double precision, of its float32 table (the
    gains and columns as the per-tick firmware stores them) and of the spline's gains with
    the design's exact columns, for comparison (`keys`, a subset of `CERTIFIED`: the tables
    to certify, each an oracle over the box), and the columns' errors."""
    from stospline.oracle.exit_bound import exit_bounds_over_box
    out = {"column_error": sp.columns.error.tolist(),
           "column_box_error": sp.columns.box_error.tolist()}
    pt = sp.per_tick
    tables = {
        "spline": lambda: sp.flashed,
        "per_tick": lambda: pt,
        "per_tick_float32": lambda: ParametricTable(
            pt.table.quantized(), pt.S_k0.astype(np.float32).astype(float),
            pt.S_lambda0.astype(np.float32).astype(float), pt.parameters),
        "spline_design_columns": lambda: ParametricTable(sp.flashed.table, pt.S_k0,
                                                         pt.S_lambda0, pt.parameters)}
    for key in keys:
        box = box_moments(problem, tables[key]())
        margins = band_margins(problem, box)
        entry = {"worst_band_margin": min((m.worst for m in margins), default=None),
                 "bands_hold": all(m.holds for m in margins),
                 "bands": [m.as_dict() for m in margins], "corridors": []}
        for c in problem.corridors:
            b = exit_bounds_over_box(c, box, problem.t0, problem.tick_hz)["cantelli"]
            entry["corridors"].append({"worst_tick": b.worst_tick, "total": b.total})
        out[key] = entry
    return out
