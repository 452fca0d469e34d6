"""The library calls behind the CLI: design a problem, evaluate it, simulate it, summarise.

Everything the CLI does is one call here, so scripts and tests use the same path.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from stospline.table.codegen import GENERATOR, generate_c
from stospline.design.bands import design_bands, has_bands
from stospline.design.continuous import DesignError, design_continuous
from stospline.design.varying import mean_maps
from stospline.design.zoh import check_delay, design_zoh
from stospline.harness.controller import build_controller
from stospline.harness.montecarlo import (MonteCarloResult, check_counts, joint_verdict, simulate,
                                      usable_workers, z_value)
from stospline.oracle.evaluate import Moments, evaluate_continuous, evaluate_table, state_range
from stospline.harness.plant_scheme import SubstepChoice, choose_substeps, scheme_moments
from stospline.oracle.faults import evaluate_with_faults, has_exact_oracle
from stospline.refine.spline_certificate import certificate
from stospline.table.spline import spline_table
from stospline.table.spline.restore import is_state_latching
from stospline.refine.every_tick import EveryTick, design_every_tick, every_tick_check
from stospline.problem.faults import Faults
from stospline.problem.model import Problem, ProblemError
from stospline.table.format import GainTable, TickGains, table_of
from stospline.table.qformat import DEFAULT_SIGMAS, FixedPointTable, quantize_table
from stospline import budget, limits, progress, strict
from stospline.precision import RoundedUp, Verbatim, verbatim
from stospline.table_options import (DEFAULT_SPLINE_TOLERANCE, TABLE_KINDS,
                                     check_spline_tolerance)

__all__ = ["Designed", "design_problem", "design_summary", "simulate_problem",
           "simulation_summary", "verdict", "plan_substeps", "write_outputs", "start_from",
           "double_table", "fixed_point_table", "fixed_point_spline", "check_implementable",
           "loop_moments", "fault_sweep", "simulation_estimate"]

# JSON summaries keep 10 significant digits and an absolute quantum of 1e-10: the designs
# agree to ~1e-14 however the arithmetic is ordered, so regenerated files stay byte-identical
# (a residual of 1e-15, or a zero computed as 2e-18, prints as 0).
_SIG, _ABS = 10, 10


def _r(x):
    """Round floats (recursively) for stable, readable JSON (see _SIG, _ABS)."""
    if isinstance(x, dict):
        return {k: _r(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_r(v) for v in x]
    if isinstance(x, np.ndarray):
        return _r(x.tolist())
    if isinstance(x, (RoundedUp, Verbatim)):  # a bound at its own precision, rounded up:
        return float(x)  # rounding it to nearest could lower it; an input: echoed as given
    if isinstance(x, (float, np.floating)):
        v = float(f"{round(float(x), _ABS):.{_SIG}g}")
        return 0.0 if v == 0 else v
    if isinstance(x, np.integer):
        return int(x)
    return x


DISCRETIZATIONS = ("exact-zoh", "continuous")


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
                   max_time: float | None = budget.DEFAULT_MAX_SECONDS) -> Designed:
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
        a]``, ``a`` the command being applied (docs/guide/firmware.md, "A one-tick delay").
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
    limits.check_mode(problem, mode)   # before the work: the firmware's STSP_MAX_LATCH
    if delay_ticks is None:
        delay_ticks = problem.options.get("delay_ticks", 0)
    delay_ticks = check_delay(problem, delay_ticks, discretization)
    table = table or problem.options.get("table", "per-tick")
    if table not in TABLE_KINDS:
        raise ValueError(f"table must be one of {TABLE_KINDS}, got {table!r}")
    if spline_tolerance is None:
        spline_tolerance = problem.options.get("spline_tolerance", DEFAULT_SPLINE_TOLERANCE)
    spline_tolerance = check_spline_tolerance(spline_tolerance, "spline_tolerance")
    _within_budget(max_memory, max_time, lambda: budget.estimate(
        problem, command="design", mode=mode, discretization=discretization,
        delay_ticks=delay_ticks, table=table, spline_tolerance=spline_tolerance), problem)
    try:
        return _design_problem(problem, noise=noise, discretization=discretization, mode=mode,
                               delay_ticks=delay_ticks,
                               spline_tolerance=spline_tolerance if table == "spline" else None)
    except FloatingPointError:
        # Products of extreme data (B = 1e308, C'C of 1e300) overflowed to Inf or NaN.
        raise DesignError(*strict.overflow_failure(problem)) from None


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


def _design_problem(problem: Problem, *, noise: bool, discretization: str,
                    mode: str, delay_ticks: int = 0,
                    spline_tolerance: float | None = None) -> Designed:
    every_tick = None
    if problem.tick_regions:
        first = f"regions[{problem.tick_regions[0].index}].every"
        if mode != "joint":
            raise DesignError(first, 'a region at every tick is a band: use mode joint '
                                     '(--mode joint)')
        if discretization != "exact-zoh":
            raise DesignError(first, 'a region at every tick is met for the law held over '
                                     'each tick: use --discretization exact-zoh')
        every_tick = design_every_tick(problem, noise=noise)
        # From here on the problem is the one the tables are for: the file's knots plus the
        # working set's band knots (its tick regions kept, so it says what it was made for).
        problem = every_tick.problem
        design = continuous_law = every_tick.design
    elif has_bands(problem):
        if mode != "joint":
            raise DesignError("knots", "band constraints (lower/upper) are exact only with one "
                                       "multiplier vector for all knots: use mode joint "
                                       "(--mode joint)")
        if discretization not in DISCRETIZATIONS:
            raise ValueError(f"discretization must be one of {DISCRETIZATIONS}")
        design = design_bands(problem, discretization=discretization, noise=noise)
        continuous_law = design.base
    elif discretization == "exact-zoh":
        design = continuous_law = design_zoh(problem, noise=noise, mode=mode,
                                             delay_ticks=delay_ticks)
    elif discretization == "continuous":
        design = continuous_law = design_continuous(problem, noise=noise, mode=mode)
    else:
        raise ValueError(f"discretization must be one of {DISCRETIZATIONS}")
    table = table_of(design)
    # A float32 entry that overflowed would make the oracle's moments non-finite: refuse it
    # here, naming the cause, before evaluating the table as implemented.
    strict.check_table_finite(problem, table, exact=lambda: table_of(design, quantize=False))
    # The design's own law in double precision: the oracle's reference (zero-order hold) and
    # what a spline is fitted to; a continuous design without a spline needs neither.
    exact = (table_of(design, quantize=False)
             if discretization != "continuous" or spline_tolerance is not None else None)
    per_tick = table
    if spline_tolerance is not None:
        if every_tick is not None and not is_state_latching(per_tick):
            # Constraint generation's band dual re-plans its working set only; the other
            # ticks' slack is not restored for the spline's gains (the tick-grid QP's tables
            # latch the state and are: `spline_restore`).
            raise DesignError("design.table", "a region at every tick met by a band dual (at "
                                              "most 8 rows) has no spline table: its other "
                                              "ticks are not restored; use table \"per-tick\"")
        table = spline_table(problem, exact, spline_tolerance, per_tick=per_tick,
                             varying_maps=mean_maps)
    def evaluate_exact():
        return evaluate_table(problem, exact, path=False)
    # A spline's certificate checks every row of a region at every tick: the mean path.
    path = spline_tolerance is not None and bool(problem.tick_regions)
    evaluations = [evaluate_exact, lambda: evaluate_table(problem, table, path=path)]
    if discretization == "continuous":
        # The law is the continuous-time one; a spline's certificate is still measured
        # against the sampled table it compresses (the law the firmware would otherwise run).
        evaluations[0] = lambda: evaluate_continuous(problem, continuous_law)
        if spline_tolerance is not None:
            evaluations.append(evaluate_exact)
    law, implemented, *compressed = _concurrently(evaluations, 2 * table.n_ticks)
    d = Designed(problem, design, discretization, table, law, implemented,
                 every_tick=every_tick)
    if spline_tolerance is not None:
        d.certificate = certificate(d.problem, table, per_tick, d.design.J0,
                                    compressed[0] if compressed else law, implemented,
                                    tolerance=spline_tolerance)
    return d


def _concurrently(evaluations, ticks: int) -> list:
    """Run independent oracle evaluations two at a time (their loops are C or numpy, which
    release the GIL), under one progress bar of `ticks`; results in order, each exactly
    what it would be alone."""
    from concurrent.futures import ThreadPoolExecutor
    with progress.shared("oracle", ticks), ThreadPoolExecutor(max_workers=2) as pool:
        futures = [pool.submit(evaluate) for evaluate in evaluations]
        return [f.result() for f in futures]


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


def predicted_cost(d: Designed) -> float:
    """The designer's optimal expected cost from ``d.problem.x0`` (which `start_from` may have
    moved away from the design's own start)."""
    return d.design.cost_from(d.problem.x0)


def _violation(y: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Signed distance outside [lo, hi] per row (0 inside; for an equality, y - value)."""
    return np.where(lo == hi, y - lo, np.maximum(y - hi, 0) - np.maximum(lo - y, 0))


def _limits(d: Designed) -> dict:
    """``{"actuator_limits": {"u_min": [...] | None, "u_max": ...}}`` as the table stores them
    (float32), when the problem sets limits; ``{}`` otherwise (summaries stay unchanged)."""
    p = d.problem
    if p.u_min is None and p.u_max is None and p.u_hold is None:
        return {}
    return {"actuator_limits": {
        "u_min": None if p.u_min is None else d.table.u_min.astype(float),
        "u_max": None if p.u_max is None else d.table.u_max.astype(float),
        **({} if p.u_hold is None else {"u_hold": d.table.u_hold.astype(float)}),
        "note": "the design ignores the limits: the firmware clips the unconstrained law, "
                "and the oracle's numbers assume no command is clipped",
    }}


def _cov_digits(cov: np.ndarray, mean: np.ndarray) -> np.ndarray:
    """A knot covariance for the summary. The oracle computes it as ``E xx' - mean mean'``, so
    it keeps only the digits of ``E xx'``: rounded to `_SIG` significant digits of
    ``max(|cov|, |mean|^2)`` (a wealth of 100 with a variance of 12 loses three digits, and
    the last bits of the design would otherwise show)."""
    cov, mean = np.asarray(cov, dtype=float), np.asarray(mean, dtype=float)
    scale = max(float(np.abs(cov).max(initial=0.0)), float(np.max(mean ** 2, initial=0.0)))
    if not np.isfinite(scale) or scale == 0.0:
        return cov
    # The decade rounded to nearest, not down: means at constrained knots are round numbers
    # (a mean of 100 gives a scale of exactly 1e4), and the digits kept must not flip there.
    return np.round(cov, _SIG - 1 - int(np.floor(np.log10(scale) + 0.5)))


def design_summary(d: Designed) -> dict:
    """Machine-readable summary: predicted J0 and per-knot predicted moments (and the
    actuator limits, when the problem sets them)."""
    p = d.problem
    knots = []
    for k, kn in enumerate(p.knots):
        entry = {
            "t": verbatim(kn.t),
            "mean": d.law.knot_mean[k],
            "cov": _cov_digits(d.law.knot_cov[k], d.law.knot_mean[k]),
            "implemented_mean": d.implemented.knot_mean[k],
            "implemented_cov": _cov_digits(d.implemented.knot_cov[k], d.implemented.knot_mean[k]),
        }
        if kn.constraint is not None:
            lo, hi = kn.constraint.bounds
            entry["constraint"] = {
                "lower": lo, "upper": hi,
                "design_violation": _violation(d.law.knot_constraint[k], lo, hi),
                "implemented_violation": _violation(d.implemented.knot_constraint[k], lo, hi),
            }
        knots.append(entry)
    return _r({
        "name": p.name,
        "generator": GENERATOR,
        "problem_sha256": p.source_sha256,
        "design": f"{d.design.mode}-{d.discretization}"
                  + ("" if d.design.noise_aware else "-noise-ignoring"),
        "tick_hz": d.table.tick_hz,
        "n_ticks": d.table.n_ticks,
        "J0": d.design.J0,
        "oracle_J_design": d.law.J,
        "oracle_J_implemented": d.implemented.J,
        "knots": knots,
        **({"table": d.certificate} if d.certificate is not None else {}),
        **_band_terms(d),
        **_limits(d),
        **_estimator(d),
    })


def _estimator(d: Designed) -> dict:
    """With a [measurement] table: the loop on the filter's estimate (docs/theory/estimator.md);
    ``{}`` otherwise (summaries stay unchanged)."""
    if d.problem.measurement is None:
        return {}
    from stospline.estimator.summary import estimator_summary
    return {"estimator": estimator_summary(d.problem, d.table, _cov_digits)}


def _band_terms(d: Designed) -> dict:
    """The design's own summary entries; with bands also the rows of the dual the firmware
    re-solves from the measured x0 (0: it latches the affine map of the design's active set,
    see docs/theory/math-notes.md)."""
    terms = d.design.summary_terms()
    if has_bands(d.problem):
        terms["band_qp_rows"] = 0 if d.table.band_qp is None else d.table.band_qp.q
    if d.every_tick is not None:
        terms["every_tick"] = every_tick_check(d)
    return terms


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
    return quantize_table(double_table(d), arith, x_range)


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
    from stospline.refine.spline_certificate import q_certificate
    from stospline.table.spline.fixed_point import dequantized
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
                     d.problem.options.get("spline_tolerance", DEFAULT_SPLINE_TOLERANCE))
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
    return ft, _r(cert)


def generated_files(d: Designed, source_name: str, arith: str = "float32", *,
                    with_c: bool = True) -> dict[str, str]:
    """``<name>.{h,c,json}`` for float32; ``<name>_<arith>.{h,c,json}`` for Q15/Q31, whose
    summary adds the scales and the error bound (``fixed``). ``with_c=False``: only the
    ``.json`` (formatting the C text is most of the time of a small design).

    Raises ProblemError, before any text exists, if the table exceeds the firmware's limits or
    holds a number that overflows its format, or the summary a non-finite number."""
    check_implementable(d)
    summary = design_summary(d)
    if arith == "float32":
        table, n = d.table, d.table.name
    elif d.table.spline is not None:
        # The Q15/Q31 spline table (`fixed_point_spline`): its scales and error bound, and its
        # own certificate in place of the float32 spline's.
        table, q_cert = fixed_point_spline(d, arith)
        limits.check_table(table)
        n = table.name
        summary["fixed"] = _r({**table.summary(), "state_sigmas": DEFAULT_SIGMAS})
        summary["table"] = q_cert
    else:
        try:
            table = fixed_point_table(d, arith)
        except ValueError as exc:            # scale exponents beyond STSP_Q_EXP_MAX
            raise strict.fixed_scale_error(d.problem, arith, exc) from None
        limits.check_table(table)
        n = table.name
        summary["fixed"] = _r({**table.summary(), "state_sigmas": DEFAULT_SIGMAS})
    strict.check_summary_finite(d.problem, summary)
    text = strict.dumps(summary) + "\n"
    if not with_c:
        return {f"{n}.json": text}
    header, source = generate_c(table, source_name=source_name)
    if arith == "float32":               # the filter's tables, with a [measurement] table
        from stospline.estimator.ctable import with_estimator
        header, source = with_estimator(header, source, d.problem, table)
    return {f"{n}.h": header, f"{n}.c": source, f"{n}.json": text}


def check_implementable(d: Designed) -> None:
    """Raise ProblemError unless the firmware accepts `d.table`: dimensions within its limits
    (`limits.check_table`) and every entry finite (`strict.check_table_finite`)."""
    limits.check_table(d.table)
    strict.check_table_finite(d.problem, d.table, exact=lambda: double_table(d))


def loop_moments(d: Designed, faults: Faults | None = None) -> Moments:
    """The exact moments the Monte Carlo run is compared with: the implemented law's
    (`Designed.implemented`) without faults, the fault oracle's (`oracle.faults`) in a loop
    with linear `faults` (default ``d.problem.faults``). Nonlinear faults (quantization, missed
    ticks) have none: the fault-free loop's moments are returned, and the verdict says the run
    is not comparable."""
    faults = d.problem.faults if faults is None else faults
    if not faults.any or not has_exact_oracle(d.table, faults):
        return d.implemented
    return evaluate_with_faults(d.problem, d.table, faults)


def simulate_problem(d: Designed, *, paths: int, seed: int,
                     substeps: int | str | SubstepChoice = "auto", workers: int | None = None,
                     record: int = 0, scheduler: str | None = None,
                     build_dir=None, faults: Faults | None = None, force_workers: bool = False,
                     max_memory: float | None = budget.DEFAULT_MAX_GIB,
                     max_time: float | None = budget.DEFAULT_MAX_SECONDS) -> MonteCarloResult:
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
        600 s); None: no check. Monte Carlo memory grows with `paths`.

    Returns
    -------
    MonteCarloResult
        Per-path costs (``cost``, ``cost_mean_ci()``), knot states, saturation counts, the
        plant steps per tick (``substeps``, ``substep_choice``).

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
    ctl = build_controller(d.table, build_dir=build_dir)
    faults = d.problem.faults if faults is None else faults
    if substeps == "auto":
        choice = choose_substeps(d.problem, ctl, loop_moments(d, faults).J, paths=paths,
                                 seed=seed, faults=faults)
        if choice.substeps > 1:
            within_budget(choice.substeps)
    mc = simulate(d.problem, ctl, paths=paths, seed=seed,
                  substeps=choice.substeps if choice is not None else substeps, workers=workers,
                  record=record, scheduler=scheduler, faults=faults, force_workers=True)
    mc.substep_choice = choice
    return mc


def simulation_estimate(d: Designed, *, paths: int, substeps: int, workers: int = 1,
                        record: int = 0) -> budget.Estimate:
    """What `simulate_problem` and `simulation_summary` of `d` will take: the controller's C
    text compiled, and the Monte Carlo terms (`budget.monte_carlo_terms`)."""
    t = d.table
    numbers = (t.K.size + t.k0.size + t.L.size if t.spline is None
               else t.spline.coef.size + t.spline.knot.size)
    est = budget.Estimate("simulation")
    est.terms.append(budget.Term("start-up (imports, compiled kernels)", "--max-time",
                                 seconds=budget.BASE_SECONDS))
    est.terms.append(budget.Term("C text of the tables, compiled", "tick_hz",
                                 seconds=(budget.CODEGEN_NUMBER + budget.COMPILE_NUMBER)
                                 * numbers,
                                 bytes=(budget.CODEGEN_BYTES + budget.COMPILE_BYTES) * numbers))
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
    from stospline.harness.fault_sweep import fault_table
    check_implementable(d)
    ctl = build_controller(d.table, build_dir=build_dir)
    return fault_table(d.problem, ctl, paths=paths, seed=seed, substeps=substeps,
                       workers=workers, scheduler=scheduler)


def plan_substeps(d: Designed, *, paths: int, seed: int, build_dir=None,
                  faults: Faults | None = None) -> SubstepChoice:
    """The plant steps per tick ``simulate_problem(..., substeps="auto")`` would choose for
    this run (`harness.plant_scheme.choose_substeps`); pass the result as its `substeps` to run
    with it, e.g. after checking that run's cost."""
    check_implementable(d)
    ctl = build_controller(d.table, build_dir=build_dir)
    faults = d.problem.faults if faults is None else faults
    return choose_substeps(d.problem, ctl, loop_moments(d, faults).J, paths=paths, seed=seed,
                           faults=faults)


def simulation_summary(d: Designed, mc: MonteCarloResult, *, seed: int,
                       confidence: float = 0.99) -> dict:
    """Monte Carlo statistics beside the oracle's exact numbers, the plant scheme's bias, and
    the verdict (`verdict`) on whether they agree at the joint `confidence`.

    ``saturation.tick_fraction`` is the fraction of (path, tick) steps on which the C controller
    returned STSP_WARN_SATURATED; when it is nonzero the oracle's numbers (which assume the
    law is never clipped) do not describe the simulated controller.

    A ratio to a Monte Carlo standard error that is 0 (every path alike, as without noise) is
    undefined: it is None (JSON null) and a sibling ``<key>_undefined`` says why. Raises
    ProblemError if some other number is not finite.

    With faults (``mc.faults``) the exact numbers are the fault oracle's (`loop_moments`) and
    ``faults`` says which; faults without an oracle make the verdict "not comparable"."""
    substeps = mc.substeps
    choice = mc.substep_choice
    faults = mc.faults
    exact = loop_moments(d, faults)
    exact_oracle = has_exact_oracle(d.table, faults)
    euler = (choice.scheme if choice is not None and choice.substeps == substeps
             else scheme_moments(d.problem, d.table, substeps, faults))
    mean, hw95 = mc.cost_mean_ci(0.95)
    _, hw99 = mc.cost_mean_ci(0.99)
    se = hw95 / z_value(0.95)
    knots = []
    for k, kn in enumerate(d.problem.knots):
        m, s = mc.knot_mean_se(k)
        alike = np.ptp(mc.knot_states[k], axis=0) == 0   # s is then 0 or rounding error
        z, why = strict.ratio_or_null(m - exact.knot_mean[k], np.where(alike, 0.0, s),
                                      _ZERO_SE)
        knots.append({
            "t": verbatim(kn.t),
            "mc_mean": m, "mc_mean_stderr": s, "mc_cov": mc.knot_cov(k),
            "oracle_mean": exact.knot_mean[k], "oracle_cov": exact.knot_cov[k],
            "z": z, **({"z_undefined": why} if why else {}),
        })
    se_z = 0.0 if np.ptp(mc.cost) == 0 else se
    cost_z, cost_why = strict.ratio_or_null(mean - exact.J, se_z, _ZERO_SE)
    bias_z, bias_why = strict.ratio_or_null(euler.J - exact.J, se_z, _ZERO_SE)
    summary = _r({
        "name": d.problem.name, "paths": mc.paths, "seed": seed, "substeps": substeps,
        "x0": verbatim(d.problem.x0),
        "tick_hz": d.table.tick_hz, "worst_status": mc.worst_status,
        "cost": {
            "mc_mean": mean, "mc_stderr": se,
            "ci95": [mean - hw95, mean + hw95], "ci99": [mean - hw99, mean + hw99],
            "oracle_implemented": exact.J, "predicted_J0": predicted_cost(d),
            "z": cost_z, **({"z_undefined": cost_why} if cost_why else {}),
        },
        "faults": {
            "levels": verbatim(faults.as_dict()), "exact_oracle": exact_oracle,
            "oracle_cost": exact.J if exact_oracle else None,
            "nominal_cost": d.implemented.J,
        },
        "simulation_bias": {
            "cost": euler.J - exact.J,
            "cost_over_stderr": bias_z,
            **({"cost_over_stderr_undefined": bias_why} if bias_why else {}),
            **_substep_choice(mc),
            "knot_cov_max_abs": [float(np.abs(euler.knot_cov[k] - exact.knot_cov[k]).max())
                                 for k in range(len(d.problem.knots))],
        },
        "knots": knots,
        "saturation": {
            "limited": d.table.limited,
            "tick_fraction": mc.saturated_fraction,
            "path_fraction": (float(np.mean(mc.saturated_ticks > 0))
                              if mc.saturated_ticks is not None else 0.0),
            **_command_range(mc),
        },
        **_limits(d),
        **_corridors(d, mc),
    })
    summary["verdict"] = verdict(summary, confidence)
    strict.check_summary_finite(d.problem, summary, "simulated numbers",
                                faults if faults.any else None)
    return summary


def _command_range(mc: MonteCarloResult) -> dict:
    """``u_low``/``u_high``: the least and greatest command issued per input; None (with a
    reason) for an input the controller never commanded (every tick missed: the harness's
    running minimum is still its initial +inf)."""
    low, high = np.asarray(mc.u_low, float), np.asarray(mc.u_high, float)
    issued = np.isfinite(low) & np.isfinite(high)
    out = {"u_low": [float(v) if ok else None for v, ok in zip(low, issued)],
           "u_high": [float(v) if ok else None for v, ok in zip(high, issued)]}
    if not issued.all():
        out["u_range_undefined"] = ("no command was issued on any path (every tick missed, "
                                    "the actuator held u_hold throughout)")
    return out


def _corridors(d: Designed, mc: MonteCarloResult) -> dict:
    """``{"corridors": [...]}`` when the problem has corridors (`harness.exit_stats`): the Monte
    Carlo exit probability with its one-sided 99 % upper bound, and the exact oracle's
    Cantelli (valid) and Gaussian (assumed) union bounds, for the fault-free loop (None for a
    table designed for a delay)."""
    if not d.problem.corridors or mc.exit_tick is None:
        return {}
    from stospline.harness.exit_stats import corridor_report
    # The oracle's output moments exist for tables designed without a delay.
    bounded = not getattr(d.table, "delay_ticks", 0)
    rep = corridor_report(d.problem, d.table, mc.exit_tick, mc.exit_wall,
                          with_bounds=bounded)
    for entry in rep:
        if entry["bound"] is not None:
            entry["bound"]["loop"] = ("fault-free (the bounds ignore [faults])"
                                      if mc.faults.any else "the implemented table")
    return {"corridors": rep}


def _substep_choice(mc: MonteCarloResult) -> dict:
    c = mc.substep_choice
    if c is None:
        return {"substeps_chosen": "given"}
    return {"substeps_chosen": "auto", "target": c.target, "predicted_stderr": c.stderr,
            "pilot_paths": c.pilot_paths, "target_met": c.met}


def verdict(summary: dict, confidence: float = 0.99) -> dict:
    """Whether the Monte Carlo run agrees with the oracle (`harness.montecarlo.joint_verdict`):
    the mean cost and every knot-mean component, each by its z-score in the summary, within
    the two-sided normal bound Bonferroni-corrected so that a correct controller passes all
    of them at once with probability `confidence`. Saturation makes the run incomparable: the
    oracle assumes the law is never clipped."""
    c = summary["cost"]
    stats = [("cost", c["z"], c["mc_mean"], c["oracle_implemented"])]
    for k, kn in enumerate(summary["knots"]):
        stats += [(f"knot {k} mean[{i}]", z, kn["mc_mean"][i], kn["oracle_mean"][i])
                  for i, z in enumerate(kn["z"])]
    v = joint_verdict(stats, confidence)
    if not summary.get("faults", {}).get("exact_oracle", True):
        agree, reason = False, ("not comparable: these faults have no exact oracle "
                                "(quantization, missed ticks, or sensor noise before the band "
                                "latch); the Monte Carlo numbers stand alone")
    elif summary["saturation"]["tick_fraction"] > 0:
        agree, reason = False, ("the controller saturated: the oracle assumes the law is never "
                                "clipped, so it does not predict this run")
    elif v.outside:
        agree, reason = False, "outside the joint interval: " + ", ".join(v.outside)
    else:
        agree, reason = True, "every statistic inside the joint interval"
    return {"agree": agree, "confidence": confidence, "correction": "Bonferroni",
            "statistics": v.statistics, "z_limit": v.z_limit, "max_abs_z": v.max_abs_z,
            "max_abs_z_of": v.max_abs_z_of, "reason": reason}


# Why a z-score (or another ratio to a Monte Carlo standard error) is null.
_ZERO_SE = ("every path gave the same value (a problem without noise, or a deterministic "
            "quantity): the Monte Carlo standard error is 0 up to rounding, so the ratio is "
            "undefined")
