"""The library calls behind the CLI, as steps: design a problem (`design_problem`: options,
the designer, its table, the oracle), write its tables (`generated_files`), simulate it
(`simulate_problem`) and summarise (`stospline.report`).

Everything the CLI does is one call here, so scripts and tests use the same path.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from stospline import budget, limits, progress, strict
from stospline.design.bands import has_bands
from stospline.design.zoh import check_delay
from stospline.design_method import DesignedLaw, design
from stospline.errors import DesignError, ProblemError
from stospline.options import DesignOptions, resolve_options
from stospline.output_names import table_stem
from stospline.problem.faults import Faults
from stospline.problem.model import Problem
from stospline.report.design_summary import design_summary
from stospline.report.json_numbers import rounded
from stospline.oracle.evaluate import evaluate_continuous, evaluate_table, state_range
from stospline.precision import ceil_significant
from stospline.table.codegen import generate_c
from stospline.table.format import GainTable, TickGains, table_of
from stospline.table_options import DEFAULT_SIGMAS, check_spline_tolerance

if TYPE_CHECKING:
    from stospline.refine.every_tick import EveryTick
    from stospline.table.qformat import FixedPointTable
    from stospline.harness.montecarlo import MonteCarloResult
    from stospline.oracle.evaluate import Moments
    from stospline.harness.plant_scheme import SubstepChoice

__all__ = ["Designed", "design_problem", "design_summary", "simulate_problem",
           "simulation_summary", "verdict", "plan_substeps", "write_outputs", "start_from",
           "double_table", "fixed_point_table", "fixed_point_spline", "check_implementable",
           "generated_files", "design_files", "spline_parametric_files", "loop_moments",
           "fault_sweep",
           "simulation_estimate", "check_faults_runnable", "usable_workers",
           "fault_table_unavailable", "fault_sweep_runs", "table_numbers"]


# Names of `stospline.report.simulation_summary` this module offers too, loaded on first use
# (PEP 562): a design does not load the Monte Carlo harness.
_SIMULATION_REPORT = ("simulation_summary", "verdict", "loop_moments", "predicted_cost")


def __getattr__(name: str):
    if name in _SIMULATION_REPORT:
        from stospline.report import simulation_summary as report
        value = getattr(report, name)
        globals()[name] = value          # later look-ups skip this function
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


@dataclass
class Designed:
    """A design and what the oracle says of it.

    ``law`` is the exact outcome of the design's own law (the continuous-time law, or the
    zero-order-hold law with unquantized gains); ``implemented`` that of the float32 table at
    the tick rate, which is what the firmware runs.
    """
    problem: Problem
    design: TickGains   # a continuous, zero-order-hold or band design
    discretization: str
    table: GainTable
    law: Moments
    implemented: Moments
    # With ``table="spline"``: what the spline table costs and saves, for the law exactly as
    # the firmware evaluates it (`stospline.refine.spline_certificate.certificate`).
    certificate: dict | None = None
    # With [[regions]] at every tick: how they were met, by constraint generation or the
    # tick-grid QP (`stospline.refine.every_tick.EveryTick`).
    every_tick: EveryTick | None = None
    # The options it was designed with (`stospline.options.resolve_options`).
    options: DesignOptions | None = None
    # Bands or regions with runtime parameters: the parametric design and its band rows'
    # margins over the parameter box (`stospline.oracle.parametric.ParametricDesign`).
    over_box: object = None

    def gains(self, *, quantized: bool = True):
        """``Gains(t, K, k0, L, Lambda, lambda0, stage_start)`` as numpy arrays: K is
        (n_ticks, m, n), k0 (n_ticks, m), L (n_ticks, m, n_latch), t (n_ticks,) the tick times
        (`stospline.gains`); float32 table values by default, ``quantized=False`` for the
        design's double-precision gains."""
        from stospline.gains import gains_of
        return gains_of(self, quantized=quantized)


def design_problem(problem: Problem, *, noise: bool = True,
                   discretization: str = "exact-zoh", mode: str = "stagewise",
                   delay_ticks: int | None = None, table: str | None = None,
                   spline_tolerance: float | None = None,
                   max_memory: float | None = budget.DEFAULT_MAX_GIB,
                   max_time: float | None = budget.DEFAULT_MAX_SECONDS,
                   options: DesignOptions | None = None) -> Designed:
    """Design at the problem's tick rate, quantize the table, evaluate both with the oracle.

    Parameters
    ----------
    problem : Problem
        From `load_problem`, `parse_problem` or `problem_from_arrays`.
    noise : bool
        False designs as if there were no noise (the paper's Remark 2); the oracle still
        evaluates the law under the problem's noise.
    discretization : {"exact-zoh", "continuous"}
        "exact-zoh" (default) is optimal for the controller as it runs (held at each tick);
        "continuous" solves the continuous-time design and samples its gains at the ticks.
    mode : {"stagewise", "joint"}
        Multipliers latched at every stage start, or once at t0 (`stospline.design.latch`).
    delay_ticks : {0, 1}, optional
        1: design for a one-tick computation delay (the command computed from the state at
        tick j is applied at tick j+1; exact-zoh only). The table's law is then over ``[x;
        a]``, ``a`` the command being applied (docs/guide/firmware.md, "A one-tick computation
        delay").
        Default: the problem's ``[design] delay_ticks``, else 0.
    table : {"per-tick", "spline"}, optional
        The table the firmware runs: one row of gains per tick, or cubic B-splines of the
        gains per stage, with the latch maps re-solved so that the expected constraints hold
        for the law as the firmware evaluates it (`stospline.table.spline.fit`; time-varying data,
        a one-tick delay and a band dual of at most 8 rows included), or, for a table that
        latches the state (bands beyond a band dual, regions at every tick by the tick-grid
        QP), its k0 coefficients corrected so that every constraint row holds for the
        design's x0 (`stospline.table.spline.restore`). ``implemented`` is then the
        spline law's and ``certificate`` says what it costs. Default: the problem's
        ``[design] table``, else "per-tick".
    spline_tolerance : float, optional
        The spline's budget: the largest relative error of a gain entry (default: the
        problem's ``[design] spline_tolerance``, else 1e-5).
    max_memory, max_time : float or None
        Refuse (BudgetError, naming the key that costs most) a design estimated to need more
        than `max_memory` GiB (at most the machine's RAM) or `max_time` seconds, before any
        work (`stospline.budget`; the command line's ``--max-memory``/``--max-time`` and
        defaults, 4 GiB and 600 s). None: no check (a caller that checked the whole run).
    options : DesignOptions, optional
        The options resolved already (`stospline.options.resolve_options`, as the command
        line does); when given, `noise`, `discretization`, `mode`, `delay_ticks`, `table` and
        `spline_tolerance` are not read.

    Returns
    -------
    Designed
        ``design`` (predicted cost ``design.J0``), ``table`` (the float32 per-tick table the
        firmware runs), ``law`` and ``implemented`` (the oracle's exact moments and cost of
        the design's own law and of the table as implemented).

    Raises
    ------
    DesignError
        The problem has no solution (an infeasible constraint, no bounded solution).
    BudgetError
        The estimate exceeds `max_memory` or `max_time`.

    Examples
    --------
    >>> import stospline
    >>> d = stospline.design_problem(stospline.load_problem("examples/robot_corridor.toml"))
    >>> print(f"{d.design.J0:.4f} {d.implemented.J:.4f}")   # predicted, and as implemented
    27.7745 27.7745
    >>> d.table.n_ticks, d.table.dims                        # ticks; (n, m, multipliers)
    (6000, (4, 2, 4))
    """
    if options is None:
        options = resolve_options(problem, noise=noise, mode=mode,
                                  discretization=discretization, delay_ticks=delay_ticks,
                                  table=table, spline_tolerance=spline_tolerance)
    options = _checked(problem, options)
    _within_budget(max_memory, max_time, lambda: budget.estimate(
        problem, command="design", **options.workload()), problem)
    try:
        return _design_problem(problem, options)
    except FloatingPointError:
        # Products of extreme data (B = 1e308, C'C of 1e300) overflowed to Inf or NaN.
        raise DesignError(*strict.overflow_failure(problem)) from None


def _checked(problem: Problem, options: DesignOptions) -> DesignOptions:
    """Refuse, before the work, a mode whose table latches more multipliers than the firmware
    takes (STSP_MAX_LATCH) and a delay the design cannot make; the delay as an int."""
    limits.check_mode(problem, options.mode)
    return replace(options, delay_ticks=check_delay(problem, options.delay_ticks,
                                                    options.discretization))


def _within_budget(max_memory, max_time, estimate, problem: Problem, **options) -> None:
    """Refuse (BudgetError) the work `estimate()` describes when it exceeds the limits (None
    for both: no check)."""
    if max_memory is None and max_time is None:
        return
    max_bytes, max_seconds = budget.check_limits(
        budget.DEFAULT_MAX_GIB if max_memory is None else max_memory,
        budget.DEFAULT_MAX_SECONDS if max_time is None else max_time)
    budget.enforce(estimate(), problem, max_seconds=max_seconds, max_bytes=max_bytes,
                   library=True, **options)


def _design_problem(problem: Problem, options: DesignOptions) -> Designed:
    """The steps: the designer's law, its tables, the oracle of both, the spline's
    certificate."""
    law = design(problem, options)
    table, per_tick, exact = _tables(law, options)
    moments, implemented, compressed = _evaluate(law, table, exact, options)
    d = Designed(law.problem, law.gains, options.discretization, table, moments, implemented,
                 every_tick=law.every_tick, options=options, over_box=law.over_box)
    if options.spline:
        from stospline.refine.spline_certificate import certificate
        d.certificate = certificate(d.problem, table, per_tick, d.design.J0, compressed,
                                    implemented, tolerance=options.spline_tolerance)
    return d


def _tables(law: DesignedLaw, options: DesignOptions):
    """``(table, per_tick, exact)``: the table the firmware runs (float32 per-tick, or the
    spline of it), the float32 per-tick table, and the design's own law in double precision
    (the oracle's reference for zero-order hold, what a spline is fitted to; None for a
    continuous design without a spline, which needs neither)."""
    table = table_of(law.gains)
    # A float32 entry that overflowed would make the oracle's moments non-finite: refuse it
    # here, naming the cause, before evaluating the table as implemented.
    strict.check_table_finite(law.problem, table,
                              exact=lambda: table_of(law.gains, quantize=False))
    exact = (table_of(law.gains, quantize=False)
             if options.discretization != "continuous" or options.spline else None)
    if not options.spline:
        return table, table, exact
    from stospline.design.varying import mean_maps
    from stospline.table.spline import spline_table
    from stospline.table.spline.restore import is_state_latching
    if law.every_tick is not None and not is_state_latching(table):
        # Constraint generation's band dual re-plans its working set only; the other
        # ticks' slack is not restored for the spline's gains (the tick-grid QP's tables
        # latch the state and are: `spline_restore`).
        raise DesignError("design.table", "a region at every tick met by a band dual (at "
                                          "most 8 rows) has no spline table: its other "
                                          "ticks are not restored; use table \"per-tick\"")
    return (spline_table(law.problem, exact, options.spline_tolerance, per_tick=table,
                         varying_maps=mean_maps), table, exact)


def _evaluate(law: DesignedLaw, table: GainTable, exact: GainTable | None,
              options: DesignOptions):
    """``(law, implemented, compressed)``: the oracle's moments of the design's own law, of
    the table as implemented, and of the law a spline compresses (the sampled per-tick table
    for a continuous design, else the law itself)."""
    problem = law.problem

    def evaluate_exact():
        return evaluate_table(problem, exact, path=False)
    # A spline's certificate checks every row of a region at every tick: the mean path.
    path = options.spline and bool(problem.tick_regions)
    evaluations = [evaluate_exact, lambda: evaluate_table(problem, table, path=path)]
    if options.discretization == "continuous":
        # The law is the continuous-time one; a spline's certificate is still measured
        # against the sampled table it compresses (the law the firmware would otherwise run).
        evaluations[0] = lambda: evaluate_continuous(problem, law.continuous)
        if options.spline:
            evaluations.append(evaluate_exact)
    moments, implemented, *compressed = _concurrently(evaluations, 2 * table.n_ticks)
    return moments, implemented, compressed[0] if compressed else moments


def _concurrently(evaluations, ticks: int) -> list:
    """Run independent oracle evaluations two at a time (their loops are C or numpy, which
    release the GIL), under one progress bar of `ticks`; results in order, each exactly
    what it would be alone."""
    # Two plain threads (concurrent.futures would add its import, and logging's, to every
    # design), each evaluation in a thread's fresh context as a pool would run it.
    import threading
    results, errors = [None] * len(evaluations), [None] * len(evaluations)
    order, lock = iter(range(len(evaluations))), threading.Lock()

    def work():
        while True:
            with lock:
                i = next(order, None)
            if i is None:
                return
            try:
                results[i] = evaluations[i]()
            except BaseException as exc:  # noqa: BLE001 - raised below, in order
                errors[i] = exc

    with progress.shared("oracle", ticks):
        threads = [threading.Thread(target=work, name=f"stospline-oracle-{k}")
                   for k in range(min(2, len(evaluations)))]
        for t in threads:
            t.start()
        try:
            for t in threads:
                t.join()
        except BaseException:            # an interrupt: the evaluations end first, as a
            for t in threads:            # pool's shutdown waits for them
                t.join()
            raise
    for exc in errors:
        if exc is not None:
            raise exc
    return results


def start_from(d: Designed, x0) -> Designed:
    """The same design and table, run from another start state (a measured x0 on the target).

    The tables do not change: the firmware latches its multipliers from the state it measures
    at t0 (re-solving the band dual when the table carries one), so the law is optimal for the
    new start too. ``implemented`` is re-evaluated from there; ``law`` is the design's, from its
    own x0. Raises ProblemError (field ``x0``) if x0 is not n finite numbers."""
    x = np.asarray(x0, dtype=float).reshape(-1)
    if x.shape != (d.problem.n,) or not np.all(np.isfinite(x)):
        raise ProblemError("x0", f"a start state needs {d.problem.n} finite numbers, got "
                                 f"{np.asarray(x0).tolist()}")
    limits.check_state(x)   # the controller measures it in float32
    moved = replace(d.problem, x0=x)
    return replace(d, problem=moved, implemented=evaluate_table(moved, d.table, path=False))


def write_outputs(out_dir: str | Path, files: dict[str, str], inputs=()) -> list[Path]:
    """Write every file or none, as one set (`stospline.atomic.write_set`): staged and fsynced
    in a directory inside `out_dir`, committed by a journal, then renamed into place with
    SIGINT/SIGTERM deferred; a writer killed with SIGKILL is completed or undone by the next
    write into `out_dir`. Raises `stospline.atomic.OutputError` (nothing changed) when the
    directory cannot take the files, e.g. a target is a directory or one of `inputs` (the
    files the run read, which are never replaced)."""
    from stospline.atomic import write_set
    return write_set(out_dir, files, inputs)


def double_table(d: Designed) -> GainTable:
    """The design's per-tick table before float32 rounding (double precision)."""
    return table_of(d.design, quantize=False)


def fixed_point_table(d: Designed, arith: str, *, sigmas: float = DEFAULT_SIGMAS,
                x_range=None) -> FixedPointTable:
    """Quantize a design to a Q15/Q31 table (`stospline.table.qformat`).

    Parameters
    ----------
    d : Designed
    arith : {"q15", "q31"}
    sigmas : float
        State range ``max_t |mean| + sigmas * std`` of the float32 law (the oracle's exact
        moments), from which each state's power-of-two scale is chosen.
    x_range : array-like (n,), optional
        The state ranges to use instead.

    Returns
    -------
    FixedPointTable
        Integer tables with per-entry scales and the bound on ``|u_fixed - u_double|``
        (``summary()``).

    Examples
    --------
    >>> import stospline
    >>> d = stospline.design_problem(stospline.load_problem("examples/robot_corridor.toml"))
    >>> q = stospline.fixed_point_table(d, "q15")
    >>> q.name, q.arith, q.K.shape
    ('robot_corridor_q15', 'q15', (6000, 2, 4))
    """
    if d.table.delay_ticks:
        raise DesignError("design.delay_ticks", f"a design for a one-tick delay has float32 "
                                                f"tables only, not {arith}")
    if x_range is None:
        x_range = state_range(d.problem, d.table, sigmas=sigmas)
    from stospline.table.qformat import quantize_table   # fixed point only
    return quantize_table(double_table(d), arith, x_range)


def fixed_point_estimator(d: Designed, arith: str, *, sigmas: float = DEFAULT_SIGMAS
                          ) -> tuple[FixedPointTable, tuple]:
    """The Q15/Q31 law and filter of a problem with [measurement]
    (`stospline.estimator.qformat`): ``(law, (filter, summary))``. The law's state scales
    cover the true state and the estimate of the sensor loop (`estimator_state_range`); the
    summary holds the filter's scales and the written error bounds (max over the plan, rounded
    up to 3 digits) on x̂ and u against the double loop. Raises ValueError as
    `fixed_point_table`, and for a table with no estimator form (a delay, a band latch)."""
    from stospline.estimator.filter_kernel import with_table_filter
    from stospline.estimator.oracle import evaluate_estimator
    from stospline.estimator.qformat import (error_bound, estimator_state_range,
                                             quantize_estimator)
    if d.table.delay_ticks or d.table.band_qp is not None or d.table.spline is not None:
        raise ValueError("the fixed-point estimator takes per-tick tables without a delay or "
                         "a band latch")
    exact = double_table(d)
    # The ranges from the double law's loop, the filter the float32 table's (the same bits on
    # every machine, `with_table_filter`).
    loop = with_table_filter(evaluate_estimator(d.problem, exact, path=True), d.problem,
                             d.table)
    x_range = estimator_state_range(d.problem, exact, loop, sigmas=sigmas)
    ft = fixed_point_table(d, arith, x_range=x_range)
    qt = quantize_estimator(d.problem, ft, loop, sigmas=sigmas)
    summary = {**qt.summary(), "error_bound": "none (actuator limits)"}
    if not ft.limited:
        xb, ub = error_bound(ft, qt)
        summary["error_bound"] = {"xhat": [ceil_significant(b, 3) for b in xb.max(0)],
                                  "u": [ceil_significant(b, 3) for b in ub.max(0)]}
    return ft, (qt, summary)


def fixed_point_spline(d: Designed, arith: str, *, tolerance: float | None = None,
                       sigmas: float = DEFAULT_SIGMAS, x_range=None
                       ) -> tuple[FixedPointTable, dict]:
    """A Q15/Q31 spline table of a design and its certificate (`generated_files` writes it as
    ``<name>_<arith>_spline.{h,c,json}``; the firmware runs it, stsp_qspline_t).

    The gains of the per-tick Q table (`fixed_point_table`, same scales) as uniform cubic
    B-splines with integer coefficients, evaluated in exact integer arithmetic
    (`stospline.table.spline.fixed_point`); the latch maps re-solved for the gains as evaluated; the
    error bound computed from them. ``tolerance``: the fit's relative budget per entry
    (default: the design's spline tolerance, else the problem's, else 1e-5).

    Returns ``(table, certificate)``: a `FixedPointTable` whose ``spline`` is the
    `QSplineGains` and whose K, k0, L its evaluation at every tick, bit for bit; the
    certificate as `stospline.refine.spline_certificate.q_certificate`.

    Raises DesignError naming ``design.table`` for what has no spline table (as for float32)
    or ``design.spline_tolerance`` when a stage cannot meet the tolerance."""
    from stospline.design.varying import mean_maps
    from stospline.refine.spline_certificate import q_certificate
    from stospline.table.spline import spline_table
    from stospline.table.spline.fixed_point import dequantized
    from stospline.table.qformat import quantize_table
    if d.table.delay_ticks:
        raise DesignError("design.delay_ticks", f"a design for a one-tick delay has float32 "
                                                f"tables only, not {arith}")
    if has_bands(d.problem) or d.every_tick is not None:
        raise DesignError("design.table", f"a {arith} spline table does not carry the band "
                                          f"dual nor restores the constraints of a table that "
                                          f"latches the state: use float32 or table "
                                          f'"per-tick"')
    if tolerance is None:
        tolerance = (d.certificate["spline_tolerance"] if d.certificate is not None else
                     _options_of(d).spline_tolerance)
    tolerance = check_spline_tolerance(tolerance, "spline_tolerance")
    exact = double_table(d)
    if x_range is None:
        x_range = state_range(d.problem, d.table, sigmas=sigmas)
    per_tick = quantize_table(exact, arith, x_range)
    try:
        ft = spline_table(d.problem, exact, tolerance, arith=arith, x_range=x_range,
                          varying_maps=mean_maps)
    except DesignError:
        raise
    except ValueError as exc:            # scale exponents beyond STSP_Q_EXP_MAX
        raise strict.fixed_scale_error(d.problem, arith, exc) from None
    law, implemented, per_tick_moments = _concurrently(
        [lambda: evaluate_table(d.problem, exact, path=False),
         lambda: evaluate_table(d.problem, dequantized(ft), path=False),
         lambda: evaluate_table(d.problem, dequantized(per_tick), path=False)],
        3 * exact.n_ticks)
    cert = q_certificate(d.problem, ft, per_tick, d.design.J0, law, implemented,
                         per_tick_moments, tolerance=tolerance)
    return ft, rounded(cert)


def _options_of(d: Designed) -> DesignOptions:
    """The options `d` was designed with; the problem file's for a `Designed` made without."""
    return d.options if d.options is not None else resolve_options(d.problem)


def generated_files(d: Designed, source_name: str, arith: str = "float32", *,
                    with_c: bool = True) -> dict[str, str]:
    """``<name>.{h,c,json}`` for float32; ``<name>_<arith>.{h,c,json}`` for Q15/Q31, whose
    summary adds the scales and the error bound (the JSON key ``fixed``); ``_spline`` after
    the stem for a spline table (`stospline.output_names`). ``with_c=False``: only the
    ``.json`` (formatting the C text is most of the time of a small design).

    Raises ProblemError, before any text exists, if the table exceeds the firmware's limits or
    holds a number that overflows its format, or the summary a non-finite number."""
    return design_files(d, source_name, arith, with_c=with_c)[0]


def design_files(d: Designed, source_name: str, arith: str = "float32", *,
                 with_c: bool = True, fixed=None, fixed_terms: dict | None = None,
                 table_terms: dict | None = None) -> tuple[dict[str, str], dict]:
    """``(files, summary)``: the files of `generated_files` and the JSON summary they hold,
    as a dict (what the text summary is printed from). `fixed`, optional: the Q15/Q31
    table to write instead of `fixed_point_table` of the design (a table with runtime
    parameters: the gain table quantized with its columns,
    `stospline.oracle.parametric.fixed_parametric`, or the Q spline gain table of a per-tick
    design `d`, `fixed_spline_parametric`, written as ``<name>_<arith>_spline``);
    `fixed_terms`, more entries of its summary (what it guarantees over the parameter box). `table_terms`, more entries of a
    float32 spline table's certificate (the JSON key ``table``: what its spline columns
    guarantee over the box, `spline_parametric_files`)."""
    check_implementable(d)
    summary = design_summary(d)
    if table_terms:
        summary["table"] = {**summary["table"], **rounded(table_terms)}
    q_est = None
    if arith == "float32":
        table = d.table
    elif d.table.spline is not None and fixed is None:
        # The Q15/Q31 spline table (`fixed_point_spline`): its scales and error bound, and its
        # own certificate in place of the float32 spline's.
        table, q_cert = fixed_point_spline(d, arith)
        limits.check_table(table)
        summary["fixed"] = rounded({**table.summary(), "state_sigmas": DEFAULT_SIGMAS})
        summary["table"] = q_cert
    else:
        try:
            if fixed is not None:
                table = fixed
            elif d.problem.measurement is not None:     # the Q law and filter on the estimate
                table, q_est = fixed_point_estimator(d, arith)
            else:
                table = fixed_point_table(d, arith)
        except ValueError as exc:            # scale exponents beyond STSP_Q_EXP_MAX
            raise strict.fixed_scale_error(d.problem, arith, exc) from None
        limits.check_table(table)
        summary["fixed"] = rounded({**table.summary(), "state_sigmas": DEFAULT_SIGMAS,
                                    **(fixed_terms or {})})
        if q_est is not None:
            summary["fixed"]["estimator"] = rounded(q_est[1])
    strict.check_summary_finite(d.problem, summary)
    spline = d.table.spline is not None or getattr(fixed, "spline", None) is not None
    n = table_stem(d.problem.name, arith, spline)
    text = strict.dumps(summary) + "\n"
    if not with_c:
        return {f"{n}.json": text}, summary
    header, source = generate_c(table, source_name=source_name)
    if arith == "float32" and d.problem.measurement is not None:   # the filter's tables
        from stospline.estimator.ctable import with_estimator
        header, source = with_estimator(
            header, source, d.problem, table, spline_tolerance=(
                _options_of(d).spline_tolerance if table.spline is not None else None))
    elif q_est is not None:
        from stospline.estimator.qformat import estimator_q_c
        eh, ec = estimator_q_c(q_est[0], table.name)
        body, guard = header.rsplit("#endif", 1)
        header, source = body + eh.lstrip("\n") + "\n#endif" + guard, source + ec
    return {f"{n}.h": header, f"{n}.c": source, f"{n}.json": text}, summary


def spline_parametric_files(d: Designed, source_name: str = "") -> tuple[dict[str, str], object]:
    """``(files, sp)``: ``<name>_spline_params.{h,c}``, the spline columns of a design with
    runtime parameters and a float32 spline table (`design_problem` with ``table="spline"``),
    fitted on that table's knots (`stospline.refine.spline_params.spline_parametric_of`, the
    parametric design with `d`'s options), beside the ``<name>_spline.{h,c}`` that
    `design_files` writes of it; and the `SplineParametric`, what the oracle certifies
    (``certify_over_box``). ``stospline design --table spline`` and
    ``tools/params_tables.py --spline`` write them with this.

    Raises DesignError naming the option (`check_parametric_options`) or ``design.table``
    (a spline table with a band dual)."""
    from stospline.oracle.parametric import check_parametric_options
    from stospline.refine.spline_params import spline_parametric_c, spline_parametric_of
    opts = check_parametric_options(d.problem, _options_of(d))
    if d.table.spline is None or not d.problem.parameters:
        raise DesignError("design.table", "spline columns need a design with [[parameters]] "
                                          "and a float32 spline table")
    sp = spline_parametric_of(d.problem, opts, stable=d.table,
                              ptable=d.over_box.table if d.over_box is not None else None)
    stem = table_stem(d.problem.name, "float32", True)
    return spline_parametric_c(sp, stem, source_name), sp


def check_implementable(d: Designed) -> None:
    """Raise ProblemError unless the firmware accepts `d.table`: dimensions within its limits
    (`limits.check_table`) and every entry finite (`strict.check_table_finite`)."""
    limits.check_table(d.table)
    strict.check_table_finite(d.problem, d.table, exact=lambda: double_table(d))


def simulate_problem(d: Designed, *, paths: int, seed: int,
                     substeps: int | str | SubstepChoice = "auto", workers: int | None = None,
                     record: int = 0, scheduler: str | None = None,
                     build_dir=None, faults: Faults | None = None, force_workers: bool = False,
                     max_memory: float | None = budget.DEFAULT_MAX_GIB,
                     max_time: float | None = budget.DEFAULT_MAX_SECONDS,
                     per_path: bool = False) -> MonteCarloResult:
    """Monte Carlo of the compiled C controller built from `d.table` in closed loop with the
    stochastic plant (exponential Euler-Maruyama with `substeps` steps per tick).

    Parameters
    ----------
    d : Designed
    paths : int
        Number of sample paths (at least 1).
    seed : int
        Seed of the plant's noise: the same seed gives the same result.
    substeps : int, "auto" or SubstepChoice
        Plant steps per controller tick. "auto" (default): the fewest (a power of two) whose
        exact bias in the expected cost is at most 0.1 Monte Carlo standard errors of this
        run (`harness.plant_scheme.choose_substeps`, or `plan_substeps` beforehand); the choice is
        in the result's ``substep_choice``.
    workers : int, optional
        Processes that run the blocks of paths (default: every core; the numbers are the same
        for any count, `harness.montecarlo.simulate`); at most the cores this process may use
        unless `force_workers`.
    record : int
        Keep the states of this many paths at every tick (``record_x``; for reports).
    scheduler : str, optional
        A Dask scheduler's address, or "local" for a local Dask cluster of `workers`
        processes, to run the blocks on (same numbers).
    build_dir : str or Path, optional
        Where the compiled module is cached (default: the user cache directory).
    faults : Faults, optional
        The loop's faults (default: the problem file's ``[faults]``; `problem.faults`).
    force_workers : bool
        Start `workers` processes even beyond the cores this process may use.
    max_memory, max_time : float or None
        Refuse (BudgetError, naming the argument that costs most, e.g. ``paths``) a run
        estimated to need more than `max_memory` GiB or `max_time` seconds, before any work:
        compiling the controller, the paths and their worker processes, the oracle of the
        plant scheme and the corridors' exit bounds of `simulation_summary`
        (`stospline.budget.monte_carlo_terms`). Defaults as on the command line (4 GiB,
        600 s); None: no check.
    per_path : bool
        Also keep every path's cost, knot states, saturated ticks and corridor exits
        (`harness.montecarlo.simulate`; refused beyond ``PER_PATH_MAX_BYTES``).

    Returns
    -------
    MonteCarloResult
        The run's statistics (``cost_mean_ci()``, ``knot_mean_se(k)``, saturation and exit
        counts; streamed, so memory does not grow with `paths`), the plant steps per tick
        (``substeps``, ``substep_choice``).

    Raises
    ------
    ProblemError
        The firmware would refuse the table (`check_implementable`).
    BudgetError
        The estimate exceeds `max_memory` or `max_time`.

    Examples
    --------
    >>> import stospline
    >>> d = stospline.design_problem(stospline.load_problem("examples/robot_corridor.toml"))
    >>> mc = stospline.simulate_problem(d, paths=200, seed=1)
    >>> mc.substeps                  # the fewest whose plant bias is < 0.1 standard error
    1
    >>> s = stospline.simulation_summary(d, mc, seed=1)
    >>> s["verdict"]["agree"]        # cost and knot means against the oracle, 99 % jointly
    True
    """
    from stospline.harness.montecarlo import check_counts
    from stospline.harness.plant_scheme import SubstepChoice
    check_implementable(d)
    check_counts(paths=paths, **({} if isinstance(substeps, (str, SubstepChoice))
                                 else {"substeps": substeps}))
    workers = usable_workers(workers, force_workers)
    choice = substeps if isinstance(substeps, SubstepChoice) else None

    def within_budget(steps: int) -> None:
        _within_budget(max_memory, max_time, lambda: simulation_estimate(
            d, paths=paths, substeps=steps, workers=workers, record=record), d.problem,
            paths=paths, workers=workers)
    # "auto" chooses after a pilot run: checked at one step per tick, then at the choice.
    within_budget(1 if substeps == "auto"
                  else choice.substeps if choice is not None else substeps)
    from stospline.harness.controller import build_controller
    from stospline.harness.montecarlo import simulate
    from stospline.harness.plant_scheme import choose_substeps
    from stospline.report.simulation_summary import loop_moments
    ctl = build_controller(d.table, build_dir=build_dir, plant=d.problem)
    faults = d.problem.faults if faults is None else faults
    if substeps == "auto":
        choice = choose_substeps(d.problem, ctl, loop_moments(d, faults).J, paths=paths,
                                 seed=seed, faults=faults)
        if choice.substeps > 1:
            within_budget(choice.substeps)
    steps = choice.substeps if choice is not None else substeps
    mc = simulate(d.problem, ctl, paths=paths, seed=seed, substeps=steps, workers=workers,
                  record=record, scheduler=scheduler, faults=faults, force_workers=True,
                  per_path=per_path, alongside=lambda: _summary_ahead(d, steps, faults))
    mc.substep_choice = choice
    return mc


def _summary_ahead(d: Designed, substeps: int, faults):
    """What `simulation_summary` needs besides the run, done while the paths run: the
    quantile functions' module loaded, the corridors' output moments for their exit bounds
    (one oracle pass, kept by `harness.exit_stats.corridor_outputs_of`; a table designed for
    a delay has none), and the loop's moments up to the fourth for the verdict's exact
    standard errors (`oracle.tails`; returned, None where there is no such oracle)."""
    from stospline.harness.exit_stats import clopper_pearson_upper, corridor_outputs_of
    from stospline.oracle.tails import evaluate_tails, tails_unsupported
    clopper_pearson_upper(0, 1)            # imports scipy.special (~0.3 s of CPU)
    if d.problem.corridors and not getattr(d.table, "delay_ticks", 0):
        corridor_outputs_of(d.problem, d.table)
    if faults.any or tails_unsupported(d.problem, d.table) is not None:
        return None
    # Checked against the second-moment oracle by `simulation_summary`, which has it.
    return evaluate_tails(d.problem, d.table, substeps=substeps, check=False)


def simulation_estimate(d: Designed, *, paths: int, substeps: int, workers: int = 1,
                        record: int = 0) -> budget.Estimate:
    """What `simulate_problem` and `simulation_summary` of `d` will take: the controller's C
    text compiled, and the Monte Carlo terms (`budget.monte_carlo_terms`)."""
    t = d.table
    numbers = table_numbers(d)
    est = budget.Estimate("simulation")
    est.terms.append(budget.Term("start-up (imports, compiled kernels)", "--max-time",
                                 seconds=budget.BASE_SECONDS))
    est.terms.append(budget.Term("C text of the tables, compiled", "tick_hz",
                                 seconds=(budget.CODEGEN_NUMBER + budget.COMPILE_NUMBER)
                                 * numbers, bytes=budget.CODEGEN_BYTES * numbers))
    est.terms.append(budget.Term("the C compiler on the tables", "tick_hz",
                                 bytes=budget.COMPILE_BYTES * numbers, transient=True))
    est.terms += budget.monte_carlo_terms(d.problem, paths=paths, substeps=substeps,
                                          workers=workers, record=record,
                                          n_latch=t.dims[2],
                                          delay_ticks=int(getattr(t, "delay_ticks", 0)))
    return est


def fault_sweep(d: Designed, *, paths: int, seed: int, substeps: int,
                workers: int | None = None, scheduler: str | None = None, build_dir=None):
    """The fault table of the design (`harness.fault_sweep.fault_table`): each fault of the loop
    at a few levels relative to the plan, the fault oracle beside Monte Carlo through the
    compiled C controller (`paths` paths per level, the same `seed`)."""
    from stospline.harness.controller import build_controller
    from stospline.harness.fault_sweep import fault_table
    check_implementable(d)
    ctl = build_controller(d.table, build_dir=build_dir)
    return fault_table(d.problem, ctl, paths=paths, seed=seed, substeps=substeps,
                       workers=workers, scheduler=scheduler)


def plan_substeps(d: Designed, *, paths: int, seed: int, build_dir=None,
                  faults: Faults | None = None, scheme: str = "euler") -> SubstepChoice:
    """The plant steps per tick ``simulate_problem(..., substeps="auto")`` would choose for
    this run (`harness.plant_scheme.choose_substeps`); pass the result as its `substeps` to run
    with it, e.g. after checking that run's cost. `scheme` "weak2": the steps per tick of the
    weak-order-two scheme (`harness.weak_scheme`; run it on its ``scheme_problem``)."""
    from stospline.report.simulation_summary import loop_moments
    from stospline.harness.controller import build_controller
    from stospline.harness.plant_scheme import choose_substeps
    check_implementable(d)
    ctl = build_controller(d.table, build_dir=build_dir, plant=d.problem)
    faults = d.problem.faults if faults is None else faults
    return choose_substeps(d.problem, ctl, loop_moments(d, faults).J, paths=paths, seed=seed,
                           faults=faults, scheme=scheme)


def usable_workers(workers: int | None, force: bool = False) -> int:
    """The worker processes a run starts: `workers` (default: every core), at most the cores
    this process may use unless `force` (`harness.montecarlo.usable_workers`)."""
    from stospline.harness.montecarlo import usable_workers as usable
    return usable(workers, force)


def check_faults_runnable(problem: Problem, options: DesignOptions, *,
                          field: str = "faults") -> None:
    """Refuse, before the design, faults the harness cannot run around this problem's table
    (`harness.montecarlo.faults_unsupported`: what the table will be is known from the options);
    `field` names where the faults came from."""
    if not problem.faults.any:
        return
    from types import SimpleNamespace
    from stospline.harness.montecarlo import faults_unsupported
    table = SimpleNamespace(arith="float32", delay_ticks=options.delay_ticks)
    if options.delay_ticks and problem.faults.delay_ticks:
        raise ProblemError("faults.delay_ticks", "the table is designed for a one-tick delay "
                                                 "and runs with it; a delay fault on top of it "
                                                 "is not simulated")
    why = faults_unsupported(problem, table)
    if why:
        raise ProblemError(field, f"cannot be simulated here: {why}")


def fault_table_unavailable(d: Designed) -> str | None:
    """Why the harness cannot run the fault table around `d`'s table (None: it can)."""
    from stospline.harness.montecarlo import faults_unsupported
    return faults_unsupported(d.problem, d.table)


def fault_sweep_runs() -> int:
    """The Monte Carlo runs of `fault_sweep` (each fault at a few levels), each of its
    `paths`."""
    from stospline.harness.fault_sweep import SWEEP_ROWS
    return SWEEP_ROWS


def table_numbers(d: Designed) -> int:
    """The numbers the C text of `d`'s table holds (what formatting and compiling it cost)."""
    t = d.table
    return (t.K.size + t.k0.size + t.L.size if t.spline is None
            else t.spline.coef.size + t.spline.knot.size)
