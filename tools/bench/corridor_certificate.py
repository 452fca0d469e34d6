#!/usr/bin/env python3
"""How long the chance-constrained robot's certificate at eps = 1e-4 takes through C, and the
certificate itself.

`--file` (default examples/robot_corridor_eps1e4.toml: the robot with running costs and a
corridor that carries a risk budget of 1e-4; examples/robot_corridor_eps01.toml carries 0.01),
designed as the file says, is simulated through its compiled C controller.

Timing (the default): `--paths` paths (default 10^5) with the plant steps per tick that
`stospline simulate` would choose for that run, once with the plant step and corridor watch
compiled for the problem (`stospline.harness.plant_spec`, what the harness does) and once with
the generic ones (the baseline, in the same run). Each run's time is extrapolated to the
certificate's `--certify-paths` (default 3·10^6: a design whose exit probability is near eps
needs that many for a one-sided 99 % bound below it), also at the steps per tick chosen for
that many paths (the scheme's bias must then be smaller), measured on fewer paths. Prints
wall and CPU time (the command and its workers; wall time is meaningless on a loaded machine,
CPU time over the cores is what idle cores would take) and what a run under 10 minutes needs
per path-tick.

`--scheme weak2` runs the plant scheme of weak order two in the second moments
(`stospline.harness.weak_scheme`: the expected cost's bias falls as 1/substeps^2, so the
steps chosen for 3·10^6 paths are fewer); `--scheme euler` (default) the exponential
Euler-Maruyama scheme `stospline simulate` runs.

`--certify`: the certificate itself: `--certify-paths` fresh paths (seed `--seed`) at the
steps per tick `choose_substeps` picks for that many paths with `--scheme` (or `--substeps`),
on `--workers` local processes; prints wall and CPU time, CPU per path-tick, the exits, the
one-sided 99 % Clopper-Pearson bound and the verdict against `--epsilon` (default 1e-4) and the
file's own epsilon. With `--cluster N` the same run is then spread over a Dask cluster this
script starts as a user would, each its own process (``dask scheduler --port 0``, N times
``dask worker --nthreads 1``), stopped at the end; `--cluster-only` skips the local run,
`--scheduler ADDR` uses a running cluster instead. The cluster's numbers (exits by tick, the
cost's and knot states' moments, the mean path) are compared with the local run's, bit for bit.

`--exit-bias`: the exits (and the oracle's expected-cost bias) of each `--runs` entry
(scheme:steps) on `--problem-file` (default examples/robot_corridor.toml) at `--hz` ticks per
second, `--paths` paths each, one seed: how each scheme's exit probability moves with its
steps per tick, which `choose_substeps` does not bound (it bounds the cost's bias).

    PYTHONPATH=host .venv/bin/python tools/bench/corridor_certificate.py [--paths 100000]
        [--certify-paths 3000000] [--workers N] [--seed 1] [--scheme euler|weak2]
    PYTHONPATH=host nice .venv/bin/python tools/bench/corridor_certificate.py --certify
        --scheme weak2 [--certify-paths 3000000] [--cluster 3] [--cluster-only]
        [--scheduler ADDR] [--substeps S] [--epsilon 1e-4]
    PYTHONPATH=host .venv/bin/python tools/bench/corridor_certificate.py --exit-bias --hz 10
        --paths 40000 [--problem-file F] [--runs euler:1,euler:8,weak2:1,...]
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

from stospline.harness import controller as controller_module  # noqa: E402
from stospline.harness.controller import build_controller  # noqa: E402
from stospline.harness.exit_stats import clopper_pearson_upper  # noqa: E402
from stospline.harness.montecarlo import default_workers, simulate  # noqa: E402
from stospline.harness.weak_scheme import SCHEMES, scheme_problem  # noqa: E402
from stospline.pipeline import design_problem, plan_substeps  # noqa: E402
from stospline.problem import load_problem  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
BUDGET = 600.0              # seconds: the certificate's target on this machine


def cpu_seconds() -> float:
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def timed_run(problem, ctl, paths: int, substeps: int, seed: int, workers: int,
              scheme: str = "euler"):
    """(wall s, CPU s, exits) of one `simulate` (forked workers' CPU counted when they end)."""
    c, t = cpu_seconds(), time.perf_counter()
    mc = simulate(scheme_problem(problem, substeps, scheme), ctl, paths=paths, seed=seed,
                  substeps=substeps, workers=workers)
    return time.perf_counter() - t, cpu_seconds() - c, mc.exit_count(0)


def timing(problem, d, args, workers: int) -> None:
    """The timing table (the module docstring's default mode)."""
    ticks, scheme = d.table.n_ticks, args.scheme
    run_steps = plan_substeps(d, paths=args.paths, seed=args.seed, scheme=scheme).substeps
    cert_steps = plan_substeps(d, paths=args.certify_paths, seed=args.seed,
                               scheme=scheme).substeps
    print(f"{problem.name}, {ticks} ticks; {workers} worker process(es); scheme "
          f"{scheme}; plant steps per tick chosen: {run_steps} for {args.paths} paths, "
          f"{cert_steps} for {args.certify_paths}")
    ctl = build_controller(d.table)
    simulate(scheme_problem(problem, run_steps, scheme), ctl, paths=64, seed=args.seed,
             substeps=run_steps, workers=1)                                  # build

    rows = {}
    rows["compiled plant and corridor"] = timed_run(problem, ctl, args.paths, run_steps,
                                                    args.seed, workers, scheme)
    real = controller_module.plant_source
    controller_module.plant_source = lambda *a: None        # the generic step and watch
    try:
        rows["generic plant and corridor"] = timed_run(problem, ctl, args.paths, run_steps,
                                                       args.seed, workers, scheme)
    finally:
        controller_module.plant_source = real
    # at the certificate's steps per tick, on as many path-steps as the runs above
    cert_paths = max(2048, args.paths * run_steps // cert_steps)
    rows[f"compiled, {cert_steps} steps per tick"] = timed_run(
        problem, ctl, cert_paths, cert_steps, args.seed, workers, scheme)
    print(f"\nrun, then extrapolated to the certificate's {args.certify_paths} paths "
          f"(CPU time over {workers} idle cores):")
    print(f"{'':34s} {'paths':>7s} {'steps':>5s} {'wall s':>7s} {'CPU s':>7s} {'exits':>6s} "
          f"{'ns/path-tick':>12s} {'certificate':>12s}")
    for (name, (wall, cpu, exits)), paths, steps in zip(
            rows.items(), (args.paths, args.paths, cert_paths),
            (run_steps, run_steps, cert_steps)):
        ns = cpu / (paths * ticks) * 1e9
        idle = ns * 1e-9 * args.certify_paths * ticks / workers
        print(f"{name:34s} {paths:7d} {steps:5d} {wall:7.1f} {cpu:7.1f} {exits:6d} "
              f"{ns:12.1f} {idle / 60:8.1f} min")
    need = BUDGET * workers / (args.certify_paths * ticks) * 1e9
    print(f"\nunder {BUDGET / 60:.0f} min on {workers} idle cores: at most {need:.1f} ns CPU per "
          f"path-tick (the certificate's serial work, design and oracle, not counted)")


class Cluster:
    """A Dask scheduler and `workers` single-threaded workers, each started as its own process
    as a user would (``dask scheduler``, ``dask worker``), stopped on exit; `address`."""

    def __init__(self, workers: int):
        self.workers, self.procs = workers, []
        self.dir = tempfile.TemporaryDirectory(prefix="stospline-cluster-")
        self.dask = str(Path(sys.executable).with_name("dask"))

    def __enter__(self) -> "Cluster":
        file = Path(self.dir.name) / "scheduler.json"
        out = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
        self.procs.append(subprocess.Popen([self.dask, "scheduler", "--port", "0",
                                            "--no-dashboard", "--scheduler-file", str(file)],
                                           **out))
        end = time.monotonic() + 120
        while not (file.exists() and file.stat().st_size):
            if time.monotonic() > end:
                raise TimeoutError("the dask scheduler wrote no address in 120 s")
            time.sleep(0.2)
        self.address = json.loads(file.read_text())["address"]
        self.procs += [subprocess.Popen([self.dask, "worker", self.address, "--nthreads", "1",
                                         "--no-dashboard"], **out)
                       for _ in range(self.workers)]
        from distributed import Client
        with Client(self.address, timeout="60s") as client:
            client.wait_for_workers(self.workers, timeout=120)
        return self

    def cpu_seconds(self) -> float:
        """CPU seconds so far of the cluster's processes and theirs (the workers' nannies
        start the worker processes)."""
        import psutil
        total = 0.0
        for p in self.procs:
            try:
                proc = psutil.Process(p.pid)
                for q in [proc, *proc.children(recursive=True)]:
                    t = q.cpu_times()
                    total += t.user + t.system
            except psutil.NoSuchProcess:
                pass
        return total

    def __exit__(self, *exc) -> None:
        for p in self.procs[::-1]:
            p.terminate()
        for p in self.procs:
            try:
                p.wait(timeout=60)
            except subprocess.TimeoutExpired:
                p.kill()
        self.dir.cleanup()


def _numbers(mc) -> dict:
    """What the certificate and the summary read from a run, to compare two runs bit for bit."""
    out = {"exits by tick": mc.exits.by_tick[0].tolist(), "exit examples": mc.exits.examples,
           "mean path": mc.mean_x.tobytes(), "sample path": mc.sample_x.tobytes(),
           "statuses": (mc.worst_status, mc.saturated_tick_count)}
    for k, mom in enumerate([mc.cost_moments, *mc.knot_moments]):
        for name in ("mean", "comoment", "m3", "m4", "low", "high"):
            out[f"{'cost' if k == 0 else f'knot {k}'} {name}"] = \
                np.asarray(getattr(mom, name)).tobytes()
    return out


def certify(problem, d, args, workers: int) -> None:
    """The certificate at --certify-paths, here and/or on a Dask cluster (the module's
    docstring)."""
    ticks, paths, scheme = d.table.n_ticks, args.certify_paths, args.scheme
    t = time.perf_counter()
    if args.substeps:
        steps, why = args.substeps, "given"
    else:
        choice = plan_substeps(d, paths=paths, seed=args.seed, scheme=scheme)
        steps = choice.substeps
        why = (f"chosen: expected-cost bias {choice.bias:+.3g} against the target "
               f"{choice.target:.3g} (0.1 x 0.8 x the predicted standard error "
               f"{choice.stderr:.3g})")
    run_problem = scheme_problem(problem, steps, scheme)
    ctl = build_controller(d.table, plant=run_problem)
    simulate(run_problem, ctl, paths=64, seed=args.seed, substeps=steps, workers=1)   # build
    eps_file = problem.corridors[0].epsilon
    print(f"{problem.name}, {ticks} ticks, {paths} paths, seed {args.seed}, scheme "
          f"{scheme}, {steps} plant step(s) per tick ({why}); set-up "
          f"{time.perf_counter() - t:.1f} s")
    runs = {}

    def report(name, wall, cpu, mc):
        k = mc.exit_count(0)
        upper = clopper_pearson_upper(k, paths)
        mean, half = mc.cost_mean_ci()
        verdicts = ", ".join(f"eps {eps:g}: {'certified' if upper <= eps else 'not certified'}"
                             for eps in (args.epsilon, eps_file) if eps)
        print(f"  {name}: {wall:.1f} s wall, {cpu:.1f} s CPU, "
              f"{cpu / (paths * ticks) * 1e9:.1f} ns CPU per path-tick; exits {k} of {paths} "
              f"({k / paths:.3g}), one-sided 99 % upper bound {upper:.6g}; {verdicts}; "
              f"cost mean {mean!r} +- {half:.3g}")
        runs[name] = _numbers(mc)

    if not args.cluster_only:
        c, t = cpu_seconds(), time.perf_counter()
        mc = simulate(run_problem, ctl, paths=paths, seed=args.seed, substeps=steps,
                      workers=workers)
        report(f"here, {workers} worker process(es)", time.perf_counter() - t,
               cpu_seconds() - c, mc)
    if args.cluster or args.scheduler:
        def on(address, cluster=None):
            c0 = cluster.cpu_seconds() if cluster else 0.0
            c, t = cpu_seconds(), time.perf_counter()
            mc = simulate(run_problem, ctl, paths=paths, seed=args.seed, substeps=steps,
                          scheduler=address)
            wall = time.perf_counter() - t
            cpu = cpu_seconds() - c + ((cluster.cpu_seconds() - c0) if cluster else 0.0)
            report(f"Dask cluster at {address}" + (f" ({cluster.workers} `dask worker` "
                                                   f"processes)" if cluster else ""),
                   wall, cpu, mc)
        if args.scheduler:
            on(args.scheduler)
        else:
            t = time.perf_counter()
            with Cluster(args.cluster) as cluster:
                print(f"  started `dask scheduler` and {args.cluster} `dask worker "
                      f"--nthreads 1` processes in {time.perf_counter() - t:.1f} s")
                on(cluster.address, cluster)
    if len(runs) == 2:
        a, b = runs.values()
        differ = [key for key in a if a[key] != b[key]]
        print("  the two runs' numbers: " + ("bit-identical (exits by tick, cost and knot "
                                             "moments, mean and sample path)" if not differ
                                             else "DIFFER in " + ", ".join(differ)))


def exit_bias(args, workers: int) -> None:
    """Exits and expected-cost bias of each scheme and step count of `--runs` on
    `--problem-file` at `--hz` ticks per second (the same seed for every run)."""
    import tomllib
    from stospline.oracle.evaluate import evaluate_table
    from stospline.problem import parse_problem
    doc = tomllib.loads((ROOT / args.problem_file).read_text())
    if args.hz:
        doc["tick_hz"] = args.hz
    problem = parse_problem(doc)
    d = design_problem(problem)
    ctl = build_controller(d.table)
    exact = d.implemented.J
    print(f"{args.problem_file} at {doc['tick_hz']} Hz, {d.table.n_ticks} ticks, "
          f"{args.paths} paths a run, seed {args.seed}; exact expected cost {exact:.6g}")
    print(f"{'scheme':>7s} {'steps':>5s} {'exits':>7s} {'P(exit)':>8s} {'+- 1 se':>8s} "
          f"{'cost bias (oracle)':>19s} {'CPU s':>6s} {'ns/path-tick':>12s}")
    for item in args.runs.split(","):
        scheme, steps = item.split(":")
        steps = int(steps)
        run = scheme_problem(problem, steps, scheme)
        c = cpu_seconds()
        mc = simulate(run, ctl, paths=args.paths, seed=args.seed, substeps=steps,
                      workers=workers)
        cpu = cpu_seconds() - c
        k = mc.exit_count(0)
        p = k / args.paths
        bias = evaluate_table(run, d.table, propagator="euler", substeps=steps,
                              path=False).J - exact
        print(f"{scheme:>7s} {steps:5d} {k:7d} {p:8.5f} {np.sqrt(p * (1 - p) / args.paths):8.5f} "
              f"{bias:+19.3e} {cpu:6.1f} {cpu / (args.paths * d.table.n_ticks) * 1e9:12.1f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--paths", type=int, default=100_000)
    ap.add_argument("--certify-paths", type=int, default=3_000_000)
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--scheme", choices=SCHEMES, default="euler")
    ap.add_argument("--certify", action="store_true")
    ap.add_argument("--substeps", type=int, default=0)
    ap.add_argument("--epsilon", type=float, default=1e-4)
    ap.add_argument("--cluster", type=int, default=0)
    ap.add_argument("--cluster-only", action="store_true")
    ap.add_argument("--scheduler", default=None)
    ap.add_argument("--file", default="examples/robot_corridor_eps1e4.toml",
                    help="the design timed and certified (default: the robot's corridor "
                         "designed for eps = 1e-4)")
    ap.add_argument("--exit-bias", action="store_true")
    ap.add_argument("--problem-file", default="examples/robot_corridor.toml")
    ap.add_argument("--hz", type=int, default=0)
    ap.add_argument("--runs", default="euler:1,euler:2,euler:8,euler:32,weak2:1,weak2:2,weak2:4")
    args = ap.parse_args()
    workers = args.workers or default_workers()
    if args.exit_bias:
        exit_bias(args, workers)
        return
    problem = load_problem(ROOT / args.file)
    d = design_problem(problem)
    if args.certify:
        certify(problem, d, args, workers)
    else:
        timing(problem, d, args, workers)


if __name__ == "__main__":
    main()
