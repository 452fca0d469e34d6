#!/usr/bin/env python3
"""Monte Carlo throughput of the harness against a plain numpy loop, in the same run.

Both simulate the robot corridor (examples/robot_corridor.toml, 6000 ticks at 1 kHz) with the
same plant scheme (exponential Euler-Maruyama, 2 steps per tick, Gaussian increments):

* **stospline**: `stospline.sim.montecarlo.simulate`, the compiled C controller of the
  float32 table in the loop, blocks of paths spread over `--workers` processes (default:
  every core), the normal numbers from its C generator (xoshiro256++ and a ziggurat);
* **numpy**: the same closed loop written as one would in numpy, in one process: the law
  ``u = -(K x + k0 + L v)`` with the table's gains in float64 (v latched at each stage start,
  ``v = Lambda x + lambda0``), the plant step and the noise as matrix products, the running
  cost; no controller logic (tick checks, limits, statuses), so it is a lower bound on what
  a numpy harness costs; normal numbers from ``numpy.random.default_rng``.

Prints path-ticks per second for each path count, their ratio, and the time per path (which
must stay flat: time linear in paths). The numpy baseline runs up to 10^4 paths (beyond, its
time is linear too and only costs minutes).

    .venv/bin/python tools/bench/harness_throughput.py [--paths 1000,10000,100000] [--workers N]

Add 1000000 to --paths for the 10^6-path point (about 5 minutes on 2 cores).
"""
from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")      # one BLAS thread per process, for both sides

import numpy as np  # noqa: E402

from stospline.expm import expm  # noqa: E402
from stospline.pipeline import design_problem  # noqa: E402
from stospline.problem import load_problem  # noqa: E402
from stospline.sim.controller import build_controller  # noqa: E402
from stospline.sim.montecarlo import default_workers, simulate  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
SUBSTEPS = 2


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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--paths", default="1000,10000,100000")
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    counts = [int(v) for v in args.paths.split(",")]
    workers = args.workers or default_workers()

    problem = load_problem(ROOT / "examples" / "robot_corridor.toml")
    d = design_problem(problem)
    ctl = build_controller(d.table)
    ticks = d.table.n_ticks
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


if __name__ == "__main__":
    main()
