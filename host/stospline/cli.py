"""``stospline`` command line: reads the arguments, calls `stospline.pipeline`, prints reports.

Exit status: 0 success, 2 bad problem file, bad command-line value, unwritable output, a run
beyond the memory/time limits, or an infeasible problem (one line on stderr naming the field
or option), 128 + N when signal N interrupted it, 1 anything else.
"""
from __future__ import annotations

import os

# The designs and oracles multiply small matrices, where BLAS threads only cost time (a design
# ran 5.6x slower with them while the other core was busy) and would oversubscribe the oracle's
# two threads: one BLAS thread unless the caller's environment says otherwise. Before numpy
# is first imported, which reads these.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse                                                  # noqa: E402
import dataclasses                                               # noqa: E402
import functools                                                 # noqa: E402
import math                                                      # noqa: E402
import re                                                        # noqa: E402
import signal                                                    # noqa: E402
import sys                                                       # noqa: E402
from pathlib import Path                                         # noqa: E402

# Only light modules here: numpy and the rest load inside `main`, where an interrupt is
# caught (a Ctrl-C while they load ends in one line, not a traceback).
from stospline import progress                                   # noqa: E402
from stospline.errors import ProblemError, StosplineError       # noqa: E402
from stospline.firmware_interface import ARITHS                  # noqa: E402
from stospline.table_options import DEFAULT_SPLINE_TOLERANCE, TABLE_KINDS  # noqa: E402

__all__ = ["main"]


def load_problem(path):
    from stospline.nonlinear.plant_file import has_plant
    from stospline.problem.reader import load_problem as load
    _PLANT_FIT.clear()
    if not has_plant(path):
        return load(path)
    from stospline.nonlinear.iterate import load_plant_problem
    problem, fit = load_plant_problem(path)        # the linearisation along its mean path
    _PLANT_FIT[:] = [fit]
    return problem


_PLANT_FIT: list = []    # how the last [plant] problem loaded converged, for the text summary


def dumps(obj) -> str:
    from stospline.strict import dumps as strict_dumps
    return strict_dumps(obj)


def quiet_numerics(func):
    """`stospline.strict.quiet_numerics`, imported when the command runs."""
    @functools.wraps(func)
    def run(*args, **kwargs):
        from stospline.strict import quiet_numerics as quiet
        return quiet(func)(*args, **kwargs)
    return run


def _design_options(args, problem):
    """The run's `stospline.options.DesignOptions`: the command line first, then the file's
    [design] table, then defaults (`resolve_options`); options given as text checked here."""
    from stospline.options import resolve_options
    delay = None
    if args.delay_ticks is not None:
        if args.delay_ticks not in ("0", "1"):
            raise ProblemError("--delay-ticks", f"must be 0 or 1 (ticks between measuring x "
                                                f"and applying its command), got "
                                                f"{args.delay_ticks!r}")
        delay = int(args.delay_ticks)
    tolerance = None
    if args.spline_tolerance is not None:
        try:
            tolerance = float(args.spline_tolerance)
        except ValueError:
            tolerance = args.spline_tolerance       # refused, by name, as not a number
    return resolve_options(problem, noise=not getattr(args, "ignore_noise", False),
                           mode=args.mode, discretization=args.discretization,
                           delay_ticks=delay, table=args.table, spline_tolerance=tolerance,
                           arith=getattr(args, "arith", None),
                           tolerance_field="--spline-tolerance")


@quiet_numerics
def _design(args) -> int:
    from stospline.atomic import check_target
    from stospline.output_names import table_files
    from stospline.pipeline import design_files, design_problem, write_outputs
    inputs = [args.problem]
    if args.out:
        check_target(args.out)                  # before any work: nothing is created
    problem = load_problem(args.problem)
    opts = _design_options(args, problem)
    names = table_files(problem.name, opts.arith, opts.spline)
    fixed_params = bool(problem.parameters) and opts.arith != "float32"
    spline_params = bool(problem.parameters) and opts.spline and not fixed_params
    params = (_parameter_names(args, problem, opts)
              if args.out or fixed_params or spline_params else [])
    if args.out:
        check_target(args.out, params + names, inputs)
    _check_budget(args, problem, opts, "design", arith=opts.arith)
    # A Q15/Q31 spline table with parameters is fitted on the per-tick parametric design's
    # (`fixed_spline_parametric`): the design summarised is the per-tick one, as for Q tables.
    qspline = fixed_params and opts.spline
    d = design_problem(problem, options=(dataclasses.replace(opts, table="per-tick")
                                         if qspline else opts),
                       **_limits(args))
    _note_tables(d, "formatting")
    source_name = Path(args.problem).name
    pfiles, fixed, terms, table_terms = {}, None, None, None
    if spline_params:                           # the spline columns on the designed table
        pfiles, table_terms = _spline_parametric(args, d, source_name)
    elif fixed_params:                          # the gain table scaled with its columns
        pfiles, fixed, terms = _fixed_parametric(args, problem, source_name, opts,
                                                 names[0].removesuffix(".h"))
    elif params:
        from stospline.oracle.parametric import parametric_c_files
        pfiles = parametric_c_files(problem, source_name, opts)
    files, summary = design_files(d, source_name, opts.arith, with_c=bool(args.out),
                                  fixed=fixed, fixed_terms=terms, table_terms=table_terms)
    if args.out:                                # written with the tables, as one set
        files.update(pfiles)
        written = write_outputs(args.out, files, inputs)
    if args.json:
        print(files[names[-1]], end="")
    else:
        from stospline.report.summary_text import design_run_text
        print(design_run_text(d, opts.arith, summary), end="")
        for fit in _PLANT_FIT:
            print(f"  {fit.text()}")
        for path in written if args.out else []:
            print(f"wrote {path}")
    return 0


def _spline_parametric(args, d, source_name: str) -> tuple[dict, dict]:
    """``(files, terms)``: the spline columns ``<name>_spline_params.{h,c}``
    (`stospline.pipeline.spline_parametric_files`, what tools/params_tables.py --spline
    writes) and, for the JSON summary's ``table``, what the table as flashed guarantees over
    the parameter box (`stospline.refine.spline_params.certify_over_box` of the spline table
    with its columns: ``over_box``); a note on stderr when a band row does not hold there.
    A spline table the columns cannot follow: ProblemError naming ``--table`` when given."""
    from stospline.pipeline import spline_parametric_files
    from stospline.refine.spline_params import certify_over_box
    try:
        files, sp = spline_parametric_files(d, source_name)
    except ProblemError as exc:
        raise _option_error(args, exc) from None
    cert = certify_over_box(d.problem, sp, keys=("spline",))
    flashed = cert.pop("spline")
    for m in flashed["bands"]:
        if not m["holds"]:
            print(f"stospline: note: {m['field']} row {m['row']} does not hold over the "
                  f"parameter box for the spline table as flashed: it leaves the band by "
                  f"{-m['worst_margin']:.3g} at t = {m['t']:g}", file=sys.stderr)
    return files, {"over_box": {**flashed, **cert}}


def _fixed_parametric(args, problem, source_name: str, opts, stem: str):
    """``(files, table, terms)`` of a problem's Q15/Q31 parametric controller: the gain table
    scaled with its per-tick columns (`stospline.oracle.parametric.fixed_parametric`) or, with
    ``table = "spline"``, the Q spline gain table with its spline columns
    (`fixed_spline_parametric`, what tools/params_tables.py --fixed writes); the gain table
    as flashed, for `stospline.pipeline.design_files`; and `_fixed_over_box` of it."""
    from stospline.oracle.parametric import fixed_parametric, fixed_spline_parametric
    try:
        if opts.spline:
            pfiles, (pf, gains, cols), pd = fixed_spline_parametric(problem, source_name, opts)
        else:
            pfiles, pf, pd = fixed_parametric(problem, source_name, opts)
    except ProblemError as exc:                 # the spline's tolerance or format
        raise _option_error(args, exc) from None
    except ValueError as exc:                   # scale exponents beyond STSP_Q_EXP_MAX
        raise _parameter_scale_error(problem, opts.arith, exc) from None
    terms = _fixed_over_box(problem, pd, pf, opts.arith + "_spline" * opts.spline)
    if not opts.spline:
        return pfiles, pf.gain_table(stem), terms
    from stospline.table.spline.fixed_point import q_spline_bytes
    from stospline.table.spline.qparams import column_flash_bytes, spline_gain_table
    terms["spline"] = {"gain_bytes": q_spline_bytes(gains),
                       "column_bytes": column_flash_bytes(pf, cols),
                       "span_ticks": [1 << int(k) for k in gains.span_log2],
                       "spline_tolerance": opts.spline_tolerance,
                       "column_fit_error_lsb": float(cols.error.max(initial=0.0))}
    return pfiles, spline_gain_table(pf, gains, stem), terms


def _fixed_over_box(problem, pd, pf, arith: str) -> dict:
    """``{"over_box": ...}`` of the Q15/Q31 parametric table (`arith` ``q15``, ``q31``,
    ``q15_spline`` or ``q31_spline``) as flashed
    (`stospline.oracle.fixed_point_margin.fixed_point_certificate`), for its JSON summary; a
    note on stderr for each band row it does not certify (docs/theory/parameters.md,
    "Fixed-point columns")."""
    from stospline.oracle.fixed_point_margin import fixed_point_certificate
    from stospline.report.design_summary import fixed_over_box_terms
    try:
        cert = fixed_point_certificate(problem, pd.table, pf, pd.box)
    except ValueError:                          # a delay or time-varying data: not covered
        return {}
    for m in cert["margins"]:
        if not m.holds:
            print(f"stospline: note: {m.field} row {m.row} is not certified for the "
                  f"{arith.upper().replace('_SPLINE', ' spline')} table over the parameter "
                  f"box: less its error bound it leaves the band by {-m.worst:.3g} at "
                  f"t = {m.t:g}", file=sys.stderr)
    return {"over_box": fixed_over_box_terms(problem, cert)}


def _parameter_scale_error(problem, arith: str, exc: ValueError) -> ProblemError:
    """`strict.fixed_scale_error` of a fixed-point parametric table; when the problem's own
    data are moderate, naming the range of the parameter that reaches furthest (its
    deviation is a state of the fixed-point law, and it moves the states over the box)."""
    from stospline import strict
    err = strict.fixed_scale_error(problem, arith, exc)
    if err.field != "design.arith":
        return err
    reach = [max(q.upper - q.nominal, q.nominal - q.lower) for q in problem.parameters]
    j = max(range(len(reach)), key=reach.__getitem__)
    return ProblemError(f"parameters[{j}].range",
                        f"no {arith.upper()} table can hold this design over the parameter "
                        f"box: {exc}; {problem.parameters[j].name} reaches {reach[j]:.3g} "
                        f"from its nominal; narrow its range or use float32 tables")


def _option_error(args, exc: ProblemError) -> ProblemError:
    """`exc` naming the command-line option (``--table``, ``--arith``, ``--delay-ticks``...)
    instead of ``design.<key>`` when the option was given there; else `exc`."""
    key = exc.field.removeprefix("design.")
    if key != exc.field and getattr(args, key, None) is not None:
        return ProblemError(f"--{key.replace('_', '-')}", exc.reason)
    return exc


@quiet_numerics
def _parameter_names(args, problem, opts) -> list[str]:
    """``<name>[_<arith>][_spline]_params.{h,c}`` for a problem with [[parameters]] ([]
    without), or ProblemError naming the option (``--arith``/``--table``/``--delay-ticks``,
    else ``design.*`` or the stage) whose table has no sensitivity columns."""
    if not problem.parameters:
        return []
    from stospline.oracle.parametric import check_parametric_options
    try:
        check_parametric_options(problem, opts)
    except ProblemError as exc:
        raise _option_error(args, exc) from None
    from stospline.output_names import table_stem
    stem = table_stem(problem.name, opts.arith, opts.spline)
    return [f"{stem}_params.h", f"{stem}_params.c"]


def _corridor_design(args) -> int:
    """Search the (w, wv) grid for the cheapest design that meets the corridor's epsilon
    (`stospline.corridor_search`); write the designed problem file, its tables and the
    certificate together."""
    from stospline import corridor_search as cs
    from stospline.atomic import check_target
    from stospline.budget import enforce, format_seconds
    from stospline.options import with_file_options
    from stospline.output_names import corridor_design_files
    from stospline.pipeline import generated_files, write_outputs
    if args.out:
        check_target(args.out)                  # before any work: nothing is created
    if args.seed == args.certify_seed:
        raise ProblemError("--certify-seed", f"must differ from --seed ({args.seed}): "
                                             f"certifying on the screening sample biases it")
    problem = load_problem(args.problem)
    plant = _plant_corridor(args, problem) if _PLANT_FIT else None
    problem, index = cs.target_corridor(problem, args.epsilon, varying=plant is not None)
    resolved = _design_options(args, problem)
    for key, option, bad in (("table", "--table", "spline"), ("delay_ticks", "--delay-ticks", 1)):
        if getattr(resolved, key) == bad:
            raise ProblemError(option if getattr(args, key) is not None else f"design.{key}",
                               "corridor-design writes per-tick tables without a delay")
    if problem.measurement is not None:
        _sensor_corridor_refusal(args, problem, resolved, plant is not None)
    opts = {"mode": resolved.mode, "discretization": resolved.discretization}
    if args.mode or args.discretization:      # the designed file says how it was designed
        given = {k: v for k, v in opts.items() if getattr(args, k)}
        problem = with_file_options(problem, **given)
        if plant is not None:                 # and its iterations run with them
            plant.doc["design"] = {**plant.doc.get("design", {}), **given}
    name = problem.name
    files = corridor_design_files(name) + (list(plant.files()) if plant else [])
    if args.out:
        check_target(args.out, files, [args.problem])
    cs.check_reachable(problem, index, search_paths=args.search, certify_paths=args.certify,
                       epsilon_option=args.epsilon is not None)
    grid = len(args.strip) * len(args.rate)
    workers = _workers(args)
    counts = dict(grid=grid, search_paths=args.search, certify_paths=args.certify,
                  attempts=args.attempts, refine=args.refine, substeps=args.substeps)
    est = enforce(plant.work_estimate(problem, **counts, **opts) if plant else
                  cs.work_estimate(problem, workers=workers, **counts, **opts),
                  problem, max_seconds=args.max_time, max_bytes=args.max_memory * 1024 ** 3,
                  workers=workers)
    progress.note(f"corridor-design of {name}: at most ~{format_seconds(est.seconds)} "
                  f"({grid} grid points screened, {args.attempts} certifications)")
    checked = {**opts, "max_memory": None, "max_time": None}    # the whole search is checked
    on_plant = {} if plant is None else {"make": plant.candidate}
    result = cs.evaluate_grid(problem, index, strip=args.strip, rate=args.rate, **on_plant,
                              **checked)
    if plant is not None:
        on_plant["exits"] = plant.count_exits
    cs.search(problem, index, result, search_paths=args.search, certify_paths=args.certify,
              search_seed=args.seed, certify_seed=args.certify_seed, attempts=args.attempts,
              refine=args.refine, substeps=args.substeps, workers=workers, force_workers=True,
              scheduler=args.scheduler, **on_plant, **checked)
    c = result.chosen
    if c is None:                # nothing on stdout: the error line says why
        raise ProblemError(f"corridors[{index}].epsilon", cs.failure_reason(result))
    cert = cs.certificate(result, problem_sha256=result.designed.problem.source_sha256,
                          design_options=opts, substeps=args.substeps)
    if plant is not None:
        cert = plant.certificate(cert, args.substeps)
    text = dumps(cert) + "\n"
    written = []
    if args.out:
        out = generated_files(result.designed, f"{name}.toml")
        written = write_outputs(args.out, {f"{name}.toml": c.toml, **out,
                                           f"{name}_corridor.json": text,
                                           **(plant.files() if plant else {})},
                                [args.problem])
    if args.json:
        print(text, end="")
    else:
        print(cs.summary_text(result))
        for path in written:
            print(f"wrote {path}")
    return 0


def _sensor_corridor_refusal(args, problem, resolved, on_plant: bool) -> None:
    """What corridor-design's sensor loop (a problem with [measurement]: exits counted on
    the law run on the filter's estimate) does not run: one line naming the field or
    option."""
    why = "a problem with [measurement] screens and certifies on the sensor loop, which"
    if on_plant:
        raise ProblemError("measurement", f"{why} runs the linear plant, not a [plant] model")
    if problem.faults.any:
        raise ProblemError("faults", f"{why} takes no faults (the sensor's noise is the "
                                     f"measurement table's)")
    if resolved.arith != "float32":
        raise ProblemError("--arith" if getattr(args, "arith", None) else "design.arith",
                           f"{why} runs float32 tables")


def _plant_corridor(args, problem):
    """The search's hooks for a [plant] problem (`stospline.nonlinear.corridor`): grid points
    designed on their own linearisation, exits counted on the model."""
    from stospline.nonlinear.corridor import PlantCorridor
    from stospline.problem.inputfile import decode_problem, read_problem_file
    doc = decode_problem(read_problem_file(args.problem))
    return PlantCorridor(doc, Path(args.problem).resolve().parent, _PLANT_FIT[0], problem.name)


def _start(arg: str | None):
    """``--x0 "a,b,..."`` as floats (None: the problem's x0)."""
    if arg is None:
        return None
    try:
        return [float(v) for v in arg.replace(" ", "").split(",")]
    except ValueError:
        raise ProblemError("--x0", f"expected comma-separated numbers, got {arg!r}") from None


def _check_budget(args, problem, opts, command: str, **options) -> None:
    """Refuse (BudgetError, exit 2) a run beyond the limits before any work; announce a long
    one (when progress is shown)."""
    from stospline.budget import check, format_bytes, format_seconds
    substeps = options.pop("substeps", getattr(args, "substeps", 2))
    paths = options.pop("paths", getattr(args, "paths", 0))
    if command != "design":
        options.setdefault("workers", _workers(args))
        if _PLANT_FIT:          # the run is on the [plant] model (`_plant_run`)
            options.setdefault("model", True)
    est = check(problem, command=command, max_seconds=args.max_time,
                max_bytes=args.max_memory * 1024 ** 3, **opts.workload(),
                paths=paths,
                substeps=1 if substeps == "auto" else substeps,   # "auto": checked again
                **options)
    if est.seconds > 5:
        progress.note(f"{command} of {problem.name}: estimated ~{format_seconds(est.seconds)}"
                      f" and ~{format_bytes(est.bytes)} of memory")


def _limits(args) -> dict:
    """The command line's limits as the library's arguments."""
    return {"max_memory": args.max_memory, "max_time": args.max_time}


def _workers(args) -> int:
    """The worker processes of the run: --workers (default: every core), at most the cores
    this process may use unless --force-workers; a note on stderr when it limits them."""
    from stospline.pipeline import usable_workers
    workers = usable_workers(args.workers, args.force_workers)
    if args.workers is not None and workers < args.workers and not getattr(args, "_workers_noted", False):
        args._workers_noted = True
        print(f"stospline: note: --workers {args.workers} limited to the {workers} cores this "
              f"process may use (--force-workers starts them all; the numbers are the same)",
              file=sys.stderr)
    return workers


def _note_tables(d, doing: str) -> None:
    """Announce a long step without a progress bar (formatting or compiling big tables)."""
    from stospline.budget import CODEGEN_NUMBER, COMPILE_NUMBER, format_seconds
    from stospline.pipeline import table_numbers
    numbers = table_numbers(d)
    per = CODEGEN_NUMBER + (COMPILE_NUMBER if doing == "compiling" else 0.0)
    if numbers * per > 5:
        progress.note(f"{doing} the C tables ({numbers} numbers, estimated "
                      f"~{format_seconds(numbers * per)})")


def _fault_value(text: str):
    """An int, a float or a comma-separated list of floats (one per state or input)."""
    try:
        if "," in text:
            return [float(v) for v in text.split(",")]
        return int(text) if re.fullmatch(r"[+-]?\d+", text.strip()) else float(text)
    except ValueError:
        return text        # parse_faults names the key and says what it must be


def _fault(text: str) -> tuple[str, object]:
    key, sep, value = text.partition("=")
    if not sep or not key:
        raise argparse.ArgumentTypeError(f"must be KEY=VALUE (e.g. sensor_noise=0.01), "
                                         f"got {text!r}")
    return key.strip(), _fault_value(value.strip())


def _load_with_faults(args):
    """The problem file, with each ``--fault KEY=VALUE`` replacing that key of its
    ``[faults]`` (checked like the file's, the field named ``--fault KEY``)."""
    from dataclasses import replace
    from stospline.problem.faults import parse_faults
    problem = load_problem(args.problem)
    given = getattr(args, "fault", None)
    if not given:
        return problem
    merged = {**problem.faults.as_dict(), **dict(given)}    # the file's keys are valid
    return replace(problem, faults=parse_faults(merged, problem.n, problem.m,
                                                prefix="--fault "))


def _check_faults_runnable(args, problem, opts) -> None:
    """Refuse, before the design, faults the harness cannot run around this problem's table
    (`stospline.pipeline.check_faults_runnable`), naming ``--fault`` when the command line
    set faults."""
    given = getattr(args, "fault", None) or []
    if _PLANT_FIT:           # the faults run around the model (`nonlinear.simulate`)
        from stospline.nonlinear.simulate import check_model_faults
        check_model_faults(problem.faults, {key for key, _ in given})
        return
    from stospline.pipeline import check_faults_runnable
    check_faults_runnable(problem, opts, field="--fault" if given else "faults")


@quiet_numerics
def _simulate(args) -> int:
    from stospline.pipeline import design_problem, simulate_problem, simulation_summary, start_from
    from stospline.report.summary_text import saturation_warning, simulation_summary_text
    problem = _load_with_faults(args)
    opts = _design_options(args, problem)
    if problem.measurement is not None:
        return _simulate_sensor(args, problem, opts)
    x0 = args.x0
    _check_faults_runnable(args, problem, opts)
    _check_budget(args, problem, opts, "simulate")
    d = design_problem(problem, options=opts, **_limits(args))
    if x0 is not None:
        d = start_from(d, x0)
    if _PLANT_FIT:                 # the controller against the C model itself
        return _simulate_plant(args, d)
    _note_tables(d, "compiling")
    substeps = _planned_substeps(args, problem, opts, d, "simulate")
    mc = simulate_problem(d, paths=args.paths, seed=args.seed, substeps=substeps,
                          workers=_workers(args), force_workers=True,
                          scheduler=args.scheduler, **_limits(args))
    s = simulation_summary(d, mc, seed=args.seed)
    # Flushed: the saturation warning (stderr) comes after the numbers it qualifies.
    print(dumps(s) + "\n" if args.json else simulation_summary_text(s), end="", flush=True)
    warning = saturation_warning(s)
    if warning:
        print(f"stospline: warning: {warning}", file=sys.stderr)
    return 0 if (s["verdict"]["agree"] or not args.check) else EXIT_DISAGREE


SENSOR_MAX_PATHS = 10 ** 7    # the sensor loop holds every path's state at once


def _sensor_refusal(args, problem, opts) -> None:
    """Refuse, before the design, what the sensor loop's Monte Carlo does not run (one line
    naming the option, or the file's field)."""
    def named(option: str, key: str, field: str) -> str:
        return option if getattr(args, key, None) not in (None, False, []) else field
    why = "a problem with [measurement] runs the sensor loop, which"
    from stospline.estimator.oracle import estimator_faults_unsupported
    bad = estimator_faults_unsupported(problem.faults)
    if bad and getattr(args, "fault", None):
        raise ProblemError("--fault", f"{bad[0].split('.')[-1]}: {bad[1]}")
    if bad:
        raise ProblemError(*bad)
    if getattr(args, "x0", None) is not None:
        raise ProblemError("--x0", f"{why} starts from the file's x0 and x0_cov (the filter's "
                                   f"prior mean is flashed with the tables)")
    if args.scheduler is not None:
        raise ProblemError("--scheduler", f"{why} runs in this process")
    if args.paths > SENSOR_MAX_PATHS:
        raise ProblemError("--paths", f"{why} holds every path in memory: at most "
                                      f"{SENSOR_MAX_PATHS}, got {args.paths}")
    for key, bad, what in (("delay_ticks", 1, "has no estimator form for a one-tick delay"),
                           ("arith", "q15", "runs float32 tables"),
                           ("arith", "q31", "runs float32 tables")):
        if getattr(opts, key) == bad:
            raise ProblemError(named(f"--{key.replace('_', '-')}", key, f"design.{key}"),
                               f"{why} {what}")


def _sensor_run(args, problem, opts, command: str, record: int = 0):
    """``(d, run, summary)`` of the loop on the problem's sensor: the law on the filter's
    estimate, through the compiled C estimator controller (`harness.estimator_run`)."""
    from stospline.harness.estimator_run import run_sensor_loop, sensor_loop_unsupported
    from stospline.pipeline import check_implementable, design_problem
    from stospline.report.sensor_simulation import sensor_simulation_summary
    _sensor_refusal(args, problem, opts)
    _check_budget(args, problem, opts, command, record=record,
                  substeps=1 if args.substeps == "auto" else args.substeps)
    d = design_problem(problem, options=opts, **_limits(args))
    check_implementable(d)
    why = sensor_loop_unsupported(d.problem, d.table)
    if why:
        raise ProblemError(*why)
    run = run_sensor_loop(d.problem, d.table, paths=args.paths, seed=args.seed,
                          substeps=args.substeps, record=record, spline_tolerance=(
                              d.options.spline_tolerance if d.table.spline is not None else None))
    return d, run, sensor_simulation_summary(d, run, seed=args.seed)


def _simulate_sensor(args, problem, opts) -> int:
    """`simulate` of a problem with [measurement] (`_sensor_run`)."""
    from stospline.report.sensor_simulation import sensor_simulation_text
    from stospline.report.summary_text import saturation_warning
    _, _, s = _sensor_run(args, problem, opts, "simulate")
    print(dumps(s) + "\n" if args.json else sensor_simulation_text(s), end="", flush=True)
    warning = saturation_warning(s)
    if warning:
        print(f"stospline: warning: {warning}", file=sys.stderr)
    return 0 if (s["verdict"]["agree"] or not args.check) else EXIT_DISAGREE


def _planned_substeps(args, problem, opts, d, command: str, **options):
    """`--substeps auto`: the choice for this run, its cost checked against the budget before
    the run starts (a given number was checked with the problem)."""
    if args.substeps != "auto":
        return args.substeps
    from stospline.pipeline import plan_substeps
    choice = plan_substeps(d, paths=args.paths, seed=args.seed)
    if choice.substeps > 1:
        _check_budget(args, problem, opts, command, substeps=choice.substeps, **options)
    return choice


def _designed(args, command: str, record: int = 0, extra_paths: int = 0):
    """Design the file's problem for `plot`/`report`: ``(problem, opts, d)``; the output file
    is checked and the budget estimated first (for the run's paths and `extra_paths` more of
    the same kind)."""
    from stospline.atomic import check_file_target
    from stospline.pipeline import design_problem
    check_file_target(args.out, [args.problem])
    problem = _load_with_faults(args)
    opts = _design_options(args, problem)
    _check_faults_runnable(args, problem, opts)
    _check_budget(args, problem, opts, command, paths=args.paths + extra_paths, record=record)
    return problem, opts, design_problem(problem, options=opts, **_limits(args))


def _monte_carlo(args, command: str, record: int = 0, extra_paths: int = 0,
                 model_faults: list | None = None):
    """`_designed`, then `_linear_run`: ``(d, mc)``."""
    problem, opts, d = _designed(args, command, record, extra_paths)
    return _linear_run(args, command, problem, opts, d, record, model_faults)


def _linear_run(args, command: str, problem, opts, d, record: int = 0,
                model_faults: list | None = None):
    """The Monte Carlo of design `d` on the linear harness: ``(d, mc)``. A [plant] problem's
    faults run around the model, not the linearisation: its run here is fault-free, and the
    faults are appended to `model_faults`."""
    from stospline.pipeline import simulate_problem
    if _PLANT_FIT and problem.faults.any:
        from dataclasses import replace
        from stospline.problem.faults import Faults
        if model_faults is not None:
            model_faults.append(problem.faults)
        progress.note("the linearisation's Monte Carlo runs without faults (they run around "
                      "the [plant] model)")
        d = replace(d, problem=replace(problem, faults=Faults()))
    _note_tables(d, "compiling")
    substeps = _planned_substeps(args, problem, opts, d, command, record=record)
    return d, simulate_problem(d, paths=args.paths, seed=args.seed, substeps=substeps,
                               workers=_workers(args), force_workers=True, record=record,
                               scheduler=args.scheduler, **_limits(args))


@quiet_numerics
def _plot(args) -> int:
    from stospline.atomic import write_file
    from stospline.report.plot import plot_corridor
    problem, opts, d = _designed(args, "plot")
    if not _PLANT_FIT:
        _, mc = _linear_run(args, "plot", problem, opts, d)
        write_file(args.out, lambda tmp: plot_corridor(d, mc, tmp), [args.problem])
    else:                        # the controller against the C model itself
        from stospline.nonlinear.simulate import plant_summary
        from stospline.report.plant_plot import plot_plant
        r = _plant_run(args, d)
        summary = plant_summary(d, r)
        write_file(args.out, lambda tmp: plot_plant(d, r, summary, tmp), [args.problem])
    print(f"wrote {args.out}")
    return 0


@quiet_numerics
def _report(args) -> int:
    from stospline.atomic import write_file
    from stospline.pipeline import (fault_sweep, fault_sweep_runs, fault_table_unavailable,
                                    simulation_summary)
    from stospline.atomic import check_file_target
    from stospline.report.html import report_html
    check_file_target(args.out, [args.problem])        # before the file is read
    first = load_problem(args.problem)
    if first.measurement is not None:
        return _report_sensor(args)
    runs = fault_sweep_runs()
    model_faults: list = []
    d, mc = _monte_carlo(args, "report", record=REPORT_RECORD,
                         extra_paths=runs * args.fault_paths, model_faults=model_faults)
    summary = simulation_summary(d, mc, seed=args.seed)
    rows, plant, left_out = None, None, []
    why_not = None if _PLANT_FIT else fault_table_unavailable(d)
    if _PLANT_FIT:              # the run above is the linearisation's: the model's too
        from stospline.nonlinear.simulate import plant_summary
        r = _plant_run(args, d, model_faults[0] if model_faults else None)
        plant = plant_summary(d, r)
    if args.fault_paths and why_not:
        progress.note(f"no fault table: {why_not}")
    elif args.fault_paths and _PLANT_FIT:
        from stospline.nonlinear.fault_sweep import model_fault_table
        progress.note(f"fault table on the [plant] model: at most {runs} runs of "
                      f"{args.fault_paths} paths")
        rows, left_out = model_fault_table(d, _PLANT_FIT[0].model, paths=args.fault_paths,
                                           seed=args.seed, substeps=r.run.substeps)
    elif args.fault_paths:
        progress.note(f"fault table: {runs} runs of {args.fault_paths} paths")
        rows = fault_sweep(d, paths=args.fault_paths, seed=args.seed, substeps=mc.substeps,
                           workers=_workers(args), scheduler=args.scheduler)
    page = report_html(d, mc, summary, rows, why_not if args.fault_paths else None, plant,
                       left_out)
    write_file(args.out, lambda tmp: Path(tmp).write_text(page, encoding="utf-8"),
               [args.problem])
    print(f"wrote {args.out}")
    return 0


def _report_sensor(args) -> int:
    """`report` of a problem with [measurement]: the page of the sensor loop
    (`report.sensor_html`); no fault table (the sensor loop runs without faults)."""
    from stospline.atomic import check_file_target, write_file
    from stospline.report.sensor_html import sensor_report_html
    check_file_target(args.out, [args.problem])
    problem = _load_with_faults(args)
    opts = _design_options(args, problem)
    d, run, summary = _sensor_run(args, problem, opts, "report", record=REPORT_RECORD)
    if args.fault_paths:
        progress.note("no fault table: the sensor loop runs without faults")
    page = sensor_report_html(d, run, summary)
    write_file(args.out, lambda tmp: Path(tmp).write_text(page, encoding="utf-8"),
               [args.problem])
    print(f"wrote {args.out}")
    return 0


def _version() -> str:
    from stospline import __version__
    return __version__


class _VersionAction(argparse.Action):
    """``--version``: the installed version, looked up only when asked."""

    def __call__(self, parser, namespace, values, option_string=None):
        print(f"{parser.prog} {_version()}")
        parser.exit(0)


class _Parser(argparse.ArgumentParser):
    """argparse with its errors on one line: ``stospline: error: --paths: REASON``."""

    def error(self, message: str):
        if message.startswith("argument "):
            message = message[len("argument "):]
            option, sep, reason = message.partition(": ")
            message = f"{option.split('/')[-1]}{sep}{reason}"
        self.exit(2, f"stospline: error: {message} (see {self.prog} --help)\n")


def _integer(lo: int, hi: int):
    def parse(text: str) -> int:
        try:
            value = int(text, 10)
        except ValueError:
            value = None
        if value is None or not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"must be an integer in {lo}..{hi}, got {text!r}")
        return value
    return parse


def _substeps(text: str):
    """``auto`` or an integer in 1..MAX_SUBSTEPS."""
    if text == "auto":
        return text
    try:
        return _integer(1, MAX_SUBSTEPS)(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(
            f"must be auto or an integer in 1..{MAX_SUBSTEPS}, got {text!r}") from None


def _positive(hi: float, unit: str):
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not 0 < value <= hi:
            raise argparse.ArgumentTypeError(f"must be a number of {unit} in (0, {hi:g}], "
                                             f"got {text!r}")
        return value
    return parse


def _probability(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not 0 < value < 1:
        raise argparse.ArgumentTypeError(f"must be a number in (0, 1), got {text!r}")
    return value


def _weights(text: str) -> tuple[float, ...]:
    """Comma-separated finite weights >= 0, at least one, no repeats."""
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if (not values or not all(math.isfinite(v) and 0 <= v <= 1e12 for v in values)
            or len(set(values)) != len(values)):
        raise argparse.ArgumentTypeError(f"must be distinct comma-separated numbers in "
                                         f"[0, 1e12], got {text!r}")
    return values


def _x0(text: str) -> list[float]:
    try:
        return _start(text)
    except ProblemError as exc:
        raise argparse.ArgumentTypeError(exc.reason) from None


def _out_file(text: str) -> str:
    if Path(text).suffix.lower() not in PLOT_FORMATS:
        raise argparse.ArgumentTypeError(f"must name a {', '.join(PLOT_FORMATS)} file (the "
                                         f"suffix sets the format), got {text!r}")
    return text


def _scheduler(text: str) -> str:
    """``local`` or a Dask scheduler address: [protocol://]host:port."""
    if text == "local" or re.fullmatch(r"([a-z]+://)?[^\s:/]+:\d{1,5}", text):
        return text
    raise argparse.ArgumentTypeError(f"must be local or a Dask scheduler address "
                                     f"[protocol://]host:port, got {text!r}")


def _out_html(text: str) -> str:
    if Path(text).suffix.lower() != ".html":
        raise argparse.ArgumentTypeError(f"must name a .html file, got {text!r}")
    return text


def _out_dir(text: str) -> str:
    if not text or "\0" in text:
        raise argparse.ArgumentTypeError(f"must be a directory path, got {text!r}")
    return text


PLOT_FORMATS = (".png", ".pdf", ".svg")
MAX_PATHS = 10 ** 9          # the memory/time budget usually refuses far fewer
MAX_SUBSTEPS = 10_000
EXIT_DISAGREE = 3   # simulate --check: the Monte Carlo run and the oracle disagree
MAX_WORKERS = 1024
REPORT_RECORD = 200  # paths whose states the report keeps at every tick (percentile bands)
SEED_MAX = 2 ** 63 - 1


def _common(sp) -> None:
    """Options of every command: limits and progress."""
    from stospline.budget import DEFAULT_MAX_BYTES, DEFAULT_MAX_SECONDS
    sp.add_argument("--quiet", action="store_true",
                    help="no progress bars or estimates on stderr (they are shown only when "
                         "stderr is a terminal and a run is long)")
    sp.add_argument("--max-time", type=_positive(1e9, "seconds"), default=DEFAULT_MAX_SECONDS,
                    metavar="SECONDS",
                    help=f"refuse a run estimated to take longer (default "
                         f"{DEFAULT_MAX_SECONDS:g} s; docs/guide/problem-file.md, Limits)")
    sp.add_argument("--max-memory", type=_positive(1e6, "GiB"),
                    default=DEFAULT_MAX_BYTES / 1024 ** 3, metavar="GIB",
                    help=f"refuse a run estimated to need more memory (default "
                         f"{DEFAULT_MAX_BYTES / 1024 ** 3:g} GiB, at most the machine's RAM)")


def _force_workers(p) -> None:
    p.add_argument("--force-workers", action="store_true",
                   help="start --workers processes even beyond the cores this process may "
                        "use (each is counted in the memory estimate)")


def build_parser() -> argparse.ArgumentParser:
    ap = _Parser(prog="stospline", description=__doc__.splitlines()[0])
    ap.add_argument("--version", action=_VersionAction, nargs=0,
                    help="show the program's version number and exit")
    sub = ap.add_subparsers(dest="command", required=True)

    p = sub.add_parser("design", help="solve the design, write C gain tables and a summary")
    p.add_argument("problem", help="problem file (TOML)")
    p.add_argument("--out", type=_out_dir,
                   help="directory for <name>.c, <name>.h, <name>.json (created if missing; "
                        "all three are replaced together or not at all)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.add_argument("--ignore-noise", action="store_true",
                   help="design as if there were no noise (the paper's Remark 2)")
    p.add_argument("--arith", default=None, metavar="{float32,q15,q31}",
                   help="arithmetic of the generated tables: float32 (default), or fixed-point "
                        "Q15/Q31 written as <name>_<arith>.{c,h,json} (docs/guide/firmware.md). "
                        "Default: the file's [design] arith")
    p.set_defaults(func=_design)

    p = sub.add_parser("simulate", help="Monte Carlo with the compiled C controller in the loop")
    p.add_argument("problem")
    p.add_argument("--paths", type=_integer(2, MAX_PATHS), default=10000,
                   help=f"Monte Carlo paths, 2..{MAX_PATHS}")
    p.add_argument("--seed", type=_integer(0, SEED_MAX), default=1,
                   help="seed of the random numbers, 0..2^63-1")
    p.add_argument("--substeps", type=_substeps, default="auto",
                   help=f"plant steps per controller tick, 1..{MAX_SUBSTEPS}, or auto (default): "
                        "the fewest whose exact bias in the expected cost is at most 0.1 "
                        "Monte Carlo standard errors of this run")
    p.add_argument("--workers", type=_integer(1, MAX_WORKERS), default=None,
                   help="processes that run the blocks of paths (default: every core; at "
                        "most the cores this process may use unless --force-workers); the "
                        "numbers are the same for any count")
    _force_workers(p)
    p.add_argument("--scheduler", type=_scheduler, default=None, metavar="ADDRESS",
                   help="run the blocks of paths on a Dask cluster: its scheduler's address "
                        "(e.g. tcp://host:8786), or local for a local cluster of --workers "
                        "processes; the numbers are the same as without")
    p.add_argument("--check", action="store_true",
                   help=f"exit with status {EXIT_DISAGREE} unless the verdict is that the "
                        "Monte Carlo run and the oracle agree")
    p.add_argument("--json", action="store_true")
    p.add_argument("--ignore-noise", action="store_true")
    p.add_argument("--fault", type=_fault, action="append", metavar="KEY=VALUE",
                   help="a fault of the loop, as in the file's [faults] (which it overrides): "
                        "sensor_noise, sensor_quantum, delay_ticks, miss_probability, "
                        "actuator_noise, plant_A_scale, plant_B_scale, plant_noise_scale; "
                        "a vector as comma-separated numbers; repeat for several")
    p.add_argument("--x0", type=_x0, help="start the plant from this state instead of the problem's "
                                "(comma-separated; write --x0=-5,0,1,0 when it starts with a minus); the tables stay the design's and the "
                                "controller latches from what it measures")
    p.set_defaults(func=_simulate)

    p = sub.add_parser("corridor-design",
                       help="the cheapest design whose paths stay in the corridor with "
                            "probability 1 - epsilon, certified by Monte Carlo")
    p.add_argument("problem", help="problem file (TOML) with one corridor that has epsilon")
    p.add_argument("--epsilon", type=_probability, default=None,
                   help="the risk budget of the file's only corridor (overrides its epsilon)")
    p.add_argument("--search", type=_integer(1, MAX_PATHS), default=30_000, metavar="N",
                   help="Monte Carlo paths screening each grid point (default 30000)")
    p.add_argument("--certify", type=_integer(1, MAX_PATHS), default=1_000_000, metavar="N",
                   help="fresh Monte Carlo paths certifying the chosen point (default 10^6)")
    p.add_argument("--seed", type=_integer(0, SEED_MAX), default=20261126,
                   help="seed of the screening runs (default 20261126)")
    p.add_argument("--certify-seed", type=_integer(0, SEED_MAX), default=20261127,
                   help="seed of the certification runs (default 20261127; must differ "
                        "from --seed)")
    p.add_argument("--attempts", type=_integer(1, 1000), default=3,
                   help="certification runs at most (the next cheapest point that passes "
                        "screening after a failed one; default 3)")
    p.add_argument("--refine", type=_integer(0, 20), default=0, metavar="K",
                   help="bisect K times between the last failing and the first passing grid "
                        "point before certifying (each a screening; default 0: the grid only)")
    p.add_argument("--strip", type=_weights, default=(0.0, 2.0, 5.0, 10.0, 20.0, 40.0),
                   metavar="W,W,...", help="grid of centre-line weights w (default "
                                           "0,2,5,10,20,40)")
    p.add_argument("--rate", type=_weights, default=(0.0, 0.5, 1.0, 2.0, 5.0),
                   metavar="WV,WV,...", help="grid of velocity-damping weights wv (default "
                                             "0,0.5,1,2,5)")
    p.add_argument("--substeps", type=_integer(1, MAX_SUBSTEPS), default=1,
                   help="plant steps per controller tick (default 1)")
    p.add_argument("--workers", type=_integer(1, MAX_WORKERS), default=None)
    _force_workers(p)
    p.add_argument("--scheduler", type=_scheduler, default=None, metavar="ADDRESS")
    p.add_argument("--out", type=_out_dir,
                   help="directory for <name>.toml (the designed problem), <name>.{c,h,json} "
                        "(its tables) and <name>_corridor.json (the certificate), written "
                        "together or not at all")
    p.add_argument("--json", action="store_true", help="print the certificate as JSON")
    p.set_defaults(func=_corridor_design)

    # Commands that write one file from a Monte Carlo run: (name, help, --out type and help,
    # default paths, function).
    for name, text, out_type, out_help, paths, func in (
            ("report", "one self-contained HTML page: design, Monte Carlo, verdict, figures",
             _out_html, "the page, a .html file (its directory must exist)", 2000, _report),
            ("plot", "figure: corridor, one realisation, MC mean, controls (of a [plant] "
                     "problem: on the model)", _out_file,
             "figure file: .png, .pdf or .svg (its directory must exist)", 100, _plot)):
        p = sub.add_parser(name, help=text)
        p.add_argument("problem")
        p.add_argument("--out", required=True, type=out_type, help=out_help)
        p.add_argument("--paths", type=_integer(2, MAX_PATHS), default=paths)
        p.add_argument("--seed", type=_integer(0, SEED_MAX), default=1)
        p.add_argument("--substeps", type=_substeps, default="auto")
        p.add_argument("--workers", type=_integer(1, MAX_WORKERS), default=None)
        _force_workers(p)
        p.add_argument("--scheduler", type=_scheduler, default=None, metavar="ADDRESS")
        p.add_argument("--fault", type=_fault, action="append", metavar="KEY=VALUE",
                       help="a fault of the loop (see simulate --help)")
        if name == "report":
            p.add_argument("--fault-paths", type=_integer(0, MAX_PATHS), default=500,
                           help="paths of each run of the fault table (each fault at a few "
                                "levels); 0: no fault table")
        p.set_defaults(func=func)
    from stospline.board.cli import add_commands as _board_commands    # board, hil
    _board_commands(sub, sys.modules[__name__])
    for name, sp in sub.choices.items():
        _common(sp)
        sp.add_argument("--discretization", choices=["exact-zoh", "continuous"],
                        default=None,
                        help="exact-zoh (default): optimal for the held control at the tick "
                             "rate; continuous: sample the continuous-time gains. Default: "
                             "the file's [design] discretization")
        sp.add_argument("--mode", choices=["stagewise", "joint"], default=None,
                        help="stagewise (default): re-plan the multipliers at every stage "
                             "start; joint: one multiplier vector for all knots, latched at t0 "
                             "(needed for bands). Default: the file's [design] mode")
        sp.add_argument("--table", choices=list(TABLE_KINDS), default=None,
                        help="per-tick (default): one row of gains per tick; spline: the gains "
                             "as cubic B-splines per stage, ~100x smaller, latch maps re-solved "
                             "for the law as evaluated (float32; written as "
                             "<name>_spline.{c,h,json}). Default: the file's [design] table")
        sp.add_argument("--spline-tolerance", default=None, metavar="TOL",
                        help="the spline's budget: largest relative error of a gain entry, "
                             "2^-21 (4.77e-7, four float32 roundings)..0.1 (default: the file's "
                             "[design] spline_tolerance, else "
                             f"{DEFAULT_SPLINE_TOLERANCE:g})")
        sp.add_argument("--delay-ticks", default=None, metavar="{0,1}",
                        help="1: design for a one-tick computation delay (the command computed "
                             "from the state at tick j is applied at tick j+1; the controller "
                             "is fed [x; the command being applied], docs/guide/firmware.md). "
                             "Default: the file's [design] delay_ticks, else 0")
    return ap


def _plant_run(args, d, faults=None):
    """Monte Carlo of `d` (a [plant] problem's linearisation) on the model itself
    (`stospline.nonlinear.simulate.run_on_model`), in a loop with `faults` (default
    ``d.problem.faults``); ``--substeps auto`` decides the count on the model."""
    from stospline.nonlinear.simulate import run_on_model
    spread = [name for name, given in (("--workers", getattr(args, "workers", None)),
                                       ("--scheduler", getattr(args, "scheduler", None)))
              if given is not None]
    if spread and not getattr(args, "_model_noted", False):
        args._model_noted = True
        print(f"stospline: note: the Monte Carlo on the [plant] model runs in this one process; "
              f"{' and '.join(spread)} do not spread it", file=sys.stderr)
    substeps = "auto" if args.substeps == "auto" else int(args.substeps)
    return run_on_model(d, _PLANT_FIT[0].model, paths=args.paths, seed=args.seed,
                        substeps=substeps, faults=faults)


def _simulate_plant(args, d) -> int:
    """`simulate` of a [plant] problem (`stospline.nonlinear.simulate`): Monte Carlo on the
    model, against the oracle of its linearisation."""
    from stospline.nonlinear.simulate import plant_simulation_text, plant_summary
    s = plant_summary(d, _plant_run(args, d))
    print(dumps(s) + "\n" if args.json else plant_simulation_text(s), end="", flush=True)
    return 0 if (s["verdict"]["agree"] or not args.check) else EXIT_DISAGREE


def main(argv: list[str] | None = None) -> int:
    """The command line; returns the exit status (module docstring)."""
    restore = None
    try:                              # first: a Ctrl-C from here on ends in one line, also
        restore = _catch_interrupts()  # one that comes before the handler is in place
        return _main(argv)
    except BaseException as exc:
        # After a SIGINT, whatever ends the run is its consequence: numpy, for one, turns an
        # interrupt during its import into an ImportError.
        if not (isinstance(exc, KeyboardInterrupt) or _INTERRUPTED):
            raise
        print("stospline: interrupted", file=sys.stderr)
        return 130
    finally:
        if restore is not None:
            restore()


_INTERRUPTED: list[int] = []     # SIGINTs received while `main` runs


def _on_interrupt(signum, frame):
    _INTERRUPTED.append(signum)
    raise KeyboardInterrupt


def _catch_interrupts():
    """Record and raise on SIGINT while `main` runs, unless SIGINT is ignored (a background
    job) or handled by someone else, or this is not the main thread; returns what restores
    the previous handler."""
    import threading
    _INTERRUPTED.clear()
    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    old = signal.getsignal(signal.SIGINT)
    if old not in (signal.SIG_DFL, signal.default_int_handler):
        return lambda: None
    signal.signal(signal.SIGINT, _on_interrupt)
    return lambda: signal.signal(signal.SIGINT, old)


def _fault_option(args, exc: ProblemError) -> ProblemError:
    """An error on ``faults.KEY`` names ``--fault KEY`` when the command line set that key."""
    key = exc.field.partition(".")[2] if exc.field.startswith("faults.") else None
    if key and key in dict(getattr(args, "fault", None) or []):
        return ProblemError(f"--fault {key}", exc.reason)
    return exc


def _one_line(text: str) -> str:
    """`text` on one line (a compiler's message spans several)."""
    return " ".join(line.strip() for line in text.splitlines() if line.strip())


def _main(argv: list[str] | None) -> int:
    from stospline.atomic import Interrupted, OutputError
    from stospline.cache import CompilerMissing
    args = build_parser().parse_args(argv)
    if getattr(args, "arith", None) not in (None, *ARITHS):
        print(f"stospline: error: --arith must be one of {list(ARITHS)}, "
              f"got {args.arith!r}", file=sys.stderr)
        return 2
    progress.enable(not args.quiet and sys.stderr.isatty())
    try:
        return args.func(args)
    except ProblemError as exc:
        exc = _fault_option(args, exc)
        where = "" if exc.field.startswith("--") else f" in {args.problem}"
        print(f"stospline: error{where}: {exc}", file=sys.stderr)
        return 2
    except OutputError as exc:
        print(f"stospline: error: --out: {exc.reason}", file=sys.stderr)
        return 2
    except CompilerMissing as exc:
        print(f"stospline: error: {args.command} needs a C compiler to build the controller "
              f"it runs: {exc}", file=sys.stderr)
        return 2
    except FileNotFoundError as exc:
        print(f"stospline: error: {exc}", file=sys.stderr)
        return 2
    except Interrupted as exc:
        print(f"stospline: {exc}; nothing was written", file=sys.stderr)
        return 128 + exc.signum
    except StosplineError as exc:         # every other exception of the package
        print(f"stospline: error: {_one_line(str(exc))}", file=sys.stderr)
        return 2
    except MemoryError:
        print("stospline: error: out of memory (the estimate of docs/guide/problem-file.md, "
              "Limits, was too low for this machine; try --max-memory lower or a smaller "
              "problem)", file=sys.stderr)
        return 1
    finally:
        progress.close_all()


if __name__ == "__main__":
    sys.exit(main())
