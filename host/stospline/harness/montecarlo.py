"""Monte Carlo of the compiled C controller against a simulation of the SDE plant.

Between ticks the command is held and the plant advances by `substeps` exponential
Euler–Maruyama steps ``x+ = e^{A dt} x + Gamma u + sum_i x_i G_i dZ`` (exact for the mean,
O(dt) weak error in the second moments). The oracle evaluates the same scheme exactly
(`design.moments.euler_tick`), so the simulation bias is a computed number, not a guess.

The paths run in blocks of `BLOCK_PATHS`, each with its own random stream (`block_seed`), on
every core by default (forked workers) or on a Dask cluster (`scheduler`). For a float32
table without faults one C call per stage and block draws the normal numbers and runs the
controllers, the plant and the statistics (`CompiledController.runner`); with faults one
call per tick (`CompiledController.ticker`). Each block summarises itself (`path_stats`) and
the summaries merge in block order as they arrive, at most a few blocks per worker ahead, so
a run's memory does not grow with its paths and its numbers do not depend on which process
ran which block. Per-path records are kept only when asked for (`per_path`).

The plant's standard normal numbers come from a generator in C seeded by the block's stream
(`CompiledController.normals`, `normals.c`: xoshiro256++ and a ziggurat), not from numpy's C
library (``libnpyrandom.a``): ``tools/bench/normal_generators.py`` measures 1.9 ns a number
for ours against 9.5 ns for numpy's ``random_standard_normal`` on its default PCG64 (7.5 ns
even fed by our xoshiro256++ through a ``bitgen_t``: the call per word through a pointer),
which would add about 15 ns to the robot's ~25 ns path-tick (two numbers a tick).
"""
from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from stospline import progress
from stospline.problem.faults import Faults
from stospline.harness.controller import (STATUS, CompiledController, CorridorWatch, FaultDraws,
                                      TickStats)
from stospline.harness.plant_spec import zoh_step as _zoh
from stospline.harness.path_stats import COST_SAMPLE, CorridorExits, Moments, RunStats
from stospline.errors import ProblemError
from stospline.problem.model import Problem


__all__ = ["MonteCarloResult", "simulate", "z_value", "Agreement", "compare_to_oracle",
           "BLOCK_PATHS", "block_seed", "default_workers", "usable_workers", "check_counts",
           "JointVerdict", "joint_verdict", "DETERMINISTIC_RTOL", "faults_unsupported",
           "per_path_bytes", "check_per_path", "PER_PATH_MAX_BYTES", "block_counts",
           "child_stream", "fault_seed"]


def z_value(confidence: float, comparisons: int = 1) -> float:
    """Two-sided normal quantile; Bonferroni-corrected for `comparisons` joint intervals."""
    # scipy.stats.norm.ppf's own function (the same bits); importing scipy.stats takes ~1 s,
    # longer than a design, scipy.special a quarter of it
    from scipy.special import ndtri
    return float(ndtri(1 - (1 - confidence) / (2 * comparisons)))


@dataclass
class MonteCarloResult:
    """A run's statistics (`path_stats`: streamed over blocks of paths, so their size does
    not grow with `paths`), one sample path, and per-path records only when asked for
    (``simulate(per_path=True)``; else None)."""
    paths: int
    cost_moments: Moments            # of each path's realised cost (d = 1)
    knot_moments: list[Moments]      # of the state at each knot
    sample_t: np.ndarray             # tick times, (ticks + 1,)
    sample_x: np.ndarray             # one realisation (ticks + 1, n)
    sample_u: np.ndarray             # its commands (ticks, m)
    mean_x: np.ndarray               # Monte Carlo mean path (ticks + 1, n)
    worst_status: int
    # (path, tick) steps on which the C controller returned STSP_WARN_SATURATED, the paths
    # with at least one, and the smallest and largest command it issued per input (m,).
    saturated_tick_count: int = 0
    saturated_path_count: int = 0
    u_low: np.ndarray | None = None
    u_high: np.ndarray | None = None
    substeps: int = 0                # plant steps per tick of this run
    # States of the first `record` paths at every tick (ticks + 1, record, n), float32, and
    # the commands applied to them (ticks, record, m); None unless asked for
    # (simulate(record=...)): for percentile bands in reports.
    record_x: np.ndarray | None = None
    # How `substeps` was chosen (pipeline.simulate_problem with substeps="auto"), else None:
    # a `plant_scheme.SubstepChoice` (not imported: that module imports this one).
    substep_choice: object = None
    faults: Faults = field(default_factory=Faults)     # the loop's faults in this run
    record_u: np.ndarray | None = None
    # With corridors (problem.corridors): the exits by tick and wall (`CorridorExits`), and
    # the first exit tick of the recorded paths (corridors, record; -1: never).
    exits: CorridorExits | None = None
    record_exit_tick: np.ndarray | None = None
    cost_sample: np.ndarray | None = None    # the costs of the first COST_SAMPLE paths
    # Per path, with per_path=True only: realised cost (paths,), the state at each knot
    # (paths, n), saturated ticks (paths,), first exit tick and wall (corridors, paths).
    cost: np.ndarray | None = None
    knot_states: list[np.ndarray] | None = None
    saturated_ticks: np.ndarray | None = None
    exit_tick: np.ndarray | None = None
    exit_wall: np.ndarray | None = None
    # What simulate's `alongside` returned (its work ran while the paths ran), else None.
    alongside: object = None

    @property
    def saturated_fraction(self) -> float:
        """Fraction of all (path, tick) steps on which the controller clamped a command."""
        ticks = self.sample_u.shape[0]
        return 0.0 if ticks == 0 else self.saturated_tick_count / (self.paths * ticks)

    @property
    def saturated_path_fraction(self) -> float:
        """Fraction of the paths on which the controller clamped a command at least once."""
        return self.saturated_path_count / self.paths

    def cost_mean_ci(self, confidence: float = 0.95) -> tuple[float, float]:
        """Mean cost and the half-width of its normal-approximation confidence interval."""
        return (float(self.cost_moments.mean[0]),
                z_value(confidence) * float(self.cost_moments.mean_se()[0]))

    def cost_std(self) -> float:
        """Sample standard deviation of the paths' costs (ddof 1)."""
        return float(self.cost_moments.std()[0])

    def knot_mean_se(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        return self.knot_moments[k].mean, self.knot_moments[k].mean_se()

    def knot_cov(self, k: int) -> np.ndarray:
        cov = self.knot_moments[k].cov()
        return cov[0, 0] if cov.shape == (1, 1) else cov     # np.cov's shape for n = 1

    def exit_count(self, corridor: int) -> int:
        """Paths that left corridor `corridor` (`problem.corridors`)."""
        return int(self.exits.count[corridor])


# Paths per random stream. Block 0 draws from the seed's own stream, block i >= 1 from child
# i - 1 of ``SeedSequence(seed).spawn``; the blocks are the unit of work spread over processes,
# so a seed gives the same numbers whatever the number of workers (and runs of up to this many
# paths are what a single stream gives). 512: a 10^3-path run already fills two cores, while
# the per-tick call costs stay ~5 % of a block's tick.
BLOCK_PATHS = 512
# Below this many path-ticks a run stays in this process: starting workers costs more.
_PARALLEL_WORK = 2_000_000


def block_seed(seed, block: int) -> np.random.SeedSequence:
    """The random stream of `block`: the seed's own for block 0, else child ``block - 1`` of
    ``SeedSequence(seed).spawn`` (the same children, derived without spawning)."""
    ss = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    if block == 0:
        return ss
    return np.random.SeedSequence(ss.entropy, spawn_key=tuple(ss.spawn_key) + (block - 1,),
                                  pool_size=ss.pool_size)


# The faults' random numbers come from their own child of each block's stream, so the plant's
# numbers are the same with and without faults (common random numbers: rows of a fault table
# differ by the fault, not by the sample).
_FAULT_STREAM = 2**32 - 2


def child_stream(block: np.random.SeedSequence, key: int) -> np.random.SeedSequence:
    """Child `key` of a block's stream (derived without spawning)."""
    return np.random.SeedSequence(block.entropy, spawn_key=tuple(block.spawn_key) + (key,),
                                  pool_size=block.pool_size)


def fault_seed(block: np.random.SeedSequence) -> np.random.SeedSequence:
    """The stream of a block's fault draws (`_FAULT_STREAM`)."""
    return child_stream(block, _FAULT_STREAM)


def faults_unsupported(problem: Problem, table) -> str | None:
    """Why the harness cannot run faults around `table` on `problem`, or None: it runs them
    in the fused C tick, for float32 tables with time-invariant stage data."""
    if getattr(table, "arith", "float32") != "float32":
        return "the fault harness runs float32 tables"
    if any(st.varying is not None for st in problem.stages):
        return "the fault harness runs time-invariant stage data (this problem's vary in time)"
    if getattr(table, "delay_ticks", 0):
        return ("the fault harness runs tables designed without a delay (this one is designed "
                "for a one-tick delay, which it always runs with)")
    return None


def default_workers() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:          # not on Linux
        return os.cpu_count() or 1


def usable_workers(workers: int | None, force: bool = False) -> int:
    """The worker processes a run starts: `workers` (default: every core), at most the cores
    this process may use unless `force` (more only share those cores, each with its own
    memory)."""
    cores = default_workers()
    if workers is None:
        return cores
    workers = max(1, int(workers))
    return workers if force else min(workers, cores)


def check_counts(**counts) -> None:
    """ValueError unless each count (paths, substeps) is an integer >= 1, before anything is
    allocated."""
    for name, value in counts.items():
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise ValueError(f"{name} must be an integer >= 1, got {value!r}")


# Per-path records (simulate(per_path=True)) are refused beyond this many bytes: the
# statistics stream without them.
PER_PATH_MAX_BYTES = 1 << 30
# Blocks handed out to workers ahead of the one merged next: enough to keep every worker
# busy, few enough that waiting results stay small.
_AHEAD_PER_WORKER = 4


def per_path_bytes(problem: Problem, paths: int) -> float:
    """Memory of the per-path records of a `paths`-path run (``simulate(per_path=True)``):
    cost, knot states, saturated ticks, exit tick and wall per corridor."""
    per = 8.0 * (2 + problem.n * len(problem.knots)) + 8.0 * len(problem.corridors)
    return paths * per


def check_per_path(problem: Problem, paths: int) -> None:
    """ProblemError naming ``per_path`` when its records of `paths` paths would exceed
    `PER_PATH_MAX_BYTES`, before anything is allocated."""
    need = per_path_bytes(problem, paths)
    if need > PER_PATH_MAX_BYTES:
        raise ProblemError("per_path", f"the records of {paths} paths need ~{need / 2**30:.3g} "
                                       f"GiB (limit {PER_PATH_MAX_BYTES / 2**30:.3g} GiB); "
                                       f"without per_path the run's statistics stream in "
                                       f"bounded memory")


def simulate(problem: Problem, controller: CompiledController, *, paths: int, seed: int,
             substeps: int = 4, workers: int | None = None, record: int = 0,
             scheduler: str | None = None, faults: Faults | None = None,
             force_workers: bool = False, per_path: bool = False,
             alongside: Callable[[], object] | None = None) -> MonteCarloResult:
    """Run `paths` realisations of the plant with the compiled controller in the loop.

    Parameters
    ----------
    problem : Problem
        The plant (dynamics, noise, cost) and x0; the controller's table is what is tested.
    controller : CompiledController
    paths : int
        Number of paths (>= 1; ValueError otherwise, before anything is allocated).
    seed : int or numpy.random.SeedSequence
        Seed of the random streams: blocks of `BLOCK_PATHS` paths, each with its own stream
        (`block_seed`), so the result depends on the seed and `paths` only.
    substeps : int
        Plant steps per controller tick (>= 1) (time-varying data are frozen at each step's
        midpoint, a second-order error in the step).
    workers : int, optional
        Processes that run blocks at once (default: every core this process may use; runs
        below ~2e6 path-ticks stay in this process); at most those cores unless
        `force_workers`. The result is the same for any number.
    record : int
        Keep the states of the first ``min(record, paths, BLOCK_PATHS)`` paths at every tick
        (``record_x``, float32).
    scheduler : str, optional
        Run the blocks on a Dask cluster instead (``dask.distributed``): the address of its
        scheduler, or ``"local"`` for a local cluster of `workers` processes. Each worker
        compiles (or loads from its cache) the controller of the same table. The numbers are
        those of a run on this machine.
    faults : Faults, optional
        The loop's faults (default ``problem.faults``; `stospline.problem.faults`): what the
        controller measures, when it runs, what the actuator applies, and the plant's
        mismatch. Their random numbers come from a stream of their own (`fault_seed`), so the
        plant's are the same with or without faults. Float32 tables with time-invariant stage data only
        (ProblemError otherwise).
    per_path : bool
        Also keep every path's cost, knot states, saturated ticks and corridor exit
        (``cost``, ``knot_states``, ...); refused (ProblemError) beyond
        `PER_PATH_MAX_BYTES`. Without it the run's memory does not grow with `paths`: its
        statistics stream over the blocks (`path_stats`), merged in block order.
    alongside : callable, optional
        Work of this process to do while the paths run (e.g. what a summary of the run will
        need): called without arguments in a thread started once the worker processes are
        forked (or with the first block run here; the C loop does not hold the GIL); its
        return value is the result's ``alongside``, its exception is raised after the run.
    """
    check_counts(paths=paths, substeps=substeps)
    if per_path:
        check_per_path(problem, paths)
    table = controller.table
    faults = problem.faults if faults is None else faults
    if getattr(table, "delay_ticks", 0) and faults.delay_ticks:
        raise ProblemError("faults.delay_ticks", "the table is designed for a one-tick delay "
                                                 "and runs with it; a delay fault on top of it "
                                                 "is not simulated")
    if faults.any and faults_unsupported(problem, table):
        raise ProblemError("faults", "are simulated for float32 tables designed without a "
                                     "delay, with time-invariant stage data only")
    # the plant's step compiled for this problem (`plant_spec`; the same bits, built once)
    controller = controller.for_plant(faults.plant_of(problem))
    blocks = -(-paths // BLOCK_PATHS)
    workers = usable_workers(workers, force_workers)
    parallel = (workers > 1 and blocks > 1
                and paths * table.n_ticks * substeps >= _PARALLEL_WORK)
    job = _Job(problem, seed, substeps, record, faults, per_path)
    bar = progress.start(f"simulate ({paths} paths)", paths * table.n_ticks, unit="path-tick")
    side = _Alongside(alongside)
    try:
        if scheduler is not None:
            side.start()
            parts = _dask_blocks(scheduler, job, controller.table, paths, workers)
        elif parallel:
            parts = _parallel_blocks(job, controller, paths, workers, started=side.start)
        else:
            side.start()
            parts = (_run_block(job, controller, i, paths) for i in range(blocks))
        run = _Gather(per_path)
        for part in parts:
            run.add(part)
    finally:
        progress.finish(bar)
        done = side.join()
    mc = run.result(problem, table, substeps, faults)
    mc.alongside = done()
    return mc


class _Alongside:
    """`simulate`'s `alongside` work in a thread of its own."""

    def __init__(self, work):
        self.work, self.thread, self.out, self.error = work, None, None, None

    def start(self) -> None:
        if self.work is None or self.thread is not None:
            return
        import threading

        def run():
            try:
                self.out = self.work()
            except BaseException as exc:     # re-raised in the caller's thread
                self.error = exc
        self.thread = threading.Thread(target=run, name="stospline-alongside", daemon=True)
        self.thread.start()

    def join(self):
        """Wait for the work's thread; a function that returns its result (running it now
        if it never started) or raises its exception."""
        if self.thread is not None:
            self.thread.join()

        def done():
            if self.work is not None and self.thread is None:
                return self.work()
            if self.error is not None:
                raise self.error
            return self.out
        return done


def block_counts(paths: int, block_paths: int = BLOCK_PATHS):
    """``(block, first path, paths)`` of each block of a `paths`-path run, in order."""
    for i, start in enumerate(range(0, paths, block_paths)):
        yield i, start, min(block_paths, paths - start)


@dataclass(frozen=True)
class _Job:
    """What every block of a run shares."""
    problem: Problem
    seed: object
    substeps: int
    record: int
    faults: Faults
    per_path: bool


@dataclass
class _Block:
    """One block's share of a run: its statistics (`RunStats`), block 0's sample path and
    records, and its per-path arrays when the run keeps them."""
    stats: RunStats
    sample_x: np.ndarray | None = None
    sample_u: np.ndarray | None = None
    record_x: np.ndarray | None = None
    record_u: np.ndarray | None = None
    record_exit_tick: np.ndarray | None = None
    cost: np.ndarray | None = None
    knots: list | None = None
    saturated: np.ndarray | None = None
    exit_tick: np.ndarray | None = None
    exit_wall: np.ndarray | None = None


class _Gather:
    """Merges the blocks of a run as they arrive, in block order, keeping block 0's sample
    path and records and (per_path) the per-path arrays."""

    def __init__(self, per_path: bool):
        self.per_path = per_path
        self.first: _Block | None = None
        self.stats: RunStats | None = None
        self.kept: list[_Block] = []

    def add(self, block: _Block) -> None:
        if self.first is None:
            self.first, self.stats = block, block.stats
        else:
            self.stats = self.stats.merge(block.stats)
        if self.per_path:
            self.kept.append(block)

    def result(self, problem: Problem, table, substeps: int, faults: Faults) -> MonteCarloResult:
        first, st = self.first, self.stats
        t = problem.t0 + np.arange(table.n_ticks + 1) / table.tick_hz
        mc = MonteCarloResult(
            st.paths, st.cost, st.knots, t, first.sample_x, first.sample_u,
            st.x_sum / st.paths, st.worst, st.saturated_ticks, st.saturated_paths,
            st.u_low, st.u_high, substeps, first.record_x, faults=faults,
            record_u=first.record_u, exits=st.exits, record_exit_tick=first.record_exit_tick,
            cost_sample=st.cost_sample)
        if self.per_path:
            parts = self.kept
            mc.cost = np.concatenate([p.cost for p in parts])
            mc.knot_states = [np.concatenate([p.knots[k] for p in parts])
                              for k in range(len(first.knots))]
            mc.saturated_ticks = np.concatenate([p.saturated for p in parts])
            if first.exit_tick is not None:
                mc.exit_tick = np.concatenate([p.exit_tick for p in parts], axis=1)
                mc.exit_wall = np.concatenate([p.exit_wall for p in parts], axis=1)
        return mc


def _block_stats(problem: Problem, table, cost, knots, x_sum, worst, stats: TickStats,
                 watch, start: int) -> RunStats:
    """A block's `RunStats` from its per-path arrays; its first path is path `start`."""
    exits = None
    if watch is not None:
        exits = CorridorExits.of(watch.exit_tick, watch.exit_wall,
                                 [len(c.wall_names()) for c in problem.corridors],
                                 table.n_ticks, start)
    return RunStats(len(cost), Moments.of(cost), [Moments.of(X) for X in knots], x_sum, worst,
                    int(stats.saturated.sum()), int(np.count_nonzero(stats.saturated)),
                    stats.u_low.copy(), stats.u_high.copy(),
                    cost[:max(0, min(len(cost), COST_SAMPLE - start))].copy(), exits)


def _run_block(job: _Job, controller: CompiledController, block: int, paths: int, *,
               report: bool = True) -> _Block:
    """Block `block` of a `paths`-path run (`block_counts`)."""
    start = block * BLOCK_PATHS
    count = min(BLOCK_PATHS, paths - start)
    return _simulate_block(job.problem, controller, count, block_seed(job.seed, block),
                           job.substeps, first=block == 0, report=report, record=job.record,
                           faults=job.faults, start=start, per_path=job.per_path)


def _simulate_block(problem: Problem, controller: CompiledController, paths: int, seed,
                    substeps: int, *, first: bool, report: bool = True, record: int = 0,
                    faults: Faults | None = None, start: int = 0,
                    per_path: bool = False) -> _Block:
    table = controller.table
    faults = Faults() if faults is None else faults
    plant_of = faults.plant_of(problem)         # the plant the loop really has
    seed = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    normals = controller.normals(seed)        # the plant's standard normal numbers, in C
    n, m = problem.n, problem.m
    h = 1.0 / table.tick_hz
    dt = h / substeps
    X = np.ascontiguousarray(np.tile(problem.x0, (paths, 1)), dtype=float)
    cost = np.zeros(paths)
    # float32 tables: one C call per tick does controller, plant and statistics; otherwise the
    # controller and the plant are separate calls and numpy gathers the statistics.
    fused = getattr(table, "arith", "float32") == "float32"
    # real states in, real commands out, also for a Q15/Q31 table (`real_stepper`)
    step = controller.real_stepper(paths)
    kept = min(record, paths) if first else 0
    stats = TickStats.zeros(paths, n, m, kept)
    knots, worst = [], 0
    x_sum = np.empty((table.n_ticks + 1, n))
    x_sum[0] = X.sum(axis=0)
    sample_u = np.empty((table.n_ticks, m))
    sample_x = np.empty((table.n_ticks + 1, n))
    sample_x[0] = X[0]
    record_x = np.empty((table.n_ticks + 1, kept, n), np.float32) if kept else None
    record_u = np.empty((table.n_ticks, kept, m), np.float32) if kept else None
    if kept:
        record_x[0] = X[:kept]
    # A table designed for a one-tick delay runs in the delayed loop (the fault path of the
    # fused tick, measuring the held command too).
    delayed = int(getattr(table, "delay_ticks", 0))
    draws = (FaultDraws.of(faults, paths, n, table.u_hold, delayed)
             if faults.any or delayed else None)
    fault_rng = np.random.default_rng(fault_seed(seed)) if draws is not None else None
    watch = (CorridorWatch.of(problem.corridors, paths, problem.t0, table.tick_hz)
             if problem.corridors else None)
    if watch is not None:
        watch.check(0, X)                         # x0 (the others after each tick, in C)
    for k in range(table.n_stages):
        st = plant_of.stages[k]
        plant = (None if st.varying is not None
                 else controller.plant(st, *_zoh(st, dt), dt, substeps))
        mz = st.G.shape[2]
        dZ = np.empty((paths, substeps, mz))       # standard normal; the C scales by sqrt(dt)
        fill_dZ = normals(dZ)
        tick = None
        ticks = range(int(table.stage_start[k]), int(table.stage_start[k + 1]))
        if fused and plant is not None and draws is None:
            # the whole stage in one C call: normals, controllers, plant, statistics
            run = controller.runner(step.instances, paths, normals, dZ, X, cost, stats, watch,
                                    x_sum, sample_x, sample_u, record_x, record_u)
            worst = min(worst, run(ticks.start, ticks.stop, plant))
            if report:
                progress.advance(paths * len(ticks))
            ticks = range(0)
        elif fused and plant is not None:
            tick = controller.ticker(step.instances, paths, dZ, X, cost, stats, draws, watch)
        for j in ticks:
            fill_dZ()
            if draws is not None:
                draws.draw(fault_rng)
            if tick is not None:
                worst = min(worst, tick(j, plant))
                sample_u[j] = stats.u_rec[0]
                if kept:
                    record_u[j] = stats.u_rec[:kept]
                x_sum[j + 1] = stats.x_sum
            else:
                U, status = step(j, X)
                worst = min(worst, int(status.min()))
                stats.saturated += status == STATUS["WARN_SATURATED"]
                np.minimum(stats.u_low, U.min(axis=0), out=stats.u_low)
                np.maximum(stats.u_high, U.max(axis=0), out=stats.u_high)
                _plant_tick(controller, problem, plant, st, j, h, dt, substeps, dZ, U, X, cost)
                if watch is not None:
                    watch.check(j + 1, X)
                sample_u[j] = U[0]
                if kept:
                    record_u[j] = U[:kept]
                x_sum[j + 1] = X.sum(axis=0)
            sample_x[j + 1] = X[0]
            if kept:
                record_x[j + 1] = X[:kept]
            if report:
                progress.advance(paths)
        knot = problem.knots[k]
        if knot.penalty is not None:
            r = X @ knot.penalty.C.T - knot.penalty.target
            cost += knot.penalty.weight * np.einsum("pi,pi->p", r, r)
        knots.append(X.copy())
    out = _Block(_block_stats(problem, table, cost, knots, x_sum, worst, stats, watch, start))
    if first:
        out.sample_x, out.sample_u, out.record_x, out.record_u = (sample_x, sample_u,
                                                                  record_x, record_u)
        if watch is not None:
            out.record_exit_tick = watch.exit_tick[:, :kept].copy()
    if per_path:
        out.cost, out.knots, out.saturated = cost, knots, stats.saturated
        if watch is not None:
            out.exit_tick, out.exit_wall = watch.exit_tick, watch.exit_wall
    return out


# What the forked workers run (set before the pool starts; inherited, never pickled: the
# problem may hold closures and the controller a loaded C library).
_JOB: tuple | None = None


def _block_job(block: int, paths: int) -> _Block:
    job, controller, run = _JOB
    return run(job, controller, block, paths, report=False)


def _dask_block(job: _Job, table, block: int, paths: int) -> _Block:
    """One block on a Dask worker: the controller of `table` from the worker's cache."""
    from stospline.harness.controller import build_controller
    ctl = build_controller(table, plant=job.faults.plant_of(job.problem))
    return _run_block(job, ctl, block, paths, report=False)


def _in_order(submit, paths: int, ahead: int, ticks: int, block_paths: int = BLOCK_PATHS):
    """Each block's result in block order, with at most `ahead` blocks submitted and not yet
    yielded (`submit(block)` returns a future with ``result()``)."""
    from collections import deque
    blocks = iter(block_counts(paths, block_paths))
    waiting: deque = deque()
    for _ in range(ahead):
        nxt = next(blocks, None)
        if nxt is None:
            break
        waiting.append((nxt[2], submit(nxt[0])))
    while waiting:
        count, fut = waiting.popleft()
        nxt = next(blocks, None)
        if nxt is not None:
            waiting.append((nxt[2], submit(nxt[0])))
        part = fut.result()
        progress.advance(count * ticks)
        yield part


def _dask_blocks(scheduler: str, job, table, paths: int, workers: int, *,
                 run=_dask_block, block_paths: int = BLOCK_PATHS):
    """The blocks on a Dask cluster (`scheduler`: an address, or "local"), in block order:
    ``run(job, table, block, paths)`` on a worker (default `_dask_block`, the full-state
    loop) for each block of `block_paths` paths."""
    from distributed import Client, LocalCluster
    cluster = None
    if scheduler == "local":
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               dashboard_address=None)
        address = cluster.scheduler_address
    else:
        address = scheduler
    try:
        try:
            client = Client(address, timeout="10s")
        except OSError as exc:
            raise ProblemError("--scheduler", f"cannot reach the Dask scheduler at {address!r} "
                                              f"({exc})") from None
        with client:
            ahead = _AHEAD_PER_WORKER * max(workers, len(client.scheduler_info()["workers"]))
            job_ref = client.scatter(job, broadcast=True)
            table_ref = client.scatter(table, broadcast=True)
            yield from _in_order(lambda i: client.submit(run, job_ref, table_ref, i, paths,
                                                         pure=False),
                                 paths, ahead, table.n_ticks, block_paths)
    finally:
        if cluster is not None:
            cluster.close()


def _parallel_blocks(job, controller, paths: int, workers: int, *, started=None,
                     run=_run_block, block_paths: int = BLOCK_PATHS):
    """The blocks on `workers` forked processes, in block order; progress per block.
    `started()` is called once they are forked (the first submission forks them all): a
    thread it starts is not in them. ``run(job, controller, block, paths, report=False)``
    runs a block of `block_paths` paths (default `_run_block`, the full-state loop)."""
    global _JOB
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor
    _JOB = (job, controller, run)
    try:
        ctx = multiprocessing.get_context("fork")
        blocks = -(-paths // block_paths)
        with ProcessPoolExecutor(max_workers=min(workers, blocks), mp_context=ctx) as pool:
            def submit(i):
                future = pool.submit(_block_job, i, paths)
                if started is not None:
                    started()
                return future
            yield from _in_order(submit, paths, _AHEAD_PER_WORKER * workers,
                                 controller.table.n_ticks, block_paths)
    finally:
        _JOB = None


def _plant_tick(controller, problem, plant, stage, j, h, dt, substeps, dZ, U, X, cost):
    """The plant over tick j as its own C call: a constant stage's prepared plant, or, with
    time-varying data, each substep with the data at its midpoint."""
    if plant is not None:
        controller.plant_tick(plant, dZ, U, X, cost)
        return
    for i in range(substeps):
        sd = stage.at(problem.t0 + j * h + (i + 0.5) * dt)
        one = controller.plant(sd, *_zoh(sd, dt), dt, 1)
        controller.plant_tick(one, np.ascontiguousarray(dZ[:, i:i + 1]), U, X, cost)


# A deterministic statistic (zero Monte Carlo spread) agrees when it is this close, relative.
DETERMINISTIC_RTOL = 1e-6


@dataclass(frozen=True)
class JointVerdict:
    """Monte Carlo statistics against exact values, all at once: each z-score within the
    two-sided normal bound `z_limit`, Bonferroni-corrected so that a correct controller passes
    every one of them together with probability `confidence`."""
    agree: bool
    confidence: float
    statistics: int
    z_limit: float
    max_abs_z: float
    max_abs_z_of: str | None
    outside: tuple[str, ...]     # the statistics that fail


def joint_verdict(stats, confidence: float = 0.99) -> JointVerdict:
    """`stats`: (name, z, Monte Carlo value, exact value) per statistic, z None where the
    Monte Carlo spread is zero (every path alike): that statistic must then equal the exact
    value to DETERMINISTIC_RTOL relative."""
    stats = list(stats)
    limit = z_value(confidence, len(stats))
    worst_name, worst, outside = None, 0.0, []
    for name, z, mc_value, exact in stats:
        if z is None:
            if abs(mc_value - exact) > DETERMINISTIC_RTOL * max(1.0, abs(exact)):
                outside.append(name)
            continue
        if worst_name is None or abs(z) > worst:
            worst_name, worst = name, abs(z)
        if not abs(z) <= limit:
            outside.append(name)
    return JointVerdict(not outside, confidence, len(stats), limit, worst, worst_name,
                        tuple(outside))


@dataclass
class Agreement:
    """Monte Carlo vs exact numbers: z-scores (0 where the spread is zero) and the joint
    verdict at a confidence level. `standard_errors` says what the z-scores divide by:
    "exact" (the oracle's moments up to the fourth, `oracle.tails`) or "sample" (the run's
    own second and fourth central sums)."""
    confidence: float
    z_limit: float
    cost_z: float
    knot_mean_z: list[np.ndarray]
    verdict: JointVerdict
    standard_errors: str = "sample"

    @property
    def max_abs_z(self) -> float:
        return self.verdict.max_abs_z

    @property
    def ok(self) -> bool:
        return self.verdict.agree


def compare_to_oracle(mc: MonteCarloResult, J: float, knot_means: list[np.ndarray], *,
                      confidence: float = 0.99,
                      knot_covs: list[np.ndarray] | None = None,
                      exact_se=None) -> Agreement:
    """Compare the Monte Carlo cost and knot means with exact values (`joint_verdict`),
    Bonferroni-corrected so that the *joint* statement (cost and every knot-mean component)
    holds at `confidence` when the controller is right. With `knot_covs`, every knot variance
    joins them: faults such as sensor noise move the spread, not the mean.

    The z-scores divide by the exact standard errors of a run of ``mc.paths`` paths when
    `exact_se` (an `oracle.tails.TailMoments` of the loop, or anything with its
    ``cost_mean_se``, ``knot_mean_se`` and ``knot_var_se``) is given: the cost's variance and
    each knot component's variance and fourth central moment. Else they divide by the sample's
    own (`path_stats.Moments.mean_se`, ``var_se``), which heavy tails (multiplicative noise)
    make too small."""
    N = mc.paths
    mean, _ = mc.cost_mean_ci()
    alike = bool(mc.cost_moments.alike()[0])
    if exact_se is None:
        se = float(mc.cost_moments.mean_se()[0])
    else:
        se = 0.0 if alike else exact_se.cost_mean_se(N)
    cost_z = float((mean - J) / se) if se > 0 else None
    stats = [("cost", cost_z, mean, J)]
    zs = []
    for k, exact in enumerate(knot_means):
        m, s = mc.knot_mean_se(k)
        if exact_se is not None:
            s = np.where(mc.knot_moments[k].alike(), 0.0, exact_se.knot_mean_se(k, N))
        z = [float((m[i] - exact[i]) / s[i]) if s[i] > 0 else None for i in range(len(m))]
        stats += [(f"knot {k} mean[{i}]", z[i], m[i], exact[i]) for i in range(len(m))]
        zs.append(np.array([0.0 if v is None else v for v in z]))
        if knot_covs is not None:
            var = np.diag(mc.knot_moments[k].cov())
            se_var = (mc.knot_moments[k].var_se() if exact_se is None else
                      np.where(mc.knot_moments[k].alike(), 0.0, exact_se.knot_var_se(k, N)))
            exact_var = np.diag(knot_covs[k])
            stats += [(f"knot {k} var[{i}]",
                       float((var[i] - exact_var[i]) / se_var[i]) if se_var[i] > 0 else None,
                       var[i], exact_var[i]) for i in range(len(m))]
    v = joint_verdict(stats, confidence)
    return Agreement(confidence, v.z_limit, 0.0 if cost_z is None else cost_z, zs, v,
                     "sample" if exact_se is None else "exact")
