#!/usr/bin/env python3
"""Monte Carlo throughput of the harness against a plain numpy loop and a hand-written C
loop, in the same run.

All simulate the robot corridor (examples/robot_corridor.toml, 6000 ticks at 1 kHz):

* **stospline**: `stospline.harness.montecarlo.simulate`, the compiled C controller of the
  float32 table in the loop, blocks of paths spread over `--workers` processes (default:
  every core), the normal numbers from its C generator (xoshiro256++ and a ziggurat), 2
  plant steps per tick (exponential Euler-Maruyama, Gaussian increments);
* **numpy**: the same closed loop written as one would in numpy, in one process: the law
  ``u = -(K x + k0 + L v)`` with the table's gains in float64 (v latched at each stage start,
  ``v = Lambda x + lambda0``), the plant step and the noise as matrix products, the running
  cost; no controller logic (tick checks, limits, statuses), so it is a lower bound on what
  a numpy harness costs; normal numbers from ``numpy.random.default_rng``;
* **hand-written C** (`tools/bench/robot_loop.c`, one core, 1 plant step per tick): the
  robot's float32 law with latching, the exact zero-order hold of the double integrators with
  the multiplicative velocity noise and the running cost, written for this problem only; with
  and without drawing the normal numbers. Beside it the harness on one core, 1 plant step per
  tick (CPU time per path-tick), and where the harness's time goes per path-tick: the
  corridor watch (a run without the corridor; and the generic watch, a corridor the module
  was not compiled for), the normal numbers (``harness_normals``
  alone), the controller (``stsp_step`` over a block, ``harness_step_batch``), the plant
  (``harness_plant_tick``, the step compiled for the problem, and beside it the step generic
  in the stage data), the rest (the loop, the statistics);
* **the whole command** ``stospline simulate examples/robot_corridor.toml --paths N --json``
  (imports, design, oracle, substep pilot, Monte Carlo on every core, corridor bounds):
  wall time, path-ticks per second of wall time.

Prints path-ticks per second for each path count, their ratio, and the time per path (which
must stay flat: time linear in paths). The numpy baseline runs up to 10^4 paths (beyond, its
time is linear too and only costs minutes).

    PYTHONPATH=host .venv/bin/python tools/bench/harness_throughput.py [--paths 1000,10000,100000]
        [--workers N] [--command-paths 20000] [--repeat 3] [--command-only]

Add 1000000 to --paths for the 10^6-path point (about 5 minutes on 2 cores).
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")      # one BLAS thread per process, for both sides

import numpy as np  # noqa: E402

from stospline.expm import expm  # noqa: E402
from stospline.pipeline import design_problem  # noqa: E402
from stospline.problem import load_problem  # noqa: E402
from stospline.harness.controller import build_controller  # noqa: E402
from stospline.harness.montecarlo import default_workers, simulate  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
SUBSTEPS = 2
SIM = ROOT / "host" / "stospline" / "harness"
BLOCK = 512                 # paths per block, as the harness's BLOCK_PATHS


def numpy_loop(problem, table, paths: int, seed: int) -> np.ndarray:
    """The closed loop in plain numpy (float64 gains of the table, vectorised over paths,
    matrix products only); returns the per-path costs."""
    rng = np.random.default_rng(seed)
    n, m = problem.n, problem.m
    h = 1.0 / table.tick_hz
    dt = h / SUBSTEPS
    sq = np.sqrt(dt)
    X = np.tile(problem.x0, (paths, 1))
    cost = np.zeros(paths)
    KT = np.ascontiguousarray(np.swapaxes(np.asarray(table.K, float), 1, 2))   # (ticks, n, m)
    LT = np.ascontiguousarray(np.swapaxes(np.asarray(table.L, float), 1, 2))
    k0 = np.asarray(table.k0, float)
    V = None
    for s in range(table.n_stages):
        st = problem.stages[s]
        E = expm(np.block([[st.A, st.B], [np.zeros((m, n + m))]]) * dt)
        AdT, BdT = E[:n, :n].T.copy(), E[:n, n:].T.copy()
        mz = st.G.shape[2]
        Gflat = np.moveaxis(st.G, 1, 2).reshape(n, mz * n)   # x @ Gflat -> (k, a) blocks
        R, r = st.R, st.r
        if V is None or int(table.stage_n_latch[s]) > 0:
            V = X @ np.asarray(table.Lambda[s], float).T + table.lambda0[s]
        for j in range(int(table.stage_start[s]), int(table.stage_start[s + 1])):
            U = -(X @ KT[j] + V @ LT[j] + k0[j])
            cost += h * (((U @ R) * U).sum(axis=1) + 2 * U @ r + st.rho)
            UB = U @ BdT
            for _ in range(SUBSTEPS):
                dZ = rng.standard_normal((paths, mz)) * sq
                W = (X @ Gflat).reshape(paths, mz, n)              # W[p, k, a]
                X = X @ AdT + UB + np.einsum("pka,pk->pa", W, dZ)
        knot = problem.knots[s]
        if knot.penalty is not None:
            r_k = X @ knot.penalty.C.T - knot.penalty.target
            cost += knot.penalty.weight * (r_k * r_k).sum(axis=1)
    return cost


def rate(paths: int, ticks: int, seconds: float) -> float:
    return paths * ticks / seconds


_LOOP_PROTOTYPE = """#include <stddef.h>
#include <stdint.h>
void robot_loop(const float *K, const float *k0, const float *L, const float *Lambda,
                const float *lambda0, const uint32_t *stage_start, uint32_t n_stages,
                double h, size_t paths, uint64_t *rng, int draw, double *z, double *X,
                float *V, double *cost, double *x_sum);
"""


def build_c_loop(tmp: str):
    """`robot_loop.c` with the harness's normals.c, as a cffi module (-O3, as the harness)."""
    import importlib.util
    import cffi
    ffib = cffi.FFI()
    ffib.cdef("""void robot_loop(const float *K, const float *k0, const float *L,
        const float *Lambda, const float *lambda0, const uint32_t *stage_start,
        uint32_t n_stages, double h, size_t paths, uint64_t *rng, int draw, double *z,
        double *X, float *V, double *cost, double *x_sum);""")
    ffib.set_source("_robot_loop", _LOOP_PROTOTYPE,
                    sources=[str(ROOT / "tools" / "bench" / "robot_loop.c"),
                             str(SIM / "normals.c")],
                    include_dirs=[str(SIM)], extra_compile_args=["-std=c99", "-O3"])
    path = ffib.compile(tmpdir=tmp)
    spec = importlib.util.spec_from_file_location("_robot_loop", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.ffi, mod.lib


def c_loop_seconds(ffi, lib, problem, table, paths: int, draw: bool) -> float:
    """CPU seconds of the hand-written loop over `paths` paths, in blocks of BLOCK."""
    arr = {k: np.ascontiguousarray(getattr(table, k), dtype=np.float32)
           for k in ("K", "k0", "L", "Lambda", "lambda0")}
    starts = np.ascontiguousarray(table.stage_start, dtype=np.uint32)
    ptr = {k: ffi.from_buffer("float[]", a) for k, a in arr.items()}
    rng = np.array([1, 2, 3, 4], np.uint64)
    z = np.zeros(2 * BLOCK)
    x_sum = np.zeros((table.n_ticks + 1, 4))
    spent = 0.0
    for start in range(0, paths, BLOCK):
        count = min(BLOCK, paths - start)
        X = np.ascontiguousarray(np.tile(problem.x0, (count, 1)))
        V = np.zeros((count, 4), np.float32)
        cost = np.zeros(count)
        t = time.process_time()
        lib.robot_loop(ptr["K"], ptr["k0"], ptr["L"], ptr["Lambda"], ptr["lambda0"],
                       ffi.from_buffer("uint32_t[]", starts), table.n_stages,
                       1.0 / table.tick_hz, count, ffi.from_buffer("uint64_t[]", rng),
                       int(draw), ffi.from_buffer("double[]", z),
                       ffi.from_buffer("double[]", X), ffi.from_buffer("float[]", V),
                       ffi.from_buffer("double[]", cost), ffi.from_buffer("double[]", x_sum))
        spent += time.process_time() - t
    return spent


def harness_seconds(problem, ctl, paths: int) -> float:
    """CPU seconds of `simulate` in this process (one core), 1 plant step per tick."""
    t = time.process_time()
    simulate(problem, ctl, paths=paths, seed=1, substeps=1, workers=1)
    return time.process_time() - t


def part_seconds(problem, ctl, paths: int) -> dict:
    """CPU seconds of the harness's parts over `paths` path-ticks' worth of work each,
    run apart: the normals, the controllers' step, the plant's tick (BLOCK paths a call)."""
    from stospline.harness.montecarlo import _zoh
    table = ctl.table
    ticks = table.n_ticks
    calls = max(1, paths * ticks // BLOCK)
    out = {}
    dZ = np.empty((BLOCK, 1, problem.stages[0].G.shape[2]))
    fill = ctl.normals(np.random.SeedSequence(1))(dZ)
    t = time.process_time()
    for _ in range(calls):
        fill()
    out["normal numbers"] = time.process_time() - t
    step = ctl.stepper(BLOCK)
    X = np.tile(problem.x0, (BLOCK, 1)).astype(np.float32)
    xs = ctl.ffi.cast("const stsp_scalar_t *", ctl.ffi.from_buffer(X))
    us = np.zeros((BLOCK, problem.m), np.float32)
    st = np.zeros(BLOCK, np.intc)
    pu = ctl.ffi.cast("stsp_scalar_t *", ctl.ffi.from_buffer(us))
    ps = ctl.ffi.cast("int *", ctl.ffi.from_buffer(st))
    t = time.process_time()
    for c in range(calls):
        ctl.lib.harness_step_batch(step.instances, BLOCK, c % ticks, xs, pu, ps)
    out["controller (stsp_step)"] = time.process_time() - t
    stage = problem.stages[0]
    h = 1.0 / table.tick_hz
    plant = ctl.plant(stage, *_zoh(stage, h), h, 1)
    Xd = np.tile(problem.x0, (BLOCK, 1))
    cost = np.zeros(BLOCK)
    dZ[:] = 0.0
    t = time.process_time()
    for _ in range(calls):
        ctl.plant_tick(plant, dZ, us, Xd, cost)
    out["plant (1 step)"] = time.process_time() - t
    # the step generic in the stage data, for comparison (not part of the harness's time)
    generic = build_controller(table)
    plant = generic.plant(stage, *_zoh(stage, h), h, 1)
    t = time.process_time()
    for _ in range(calls):
        generic.plant_tick(plant, dZ, us, Xd, cost)
    out["generic plant step"] = time.process_time() - t
    return out


# The commands run as an installed package runs: with its modules' bytecode compiled (pip
# compiles it; here into a directory of its own, PYTHONPYCACHEPREFIX), not from source.
_PYC = tempfile.mkdtemp(prefix="stospline-bench-pyc-")


def _command_env() -> dict:
    env = {**os.environ, "PYTHONPATH": str(ROOT / "host"), "PYTHONPYCACHEPREFIX": _PYC}
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    return env


def command_seconds(paths: int) -> tuple[float, float]:
    """Wall and CPU seconds (user + system, the command and its workers) of the whole
    `stospline simulate` command."""
    import resource
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    subprocess.run([sys.executable, "-m", "stospline", "simulate",
                    str(ROOT / "examples" / "robot_corridor.toml"), "--paths", str(paths),
                    "--json"], check=True, env=_command_env(), stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def alongside_seconds() -> float:
    """CPU seconds, in a fresh process, of what the command does while its paths run
    (`pipeline._summary_ahead`: scipy.special imported, the corridor's exit-bound oracle
    pass, the fourth-moment oracle): the serial part of the command is its CPU with 2 paths
    less this."""
    code = ("import time\n"
            "from stospline.pipeline import _summary_ahead, design_problem\n"
            "from stospline.problem import load_problem\n"
            f"d = design_problem(load_problem({str(ROOT / 'examples' / 'robot_corridor.toml')!r}))\n"
            "t = time.process_time()\n"
            "_summary_ahead(d, 1, d.problem.faults)\n"
            "print(time.process_time() - t)\n")
    out = subprocess.run([sys.executable, "-c", code], check=True, env=_command_env(),
                         capture_output=True, text=True).stdout
    return float(out.split()[-1])


_PARTS = ("scipy.special imported", "the exit bounds' oracle pass",
          "the fourth-moment oracle (C loop)", "the same, numpy loop (not run by the command)")


def alongside_parts() -> list[float]:
    """CPU seconds, in a fresh process, of each part of the work beside the paths, one after
    another (`_PARTS`), and the fourth-moment oracle's numpy loop for comparison."""
    code = ("import os, time\n"
            "from stospline.pipeline import design_problem\n"
            "from stospline.problem import load_problem\n"
            "from stospline.harness.exit_stats import clopper_pearson_upper, "
            "corridor_outputs_of\n"
            "from stospline.oracle.tails import evaluate_tails\n"
            f"d = design_problem(load_problem({str(ROOT / 'examples' / 'robot_corridor.toml')!r}))\n"
            "def cpu(f):\n"
            "    t = time.process_time(); f(); return time.process_time() - t\n"
            "tails = lambda: evaluate_tails(d.problem, d.table, substeps=1, check=False)\n"
            "out = [cpu(lambda: clopper_pearson_upper(0, 1)),\n"
            "       cpu(lambda: corridor_outputs_of(d.problem, d.table)), cpu(tails)]\n"
            "os.environ['STOSPLINE_ORACLE_KERNEL'] = 'numpy'\n"
            "print(*out, cpu(tails))\n")
    out = subprocess.run([sys.executable, "-c", code], check=True, env=_command_env(),
                         capture_output=True, text=True).stdout
    return [float(v) for v in out.split()[-len(_PARTS):]]


def _loads(avg) -> str:
    return ", ".join(f"{v:.2f}" for v in avg)


def whole_command(paths: int, workers: int, repeat: int, ticks: int) -> None:
    """The whole command's wall and CPU time, and from them its wall on idle cores."""
    command_seconds(2)                      # warm the caches (the compiled controller)
    load_before = os.getloadavg()
    runs = [command_seconds(paths) for _ in range(repeat)]
    wall = statistics.median(r[0] for r in runs)
    cpu = statistics.median(r[1] for r in runs)
    small = statistics.median(command_seconds(2)[1] for _ in range(repeat))
    ahead = statistics.median(alongside_seconds() for _ in range(repeat))
    parts = [statistics.median(v) for v in zip(*(alongside_parts() for _ in range(repeat)))]
    serial = small - ahead
    work = paths * ticks
    print(f"\nwhole command, stospline simulate examples/robot_corridor.toml --paths "
          f"{paths} --json (median of {repeat}):")
    print(f"  {wall:.2f} s wall, {work / wall:.3e} path-ticks/s of wall time")
    print(f"  load average (1, 5, 15 min) before: {_loads(load_before)}, after: "
          f"{_loads(os.getloadavg())}")
    print(f"  {cpu:.2f} s CPU (command and workers); with 2 paths {small:.2f} s, of which "
          f"{ahead:.2f} s run beside the paths (scipy.special, the exit bounds' oracle, the "
          f"fourth-moment oracle)")
    for name, sec in zip(_PARTS, parts):
        print(f"    {name:48s} {sec:6.3f} s")
    print(f"  in series: S = {small:.2f} - {ahead:.2f} = {serial:.2f} s (imports, design, "
          f"substep pilot and plant-scheme oracle, the summary)")
    print(f"  per path-tick: {(cpu - small) / work * 1e9:.1f} ns of CPU (workers)")
    idle = serial + (cpu - serial) / workers
    print(f"  on {workers} idle cores: S + (CPU - S) / {workers} = {idle:.2f} s wall, "
          f"{work / idle:.3e} path-ticks/s")


def one_core_and_baseline(problem, d, ctl, paths: int, repeat: int) -> None:
    """The harness on one core beside the hand-written C loop, and the breakdown."""
    ticks = d.table.n_ticks
    work = paths * ticks
    bare = replace(problem, corridors=())
    # the same corridor to the last bit of C but one: not the module's compiled corridor, so
    # the generic watch runs (with the module's compiled plant step)
    cor = problem.corridors[0]
    other = replace(problem, corridors=(replace(cor, C=cor.C * (1 + 2.0**-52)),))
    same = replace(ctl)
    same.for_plant = lambda _problem: same
    with tempfile.TemporaryDirectory() as tmp:
        ffi, lib = build_c_loop(tmp)
        c_loop_seconds(ffi, lib, problem, d.table, BLOCK, True)          # warm
        simulate(problem, ctl, paths=BLOCK, seed=1, substeps=1, workers=1)
        rows = {"harness": [], "harness without the corridor": [],
                "harness, generic corridor watch": [],
                "hand-written C, normals drawn": [], "hand-written C, no normals": []}
        for _ in range(repeat):
            rows["harness"].append(harness_seconds(problem, ctl, paths))
            rows["harness without the corridor"].append(harness_seconds(bare, ctl, paths))
            rows["harness, generic corridor watch"].append(harness_seconds(other, same, paths))
            rows["hand-written C, normals drawn"].append(
                c_loop_seconds(ffi, lib, problem, d.table, paths, True))
            rows["hand-written C, no normals"].append(
                c_loop_seconds(ffi, lib, problem, d.table, paths, False))
    med = {k: statistics.median(v) for k, v in rows.items()}
    base = med["hand-written C, normals drawn"]
    print(f"\none core, {paths} paths, 1 plant step per tick, CPU time, median of {repeat}:")
    print(f"{'':32s} {'path-ticks/s':>13s} {'ns/path-tick':>13s} {'time / hand-written':>20s}")
    for name, sec in med.items():
        print(f"{name:32s} {work / sec:13.3e} {sec / work * 1e9:13.1f} {sec / base:20.2f}")
    parts = part_seconds(problem, ctl, paths)
    whole = med["harness"] / work * 1e9
    watch = (med["harness"] - med["harness without the corridor"]) / work * 1e9
    print("where the harness's time goes per path-tick (parts run apart, ns):")
    known = watch
    print(f"  {'corridor watch':30s} {watch:6.1f}")
    generic = parts.pop("generic plant step") / work * 1e9
    for name, sec in parts.items():
        ns = sec / work * 1e9
        known += ns
        print(f"  {name:30s} {ns:6.1f}")
    print(f"  {'the rest (loop, statistics)':30s} {whole - known:6.1f}")
    print(f"  {'total':30s} {whole:6.1f}")
    generic_watch = (med["harness, generic corridor watch"]
                     - med["harness without the corridor"]) / work * 1e9
    print(f"  (the plant step generic in the stage data instead: {generic:.1f}; the generic "
          f"corridor watch: {generic_watch:.1f})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--paths", default="1000,10000,100000")
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--command-paths", type=int, default=20000)
    ap.add_argument("--baseline-paths", type=int, default=4096)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--command-only", action="store_true",
                    help="only the whole command's figures (a minute or two)")
    args = ap.parse_args()
    counts = [int(v) for v in args.paths.split(",")]
    workers = args.workers or default_workers()

    problem = load_problem(ROOT / "examples" / "robot_corridor.toml")
    d = design_problem(problem)
    ctl = build_controller(d.table, plant=problem)   # the plant step compiled for it
    ticks = d.table.n_ticks
    if args.command_only:
        whole_command(args.command_paths, workers, args.repeat, ticks)
        return
    print(f"robot corridor, {ticks} ticks, {SUBSTEPS} plant steps per tick; stospline on "
          f"{workers} worker process(es), numpy in one; {os.cpu_count()} CPUs reported")
    print(f"{'paths':>9} {'stospline':>16} {'numpy':>16} {'ratio':>6} "
          f"{'stospline s/path':>17}  mean cost (stospline, numpy)")
    simulate(problem, ctl, paths=100, seed=args.seed, substeps=SUBSTEPS)   # warm caches
    for paths in counts:
        t = time.perf_counter()
        mc = simulate(problem, ctl, paths=paths, seed=args.seed, substeps=SUBSTEPS,
                      workers=workers)
        t_ours = time.perf_counter() - t
        ours = rate(paths, ticks, t_ours)
        base_text, ratio_text, base_cost = f"{'-':>16}", f"{'-':>6}", ""
        if paths <= 10_000:
            t = time.perf_counter()
            c = numpy_loop(problem, d.table, paths, args.seed)
            base = rate(paths, ticks, time.perf_counter() - t)
            base_text, ratio_text = f"{base:12.3e} p-t/s", f"{ours / base:6.2f}"
            base_cost = f", {c.mean():.4f}"
        print(f"{paths:>9} {ours:12.3e} p-t/s {base_text} {ratio_text} "
              f"{t_ours / paths * 1e3:14.3f} ms  {mc.cost_mean_ci()[0]:.4f}{base_cost}")
    one_core_and_baseline(problem, d, ctl, args.baseline_paths, args.repeat)
    if args.command_paths:
        whole_command(args.command_paths, workers, args.repeat, ticks)


if __name__ == "__main__":
    main()
