"""A problem with runtime parameters: its nominal design with the sensitivity columns
(`design_parametric`), the exact moments of the table at any parameter vector
(`evaluate_at`) or with the parameters changed during the plan, at any tick
(`evaluate_switched`), and the
exact expected cost as a quadratic in the parameters
(`cost_quadratic`).

A problem with bands (knot ``lower``/``upper`` rows, ``[[regions]]``) is designed so that every
band row holds for every parameter vector in the box: the tick-grid QP
(`stospline.design.tick_qp`, joint, exact zero-order hold) with the nominal's rows tightened
by their worst-case shift over the box (`stospline.oracle.over_box`), the columns those of the
problem without its bands (a fixed affine law: the nominal's active set is kept over the box).
The shifts of parameters that set ``x0`` go through the nominal's latch of the state, which
the tightening changes, so the design repeats (at most `BOX_ROUNDS` times) until the oracle's
margins over the box all hold, else DesignError naming the row and the parameter that moves
it most.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from stospline.design.bands import has_bands
from stospline.design.continuous import design_continuous
from stospline.design.sensitivity import check_parametric, source_designs
from stospline.design.zoh import check_delay, design_zoh
from stospline.errors import DesignError
from stospline.oracle.evaluate import Moments, evaluate_table
from stospline.oracle.over_box import (band_margins, box_moments, check_bands, check_swing,
                                       quadratic_fit)
from stospline.problem.parameters import problem_at
from stospline.table.parametric import ParametricTable, parametric_table

__all__ = ["BOX_ROUNDS", "ParametricDesign", "check_parametric_options", "design_parametric", "evaluate_at",
           "evaluate_switched", "tails_at", "cost_quadratic", "parametric_c_files",
           "fixed_parametric", "fixed_spline_parametric"]


@dataclass
class ParametricDesign:
    """The nominal design and the table with its sensitivity columns; for a problem with
    bands, the moments over the box (`stospline.oracle.over_box.BoxMoments`) and every band
    row's margins over it."""
    problem: object
    design: object
    table: ParametricTable
    discretization: str
    box: object = None
    margins: list = field(default_factory=list)


# Designs of a problem with bands before its margins over the box must hold.
BOX_ROUNDS = 4


def design_parametric(problem, *, discretization: str = "exact-zoh", mode: str = "stagewise",
                      delay_ticks: int = 0, noise: bool = True) -> ParametricDesign:
    """Design the problem at its nominal parameters and each parameter's source problem with
    the same designer (`stospline.design.sensitivity`): exact zero-order hold (with a one-tick
    delay when asked) or continuous, stage-wise or joint.

    Raises
    ------
    DesignError
        Naming ``parameters`` for bands or regions, or the designer's own errors.
    """
    check_parametric(problem)
    delay = check_delay(problem, delay_ticks, discretization)
    if has_bands(problem):
        return _design_over_box(problem, discretization=discretization, mode=mode,
                                delay_ticks=delay, noise=noise)
    if discretization == "exact-zoh":
        def designer(p):
            return design_zoh(p, noise=noise, mode=mode, delay_ticks=delay)
    elif discretization == "continuous":
        def designer(p):
            return design_continuous(p, noise=noise, mode=mode)
    else:
        raise DesignError("design.discretization", f"must be exact-zoh or continuous, got "
                                                   f"{discretization!r}")
    nominal = designer(problem)
    hz, stages = nominal.tick_gains()
    table = parametric_table(problem, hz, stages, source_designs(problem, designer),
                             delay_ticks=delay)
    return ParametricDesign(problem, nominal, table, discretization)


def _design_over_box(problem, *, discretization: str, mode: str, delay_ticks: int,
                     noise: bool) -> ParametricDesign:
    """The design of a problem with bands whose rows hold over the box (module docstring)."""
    from stospline.design.tick_qp import design_tick_qp
    for key, value, want in (("design.mode", mode, "joint"),
                             ("design.discretization", discretization, "exact-zoh"),
                             ("design.delay_ticks", delay_ticks, 0)):
        if value != want:
            raise DesignError(key, f"bands or regions with runtime parameters are met over the "
                                   f"box by the joint exact-zoh tick-grid design without "
                                   f"delay: set {key.split('.')[1]} = {want!r}, got {value!r}")

    def designer(p):
        return design_tick_qp(p, noise=noise)

    columns = source_designs(problem, designer)
    tighten = None
    margins: list = []
    for _ in range(BOX_ROUNDS):
        try:
            nominal = design_tick_qp(problem, noise=noise, tighten=tighten)
        except DesignError as exc:
            if tighten is None:
                raise
            # The tightened rows leave no room: name the row the last design broke most.
            w = min(margins, key=lambda m: m.worst)
            raise DesignError(w.field, f"row {w.row} cannot stay in its band for every "
                                       f"parameter in the box: tightened by its shift over "
                                       f"the box the design has no solution ({exc.field}: "
                                       f"{exc.reason}); untightened it leaves the band by "
                                       f"{-w.worst:.3g} at t = {w.t:g}, where {w.parameter} "
                                       f"moves it most ({w.moved:.3g}); narrow the ranges or "
                                       f"widen the band") from None
        hz, stages = nominal.tick_gains()
        table = parametric_table(problem, hz, stages, columns)
        box = box_moments(problem, table)
        margins = band_margins(problem, box)
        if all(m.holds for m in margins):
            return ParametricDesign(problem, nominal, table, discretization, box, margins)
        check_swing(problem, box)
        tighten = _tightening(problem, box)
    check_bands(margins)
    raise DesignError("parameters", "the band rows' margins over the box did not settle in "
                                    f"{BOX_ROUNDS} designs")


def _tightening(problem, box):
    """The `design_tick_qp` tightening of every band row: its rise and fall over the box at
    its tick."""
    shifts = {}
    for k, kn in enumerate(problem.knots):
        if kn.constraint is not None and kn.constraint.is_band:
            shifts["knot", k] = box.shift(kn.constraint.C)[:2]
    for reg in problem.tick_regions:
        shifts["region", reg.index] = box.shift(reg.C)[:2]

    def tighten(row):
        rise, fall = shifts[row.kind, row.index]
        return float(rise[row.tick, row.row]), float(fall[row.tick, row.row])
    return tighten


def evaluate_at(problem, table: ParametricTable, theta, *, quantize: bool = False,
                path: bool = False) -> Moments:
    """Exact moments and cost of the table at parameters `theta`, run on the problem at
    `theta` (its targets, constraint values, drift and start set to them)."""
    return evaluate_table(problem_at(problem, theta), table.at(theta, quantize=quantize),
                          path=path)


def evaluate_switched(problem, table: ParametricTable, theta, stage: int, theta2, *,
                      tick: int | None = None, quantize: bool = False,
                      path: bool = False) -> Moments:
    """Exact moments and cost of the table with the parameters `theta` set before tick 0 and
    `theta2` set just before tick `tick` (default the first tick of stage `stage`; else a tick
    of that stage), as the firmware applies stsp_set_params() then: the feed-forward at
    `theta2` from tick `tick` on, the latch offsets at `theta2` from the next latch at or after
    it (a stage start that latches), the multipliers latched before kept until then. The mean
    is affine in `theta` before the change and in `theta2` after it, the law piecewise so.
    The problem is at `theta` up to that stage and at `theta2` from it (its plant and the knot
    at its end: the device learns of a change in the world at `tick`)."""
    return evaluate_table(*_switched(problem, table, theta, stage, theta2, tick, quantize),
                          path=path)


def _switched(problem, table: ParametricTable, theta, stage: int, theta2, tick, quantize):
    """The problem and the gain table of `evaluate_switched`'s loop."""
    a, b = table.at(theta, quantize=quantize), table.at(theta2, quantize=quantize)
    start, end = int(a.stage_start[stage]), int(a.stage_start[stage + 1])
    j = start if tick is None else int(tick)
    if not start <= j < end:
        raise ValueError(f"tick {j} is not in stage {stage} (ticks {start} .. {end - 1})")
    later = np.asarray(a.stage_start[:-1]) >= j          # the stages latched after the change
    mixed = replace(a, k0=np.concatenate([a.k0[:j], b.k0[j:]]),
                    lambda0=np.where(later[:, None], b.lambda0, a.lambda0))
    pa, pb = problem_at(problem, theta), problem_at(problem, theta2)
    p = replace(pa, stages=pa.stages[:stage] + pb.stages[stage:],
                knots=pa.knots[:stage] + pb.knots[stage:])
    return p, mixed


def tails_at(problem, table: ParametricTable, theta, *, substeps: int, stage: int | None = None,
             theta2=None, tick: int | None = None, quantize: bool = False):
    """The loop's cost variance and knot moments up to the fourth under the Monte Carlo plant
    scheme with `substeps` steps per tick (`oracle.tails.evaluate_tails`): the standard errors
    of a run of `harness.params_loop.simulate_params` with `theta` fixed, or changed to
    `theta2` as `evaluate_switched` (``stage`` and ``tick``). Raises ValueError for what
    `oracle.tails.tails_unsupported` names."""
    from stospline.oracle.tails import evaluate_tails
    if stage is None:
        return evaluate_tails(problem_at(problem, theta), table.at(theta, quantize=quantize),
                              substeps=substeps)
    return evaluate_tails(*_switched(problem, table, theta, stage, theta2, tick, quantize),
                          substeps=substeps)


def cost_quadratic(problem, table: ParametricTable, *, quantize: bool = False):
    """``(J_nom, g, H)`` with the exact expected cost of the table at ``theta`` equal to
    ``J_nom + 2 g'd + d'H d``, ``d = theta - theta_nom``.

    The cost of an affine law is a quadratic in the parameters (the means are affine in
    them, the second moments quadratic), so it is fixed by its values at the nominal, at
    ``s_i e_i`` and ``s_i e_i / 2`` and at ``s_i e_i + s_j e_j`` (``s_i`` the longer side of
    the range from the nominal, towards its far end): ``1 + 2P + P(P-1)/2`` oracle runs
    (`stospline.oracle.over_box.quadratic_fit`)."""
    nom = table.nominal

    def J(d):
        return evaluate_at(problem, table, nom + d, quantize=quantize).J

    J0, g, H = quadratic_fit(J, table.parameters)
    return float(J0), g, H


def parametric_c_files(problem, source_name: str = "", options=None) -> dict[str, str]:
    """``{"<name>_params.h": ..., "<name>_params.c": ...}``: the sensitivity columns of the
    problem's design with `options` (`stospline.options.DesignOptions`; default its
    ``[design]`` options: mode, discretization, delay) as C text
    (`stospline.table.parametric_c`), beside the ``<name>.{c,h}`` that `stospline design`
    writes for the nominal. Per-tick tables only (DesignError naming ``design.table`` for a
    spline one: `stospline.pipeline.spline_parametric_files`)."""
    from stospline.table.parametric_c import generate_parametric_c
    opts = check_parametric_options(problem, options)
    if opts.spline:
        raise DesignError("design.table", "a spline table's columns are splines on its knots, "
                                          "written with it by stospline.pipeline."
                                          "spline_parametric_files (stospline design --table "
                                          "spline); these are per-tick columns")
    if opts.arith != "float32":
        return fixed_parametric(problem, source_name, opts)[0]
    pd = design_parametric(problem, discretization=opts.discretization, mode=opts.mode,
                           delay_ticks=opts.delay_ticks)
    header, source = generate_parametric_c(pd.table, source_name=source_name)
    return {f"{problem.name}_params.h": header, f"{problem.name}_params.c": source}


def fixed_parametric(problem, source_name: str = "", options=None):
    """``(files, pf, pd)`` of the problem's Q15/Q31 parametric controller (`options`' arith,
    `check_parametric_options`): the four files of
    `stospline.table.parametric_c.generate_parametric_qc` (``<name>_<arith>.{h,c}``, the gain
    table quantized with the columns, so that its scales hold over the whole box, and
    ``<name>_<arith>_params.{h,c}``, the columns), the
    `stospline.table.qparams.ParametricFixedPoint` and the `ParametricDesign`. The state
    range is the box's (`stospline.oracle.over_box.box_state_range`). ValueError from
    `quantize_parametric` when no scale holds the design; DesignError naming
    ``design.table`` for spline options (`fixed_spline_parametric`)."""
    from stospline.oracle.over_box import box_state_range
    from stospline.table.parametric_c import generate_parametric_qc
    from stospline.table.qparams import quantize_parametric
    opts = check_parametric_options(problem, options)
    if opts.arith == "float32":
        raise ValueError("fixed_parametric: the options' arith is float32")
    if opts.spline:
        raise DesignError("design.table", "these are per-tick columns; a spline table's are "
                                          "written by fixed_spline_parametric")
    pd = design_parametric(problem, discretization=opts.discretization, mode=opts.mode,
                           delay_ticks=opts.delay_ticks)
    box = pd.box if pd.box is not None else box_moments(problem, pd.table)
    pf = quantize_parametric(pd.table, opts.arith, box_state_range(box))
    return generate_parametric_qc(pd.table, pf, source_name=source_name), pf, pd


def fixed_spline_parametric(problem, source_name: str = "", options=None):
    """``(files, (pf, gains, cols), pd)``: `fixed_parametric` with spline columns, the
    problem's Q15/Q31 spline parametric controller (`options`' arith, their
    ``spline_tolerance``; `stospline.table.spline.qparams.quantize_spline_parametric` over
    the box's state range): ``<name>_<arith>_spline.{h,c}`` (the Q spline gain table in the
    scales of the augmented law) and ``<name>_<arith>_spline_params.{h,c}`` (format 2), what
    ``stospline design FILE --arith <arith> --table spline --out DIR`` writes. DesignError
    naming the option (`check_parametric_options` of `options` with a spline table: a delay,
    time-varying stage data) or as `quantize_spline_parametric`; ValueError when no scale
    holds the design."""
    from stospline.options import resolve_options
    from stospline.oracle.over_box import box_state_range
    from stospline.table.parametric_c import generate_parametric_qc
    from stospline.table.spline.qparams import quantize_spline_parametric
    opts = check_parametric_options(problem, replace(
        options if options is not None else resolve_options(problem), table="spline"))
    if opts.arith == "float32":
        raise ValueError("fixed_spline_parametric: the options' arith is float32")
    pd = design_parametric(problem, discretization=opts.discretization, mode=opts.mode,
                           delay_ticks=opts.delay_ticks)
    box = pd.box if pd.box is not None else box_moments(problem, pd.table)
    pf, gains, cols = quantize_spline_parametric(pd.table, opts.arith, box_state_range(box),
                                                 opts.spline_tolerance)
    files = generate_parametric_qc(pd.table, pf, source_name=source_name,
                                   spline=(gains, cols))
    return files, (pf, gains, cols), pd


def check_parametric_options(problem, options=None):
    """`options` (default the problem's resolved ``[design]``), or DesignError naming the
    option when the table they ask for has no sensitivity columns: per-tick columns for every
    arithmetic (float32, or Q15/Q31 scaled with the gains, `fixed_parametric`), spline columns
    for a spline table of a design without a delay and with constant stage data: float32
    (`stospline.refine.spline_params`, fitted on the spline's knots with the latch re-solved
    for its gains) or Q15/Q31 (`fixed_spline_parametric`, integer B-splines on the Q gain
    spline's spans). (A spline table with a band dual is refused once designed, by
    `stospline.refine.spline_params.spline_parametric`.)"""
    from stospline.options import resolve_options
    opts = options if options is not None else resolve_options(problem)
    if opts.table == "per-tick":
        return opts
    if opts.table != "spline":
        raise DesignError("design.table", f"runtime parameters have sensitivity columns for "
                                          f"table = \"per-tick\" or \"spline\", got "
                                          f"{opts.table!r}")
    if opts.delay_ticks:
        raise DesignError("design.delay_ticks", "spline columns of runtime parameters are "
                                                "re-solved for designs without a delay: set "
                                                "delay_ticks = 0 or table = \"per-tick\"")
    varying = [k for k, st in enumerate(problem.stages) if st.varying is not None]
    if varying:
        raise DesignError(f"stages[{varying[0]}]", "spline columns of runtime parameters are "
                                                   "re-solved for constant stage data only: "
                                                   "this stage's data vary in time; use "
                                                   "table = \"per-tick\"")
    return opts
