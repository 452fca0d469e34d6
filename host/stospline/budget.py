"""Memory and time a command will need, estimated from the problem's sizes before any work.

`estimate` adds up the costs that grow with the problem (per tick, per stage, per matrix
exponential, per generated number, per Monte Carlo path and tick); `check` refuses a run whose
estimate exceeds the limits with a `BudgetError` naming the key that causes the largest part,
e.g. ``tick_hz: ~15.2 GiB of memory needed (limit 4 GiB): 1000000000 ticks x 18 numbers of
per-tick gain tables ...``. Nothing is allocated before the check.

The constants were measured on the development machine (2 shared x86-64 cores, OpenBLAS) with
``tools/bench/calibrate_budget.py``, which prints them and the estimate beside the measured time and
peak memory of a set of designs and simulations. They are estimates: expect the real figures
within a factor of about 3 (more on a loaded or much slower machine). Limits (documented in
docs/guide/problem-file.md, "Limits"): `DEFAULT_MAX_SECONDS` and `DEFAULT_MAX_BYTES`, raised with
``--max-time``/``--max-memory``; the memory limit is never above the machine's RAM.

What grows (n states, m inputs, d = n + m + 1, D = d^2, T ticks, S stages, q multipliers):

* the oracle's exact tick map per stage, a (2D)-square matrix exponential (n = 24, m = 8:
  about 10 s and 300 MiB each; n = 200: 53 GiB), evaluated twice per design;
* the oracle's per-tick propagation, a D x D product per tick, twice per design;
* the designer's tick map per distinct stage data, a (d(d+1)/2 + 1)-square exponential, and
  its per-tick recursion (with q^2 m terms for q joint multipliers);
* the per-tick tables (several double copies) and their C text (about 14 bytes a number,
  formatted at about 2 us a number, and compiled by ``simulate``/``plot``);
* Monte Carlo: per tick a Python step, per path and tick the C controller and plant, per path,
  tick and corridor wall the exit watch; each forked worker process its own memory; memory
  for a block of paths at a time, not for the run's paths (the statistics stream);
* the corridors' exit bounds: one oracle pass recording output (or state) moments, then each
  corridor's walls at its ticks;
* the tick-grid QP of regions at every tick: its sparse LU per tick, growing with the square of
  the rows per tick (those between ticks included), and the rows between ticks built in Python;
* plot and report: matplotlib and the figures.
"""
from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field

import numpy as np

from stospline.errors import BudgetError
from stospline.problem.model import Problem, ProblemError

__all__ = ["BudgetError", "Term", "Estimate", "estimate", "check", "enforce",
           "monte_carlo_terms", "check_limits", "DEFAULT_MAX_SECONDS", "DEFAULT_MAX_BYTES",
           "DEFAULT_MAX_GIB", "machine_memory", "format_bytes", "format_seconds"]

DEFAULT_MAX_SECONDS = 600.0          # 10 minutes
DEFAULT_MAX_BYTES = 4 * 1024 ** 3    # 4 GiB
DEFAULT_MAX_GIB = DEFAULT_MAX_BYTES / 1024 ** 3     # the library's max_memory, in GiB

# --- measured constants (tools/bench/calibrate_budget.py) --------------------------------------
BASE_BYTES = 50e6           # interpreter, numpy, cffi, the package (a robot design whose C is
                            # cached peaks at ~50 MiB, its simulation at ~70 MiB with the workers)
BUILD_BYTES = 110e6         # a first run's C build (the design's kernels, the controller): cffi's
                            # build machinery in the process and the compiler's process, freed
                            # after it; a cold robot design peaks at ~137 MiB, its first
                            # simulation at ~135 MiB (COMPILE_BYTES: larger tables' compiler)
BASE_SECONDS = 3.0          # start-up: imports, the cached C kernel
STAGE_SECONDS = 4e-3        # Python work per stage and oracle pass (maps, latches, knots)
EXPM_S3 = 1.0e-9            # s: scipy expm of an s-square matrix ~ EXPM_S3 s^3 + EXPM_S2 s^2
EXPM_S2 = 1.5e-6
EXPM_COPIES = 8             # expm workspace: ~8 s-square double arrays
ORACLE_TICK = 15e-6         # s per tick and oracle pass: Python overhead ...
ORACLE_TICK_D2 = 1.5e-9     # ... + per entry of the D x D tick map
KERNEL_FLOP = 1.0e-9        # s per multiply-add of the designer's C tick recursion
VARYING_TICK = 60e-6        # s per tick of time-varying data (numpy loop) + its exponential
IVP_TICK = 2.5e-3           # s per tick and oracle pass of time-varying data (DOP853)
TABLE_COPIES = 5            # double copies of the per-tick gains (design, law, table, ...)
CODEGEN_NUMBER = 2.0e-6     # s to format one table number as C
CODEGEN_BYTES = 48          # peak bytes per number while the C text is built (~14 in the file)
COMPILE_NUMBER = 4.0e-6     # s for the C compiler per table number (simulate, plot)
COMPILE_BYTES = 400         # compiler memory per table number
TICK_QP_TICK = 6e-4         # s per tick of the tick-grid QP (regions at every tick), n + m = 6
TICK_QP_BYTES = 15e3        # peak bytes per tick of it (sparse LU of the KKT matrix), n + m = 6
TICK_QP_ROW = 2.5e-3        # s per row between ticks (its Bernstein form, built in Python)
TICK_QP_ROW_BYTES = 1500    # bytes per row of the QP (the row object, its sparse entries)
SIM_TICK = 10e-6            # s per Monte Carlo tick and block of paths: the Python step
SIM_BLOCK = 0.5e-3          # s per block of paths: its instances, stream and statistics
SIM_PATH_TICK = 1.0e-9      # s per path, tick and unit of work (below), on one core
# CPU seconds of the Monte Carlo on a [plant] model (`harness.user_plant.simulate_model`, in
# one process) per path and tick: a fixed part (the controller, the bookkeeping) and a part
# per plant step (the coarse run and its check at twice the steps). The unicycle at 200 Hz,
# 2000 paths, one core (tools/bench/model_loop.py): 0.74 us per path-tick at 1 step, 1.82 at 4.
MODEL_PATH_TICK, MODEL_PATH_STEP = 3.8e-7, 3.6e-7
# Bytes per path of a run on a [plant] model, which holds every path at once: the two
# controller instances (the run and its check at half steps) and numpy's temporaries, besides
# the states, knots and normal numbers counted from the sizes. Measured: the docs' linear
# model (n = 2, mz = 1, 4 substeps) grows by 2.2 kB per path from 10^4 to 2.10^5 paths.
MODEL_PATH_BYTES = 2048
                            # (tools/bench/harness_throughput.py: ~95 ns per robot path-tick)
SIM_PATH_BYTES = 64         # bytes per path besides states (instances, buffers)
# The sensor loop's Monte Carlo (a [measurement] problem: `harness.sensor_blocks`, blocks of
# SENSOR_BLOCK_PATHS paths; `harness.estimator_loop.simulate_estimator`): per tick and block
# its numpy and cffi calls, per path and tick its numpy work (the sensor's readings, the exit
# watch, the sums) and the filter's C step, on top of the C work counted as for the full
# state (SIM_PATH_TICK, the exit watch). Fitted by ``PYTHONPATH=host .venv/bin/python
# tools/bench/sensor_loop_rate.py`` (the robot with its position sensor, 6000 ticks, one
# core, CPU time on a loaded machine): 433 ns per path-tick against 28 ns for the full-state
# harness timed in the same run (15x); 72 us per tick and block, 274 ns per path-tick beyond
# the 124 ns of full-state work this module counts (which overstates the full state's 28 ns).
SENSOR_TICK = 70e-6         # s per tick and block of paths
SENSOR_PATH_TICK = 275e-9   # s per path and tick beyond the full-state harness's C work
CONTINUOUS_STAGE = 0.5      # s per stage of the continuous-time design and its oracle
CONTINUOUS_TICK = 20e-6     # s per tick to sample continuous gains
BAND_Q3 = 5e-8              # s per q^3 of the band dual (OSQP on dense W)
CORRIDOR_WALL = 10e-9       # s per path, tick and corridor wall: the C harness's exit watch
CORRIDOR_BOUND_WALL = 1e-6  # s per tick and wall of a corridor's exit bounds (report)
CORRIDOR_BOUND_COPIES = 12  # (ticks, walls) double arrays alive while one corridor is bounded
WORKER_BYTES = 15e6         # a forked Monte Carlo worker's own pages besides its block (it
                            # shares the rest copy-on-write: ~10 MiB private, ~23 MiB of PSS)
FIGURE_BYTES = 150e6        # matplotlib and the figures of a plot or report
FIGURE_SECONDS = 4.0        # importing matplotlib, drawing and encoding the figures


@dataclass(frozen=True)
class Term:
    """One cost: what it is, the key that drives it, its time (s) and peak memory (bytes);
    `transient` memory is freed when its step ends (a matrix exponential's workspace, the
    compiler's), so only the largest such term counts."""
    what: str
    key: str
    seconds: float = 0.0
    bytes: float = 0.0
    transient: bool = False


@dataclass
class Estimate:
    """Estimated seconds and peak bytes of a command, with the terms they come from."""
    command: str
    terms: list[Term] = field(default_factory=list)

    @property
    def seconds(self) -> float:
        return sum(t.seconds for t in self.terms)

    @property
    def bytes(self) -> float:
        # Tables and text stay resident; one exponential's workspace or one build at a time
        # on top (a first run builds its C: the kernels, the controller).
        resident = sum(t.bytes for t in self.terms if not t.transient)
        transient = max([t.bytes for t in self.terms if t.transient] + [BUILD_BYTES])
        return BASE_BYTES + resident + transient

    def top(self, by: str) -> Term:
        return max(self.terms, key=lambda t: getattr(t, by))

    def summary(self) -> str:
        return (f"estimated ~{format_seconds(self.seconds)} and ~{format_bytes(self.bytes)} "
                f"(mostly {self.top('seconds').what})")


def format_bytes(b: float) -> str:
    for unit, size in (("GiB", 1024 ** 3), ("MiB", 1024 ** 2), ("KiB", 1024)):
        if b >= size:
            return f"{b / size:.3g} {unit}"
    return f"{b:.0f} B"


def format_seconds(s: float) -> str:
    if s >= 86400:
        return f"{s / 86400:.3g} days"
    if s >= 3600:
        return f"{s / 3600:.3g} h"
    if s >= 60:
        return f"{s / 60:.3g} min"
    return f"{s:.2g} s"


def machine_memory() -> float:
    """Physical memory of this machine in bytes (inf when unknown)."""
    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return math.inf


def _expm(s: float) -> tuple[float, float]:
    return EXPM_S3 * s ** 3 + EXPM_S2 * s ** 2, EXPM_COPIES * 8.0 * s * s


def _dims_key(problem: Problem) -> str:
    """The key that sets the matrix sizes: x0 (n) unless the inputs (dynamics.B) dominate."""
    return "x0" if problem.n >= problem.m else "dynamics.B"


def _widths(problem: Problem, mode: str) -> tuple[list[int], int]:
    """Per stage the width q of the multiplier vector the design carries, and the table's
    n_latch."""
    from stospline.design.bands import has_bands
    from stospline.design.latch import latch_groups
    from stospline.table.format import BANDQP_MAX
    rows = sum(kn.n_constraints for kn in problem.knots)
    if has_bands(problem):
        q = [rows] * len(problem.knots)         # joint: one vector over every stage
        return q, rows if rows <= BANDQP_MAX else min(rows, problem.n)
    try:
        _, group_of = latch_groups(problem, mode)
    except ValueError:
        group_of = [None] * len(problem.knots)
    q = [0 if g is None else g.size for g in group_of]
    return q, min(max(q + [0]), problem.n)


def estimate(problem: Problem, *, command: str = "design", mode: str = "stagewise",
             discretization: str = "exact-zoh", arith: str = "float32", paths: int = 0,
             substeps: int = 2, delay_ticks: int = 0, table: str = "per-tick",
             spline_tolerance: float | None = None, workers: int = 1,
             record: int = 0, model: bool = False) -> Estimate:
    """Estimate the time and peak memory of ``stospline COMMAND`` on `problem`.

    A design for a one-tick delay (`delay_ticks` 1) is counted as one of ``n + m`` states.
    A spline table (`table`, `spline_tolerance`) is counted as a per-tick one: its fit takes
    a fraction of the design (docs/evidence/spline-tables.md) and its C text is smaller.

    Parameters
    ----------
    command : {"design", "simulate", "plot", "report"}
    paths, substeps : int
        The Monte Carlo run of simulate, plot and report.
    workers : int
        Processes that run its blocks of paths at once (each counted with its own memory).
    record : int
        Paths whose states are kept at every tick (a report's percentile bands).
    model : bool
        The Monte Carlo runs on the problem's [plant] model (its own loop, one process), not
        on the linear harness.
    """
    n, m, mz = problem.n, problem.m, problem.mz
    n += m * (delay_ticks == 1)
    d = n + m + 1
    D = d * d
    ds, vs = d * (d + 1) // 2, (n + 1) * (n + 2) // 2
    ticks = [int(t) for t in problem.ticks_per_stage]
    T, S = sum(ticks), len(ticks)
    q, n_latch = _widths(problem, mode)
    qmax = max(q + [0])
    dims, stages = _dims_key(problem), "knots"
    varying = [st.varying is not None for st in problem.stages]
    T_var = sum(t for t, v in zip(ticks, varying) if v)
    distinct = len({id(st) for st, v in zip(problem.stages, varying) if not v})
    est = Estimate(command)
    add = est.terms.append
    passes = 2 + (arith != "float32") + (command == "plot")     # oracle passes over the ticks

    add(Term("start-up (imports, compiled kernels)", "--max-time", seconds=BASE_SECONDS))
    add(Term("per-stage work (tick maps, latches, knots)", stages,
             seconds=STAGE_SECONDS * S * (passes + 1)))
    # The design's per-tick gains (several double copies) and the table.
    numbers = T * m * (n + 1 + n_latch)
    add(Term("per-tick gain tables", "tick_hz",
             bytes=TABLE_COPIES * 8.0 * sum(t * m * (n + 1 + max(qk, n_latch))
                                            for t, qk in zip(ticks, q))))
    if discretization == "continuous":
        add(Term("continuous-time design and its oracle", stages,
                 seconds=CONTINUOUS_STAGE * S * (1 + (n * n + n * qmax + qmax * qmax) / 64)))
        add(Term("sampling the continuous gains at the ticks", "tick_hz",
                 seconds=CONTINUOUS_TICK * T * (1 + (n + qmax) / 8),
                 bytes=8.0 * T * (n * n + n + 1 + n * qmax + qmax * qmax)))
    else:
        sec, byt = _expm(ds + 1)
        add(Term("tick map of the design (matrix exponential per distinct stage data)", dims,
                 seconds=distinct * sec, bytes=byt + 4 * 8.0 * D * D, transient=True))
        flops = ds * vs + 2 * qmax * n * d + qmax * qmax * m + m * m * (n + 1 + qmax)
        add(Term("the design's tick recursion", "tick_hz",
                 seconds=KERNEL_FLOP * flops * (T - T_var) + VARYING_TICK * T_var
                 * (1 + (D + 1) ** 3 / 1e5)))
    if problem.tick_regions:
        add(_tick_qp_term(problem, n, m, T))
    sec, byt = _expm(2 * D)
    add(Term("tick map of the oracle (matrix exponential per stage and pass)", dims,
             seconds=passes * sec * (S - sum(varying)), bytes=byt + 4 * 8.0 * D * D,
             transient=True))
    add(Term("the oracle's propagation over the ticks", "tick_hz",
             seconds=passes * ((ORACLE_TICK + ORACLE_TICK_D2 * D * D) * (T - T_var)
                               + IVP_TICK * (1 + D / 50) * T_var),
             bytes=(command == "plot") * T * 2 * (8 * n + 112.0)))
    if qmax:
        add(Term("joint multipliers (W is q x q)", stages,
                 seconds=BAND_Q3 * qmax ** 3, bytes=6 * 8.0 * qmax * qmax))
    if command == "design":
        add(Term("C text of the tables", "tick_hz", seconds=CODEGEN_NUMBER * numbers,
                 bytes=CODEGEN_BYTES * numbers))
    else:
        add(Term("C text of the tables, compiled", "tick_hz",
                 seconds=(CODEGEN_NUMBER + COMPILE_NUMBER) * numbers,
                 bytes=CODEGEN_BYTES * numbers))
        add(Term("the C compiler on the tables", "tick_hz", bytes=COMPILE_BYTES * numbers,
                 transient=True))
        est.terms += monte_carlo_terms(problem, paths=paths, substeps=substeps,
                                       workers=workers, record=record, n_latch=n_latch,
                                       delay_ticks=delay_ticks, model=model)
    if command in ("plot", "report"):
        add(Term("figures (matplotlib)", "--out", seconds=FIGURE_SECONDS, bytes=FIGURE_BYTES))
    return est


def monte_carlo_terms(problem: Problem, *, paths: int, substeps: int = 2, workers: int = 1,
                      record: int = 0, n_latch: int | None = None,
                      delay_ticks: int = 0, model: bool = False) -> list[Term]:
    """The Monte Carlo run's terms: its paths (with their corridor watch and `workers` forked
    processes, each running a block of `harness.montecarlo.BLOCK_PATHS` paths), the oracle of the
    plant scheme, and the corridors' exit bounds of its summary. On the linear harness its
    memory does not grow with `paths`: one block's paths at a time per process, and the
    statistics of the blocks handed out ahead (`harness.montecarlo`) waiting to be merged.
    On a [plant] model (`model`) every path is held at once, in one process. With a
    [measurement] table the paths run the sensor loop (`SENSOR_TICK`, `SENSOR_PATH_TICK`),
    in blocks of `harness.sensor_blocks.SENSOR_BLOCK_PATHS`."""
    from stospline.harness.montecarlo import _AHEAD_PER_WORKER, BLOCK_PATHS
    n, m, mz = problem.n, problem.m, problem.mz
    n += m * (delay_ticks == 1)
    if n_latch is None:
        n_latch = _widths(problem, "joint" if problem.tick_regions else "stagewise")[1]
    ticks = [int(t) for t in problem.ticks_per_stage]
    T, S = sum(ticks), len(ticks)
    D = (n + m + 1) ** 2
    watch = _corridor_walls(problem)
    work = n * (m + n_latch) + substeps * (n * n + n * m + n * mz) + 8
    blocks = -(-paths // BLOCK_PATHS)
    workers = max(1, min(int(workers), blocks))
    per_path = (8.0 * n * (S + 6) + 16.0 * substeps * mz + 16.0 * m + SIM_PATH_BYTES
                + 16.0 * len(problem.corridors))        # exit tick and wall, and their copies
    per_run = T * 3 * (8 * n + 112.0) + T * min(record, BLOCK_PATHS, paths) * (n + m) * 4.0
    block = min(paths, BLOCK_PATHS) * per_path
    waiting = (_AHEAD_PER_WORKER * workers if workers > 1 else 1) * 8.0 * (T + 1) * n
    if model:                   # the model's own loop: one process, every path at once
        workers = 1
        model_path = MODEL_PATH_BYTES + 8.0 * (3 * substeps * mz + n * (2 * S + 4 * substeps + 8))
        terms = [Term(f"Monte Carlo on the [plant] model ({paths} paths)", "--paths",
                      seconds=paths * T * (MODEL_PATH_TICK + substeps * MODEL_PATH_STEP),
                      bytes=paths * model_path + per_run)]
    elif getattr(problem, "measurement", None) is not None:
        from stospline.harness.sensor_blocks import SENSOR_BLOCK_PATHS
        sensor_blocks = -(-paths // SENSOR_BLOCK_PATHS)
        terms = [Term(f"Monte Carlo of the sensor loop ({paths} paths)", "--paths",
                      seconds=(SENSOR_TICK * T + SIM_BLOCK) * sensor_blocks
                      + (SENSOR_PATH_TICK + SIM_PATH_TICK * work) * paths * T,
                      bytes=min(paths, SENSOR_BLOCK_PATHS) * per_path + per_run + waiting)]
    else:
        terms = [Term(f"Monte Carlo ({paths} paths)", "--paths",
                      seconds=(SIM_TICK * T + SIM_BLOCK) * blocks
                      + SIM_PATH_TICK * paths * T * work, bytes=block + per_run + waiting)]
    if problem.corridors:
        terms.append(Term(f"the paths' exit watch of {len(problem.corridors)} corridors",
                          "corridors", seconds=CORRIDOR_WALL * paths * watch))
    if workers > 1:
        terms.append(Term(f"{workers} Monte Carlo worker processes", "--workers",
                          bytes=workers * (WORKER_BYTES + min(paths, BLOCK_PATHS) * per_path
                                           + per_run)))
    sec, _ = _expm(D)
    terms.append(Term("the oracle of the plant scheme", "tick_hz",
                      seconds=(ORACLE_TICK + ORACLE_TICK_D2 * D * D) * T
                      + S * (substeps * 2e-9 * D ** 3 + sec)))
    if problem.corridors:
        terms.append(_corridor_bounds_term(problem, n, m, T))
    return terms


def _corridor_walls(problem: Problem) -> float:
    """Sum over the corridors of their ticks times their walls (each wall a p-vector)."""
    from stospline.problem.corridors import corridor_ticks
    total = 0.0
    for c in problem.corridors:
        lo, hi = corridor_ticks(c, problem.t0, problem.tick_hz)
        total += (hi - lo + 1) * len(c.b) * max(1.0, c.p / 2)
    return total


def _corridor_bounds_term(problem: Problem, n: int, m: int, T: int) -> Term:
    """The corridors' exit bounds (`oracle.exit_bound.corridor_outputs`): one oracle pass that
    records the outputs' (or, for more rows than states, the state's) moments at every
    tick, then each corridor's walls at its ticks, one corridor at a time."""
    from stospline.problem.corridors import corridor_ticks
    D = (n + m + 1) ** 2
    rows = sum(c.p for c in problem.corridors)
    q = rows if rows <= n else n
    widest = 0.0
    for c in problem.corridors:
        lo, hi = corridor_ticks(c, problem.t0, problem.tick_hz)
        widest = max(widest, (hi - lo + 1) * (CORRIDOR_BOUND_COPIES * len(c.b) + 4 * c.p * c.p))
    return Term(f"exit bounds of {len(problem.corridors)} corridors", "corridors",
                seconds=(ORACLE_TICK + ORACLE_TICK_D2 * D * D) * T
                + CORRIDOR_BOUND_WALL * _corridor_walls(problem),
                bytes=T * (2 * 8.0 * (q * q + q) + 2 * 112.0) + 8.0 * widest)


def _chain_degree(problem: Problem) -> int:
    """The largest nilpotency index of the stages' A (n when one is not nilpotent): the
    degree of the mean over a tick, whose interior Bernstein coefficients are rows between
    ticks (`design.tick_qp`)."""
    n = problem.n
    worst = 1
    for st in problem.stages:
        A = np.asarray(st.A, float)
        P, k = A.copy(), 1
        while k < n and np.any(P):
            P, k = P @ A, k + 1
        worst = max(worst, k if not np.any(P) else n)
    return worst


def _tick_qp_term(problem: Problem, n: int, m: int, T: int) -> Term:
    """The tick-grid QP of regions at every tick (`design.tick_qp`), when constraint
    generation needs it: its KKT matrix has per tick the n + m variables, n dynamics rows and
    two rows per bound row (at the tick and between ticks); its sparse LU grows with the square
    of that width (calibrated at 14, the robot with two region rows)."""
    t0, hz = problem.t0, problem.tick_hz
    degree = _chain_degree(problem)
    rows = between = 0
    for reg in problem.tick_regions:
        ticks = len(reg.ticks(t0, hz))
        rows += ticks * len(reg.C)
        if reg.between:
            between += ticks * len(reg.C) * max(0, degree - 1)
    width = 2 * n + m + 2 * (rows + between) / max(T, 1)
    grow = (width / 14) ** 2
    return Term("regions at every tick (the QP on the tick grid, if needed)", "tick_hz",
                seconds=TICK_QP_TICK * T * grow + TICK_QP_ROW * between,
                bytes=TICK_QP_BYTES * T * grow + TICK_QP_ROW_BYTES * (rows + between))


def check(problem: Problem, *, max_seconds: float = DEFAULT_MAX_SECONDS,
          max_bytes: float = DEFAULT_MAX_BYTES, library: bool = False, **options) -> Estimate:
    """`estimate` and refuse (BudgetError) what exceeds `max_bytes` (capped at the machine's
    memory) or `max_seconds`. Returns the estimate."""
    return enforce(estimate(problem, **options), problem, max_seconds=max_seconds,
                   max_bytes=max_bytes, library=library, **options)


def enforce(est: Estimate, problem: Problem, *, max_seconds: float = DEFAULT_MAX_SECONDS,
            max_bytes: float = DEFAULT_MAX_BYTES, library: bool = False,
            **options) -> Estimate:
    """Refuse (BudgetError) an estimate `est` beyond the limits, as `check` does. `library`:
    name the library's arguments (``paths``, ``max_memory``) instead of the command line's
    options (``--paths``, ``--max-memory``)."""
    limit = min(float(max_bytes), machine_memory())
    for kind, need, cap, fmt, what in (
            ("bytes", est.bytes, limit, format_bytes,
             "needs ~{need} of memory (limit {cap}; --max-memory raises it up to this "
             "machine's RAM)"),
            ("seconds", est.seconds, max_seconds, format_seconds,
             "would take ~{need} (limit {cap}; --max-time raises it)")):
        if need > cap:
            top = est.top(kind)
            message = (f"the {est.command} " + what.format(need=fmt(need), cap=fmt(cap))
                       + f", mostly for {top.what} (~{fmt(getattr(top, kind))}) "
                       f"{_sizes(problem, top.key, options)}")
            if library:
                message = re.sub(r"--([a-z-]+)", lambda g: g[1].replace("-", "_"), message)
            raise BudgetError(_argument(top.key) if library else top.key, message)
    return est


def _argument(key: str) -> str:
    """A command-line option's library argument (``--max-time`` -> ``max_time``)."""
    return key[2:].replace("-", "_") if key.startswith("--") else key


def check_limits(max_memory, max_time) -> tuple[float, float]:
    """The library's `max_memory` (GiB) and `max_time` (seconds) as ``(bytes, seconds)``;
    ProblemError naming the argument unless each is a number > 0 (at most 1e6 GiB, 1e9 s,
    as on the command line)."""
    out = []
    for name, value, hi in (("max_memory", max_memory, 1e6), ("max_time", max_time, 1e9)):
        if (isinstance(value, bool) or not isinstance(value, (int, float, np.integer,
                                                              np.floating))
                or not 0 < float(value) <= hi):
            raise ProblemError(name, f"must be a number in (0, {hi:g}], got {value!r}")
        out.append(float(value))
    return out[0] * 1024 ** 3, out[1]


def _sizes(problem: Problem, key: str, options: dict) -> str:
    """The sizes behind a key, for the message."""
    T = int(np.sum(problem.ticks_per_stage))
    if key == "tick_hz":
        return f"with {T} ticks (tick_hz = {problem.tick_hz})"
    if key in ("x0", "dynamics.B"):
        return f"with n = {problem.n} states and m = {problem.m} inputs"
    if key == "--paths":
        return f"with {options.get('paths')} paths over {T} ticks"
    if key in ("--search", "--certify"):          # corridor-design's Monte Carlo runs
        return f"over {T} ticks"
    if key == "corridors":
        walls = sum(len(c.b) for c in problem.corridors)
        return f"with {len(problem.corridors)} corridors ({walls} walls) over {T} ticks"
    if key == "--workers":
        return f"({options.get('workers')} processes at once)"
    if key == "--out":
        return "for the figures"
    return f"with {len(problem.knots)} stages (knots and region band points)"
