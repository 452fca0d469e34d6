"""Design-time benchmark of problems whose data vary in time, against a plain solve_ivp.

Usage: .venv/bin/python tools/bench/varying_design.py [--repeat 3] [--accuracy] [--previous]
       [--dense-only]

Every time is the median of `--repeat` runs after one warm-up run (which also builds the
cached C kernels), measured with ``time.perf_counter``, the dense case also in CPU time
(``time.process_time``, every thread); BLAS threads are pinned to 1 before numpy is imported.
Figures are in docs/evidence/performance.md.

Problem
-------
`varying_chain(blocks, hz)`: `blocks` position/velocity/first-order-actuator chains (n = 3 *
blocks states, m = blocks inputs) coupled by springs, over 3.3 s in 3 stages of 1.1 s, every
knot constraining the expected positions. The dampings, actuator rates and spring constants
are scaled by 1 + 0.5 sin(1.7 t + phase) and the velocity noise (two Brownian components) by
1 + 0.5 cos(1.1 t + phase), sampled every 0.1 s and interpolated linearly (`A` and the
`noise` G are time-varying; seeded). blocks = 1 gives n = 3, blocks = 4 n = 12. Its noise is
sparse: one entry per velocity.

`dense_chain(varying_noise)`: the dense case. The n = 12, m = 4 chain over 3.441 s (3 441
ticks at 1 kHz) in 3 stages, its data sampled 5 times per stage (16 samples) and interpolated
linearly, with state noise on every state and input noise on every input: 16 dense 12 x 8
matrices G (mz = 8, seeded), constant, or (`varying_noise`) sampled with the drift.

Measured
--------
"design": `design_zoh` (the exact zero-order-hold law); "whole": `design_problem`, which is
what `stospline design` runs (the design, the float32 table, and the exact oracle on the
design's law and on the table, the two at once in two threads: `pipeline._concurrently`).
Each run starts cold: the samples of the data and the tick maps cached by the run before are
dropped.

Baseline
--------
"solve_ivp": the continuous-time Riccati equation of the feedback alone,
``-P' = A'P + PA + Q + Pi(P) - (PB + S) R^-1 (PB + S)'`` with ``Pi(P)_kl = tr(G_k' P G_l)``,
integrated backward over each stage with `scipy.integrate.solve_ivp` (DOP853, rtol 1e-12,
atol 1e-12 times the terminal scale), the data at each right-hand-side call from
`Stage.at(t)`, knot penalties added at the knots: the least a continuous-time design must
compute. The package's full continuous design (`design_continuous`: P, p, c, N, W, m and the
latches, the same integrator) is timed too. The ratio is baseline / whole.

Accuracy (``--accuracy``)
-------------------------
The designer and the C oracle interpolate the data through the same two Gauss points per tick
(order 4), so their agreement checks the recursions, not the interpolation. Both are compared
with the reference oracle, which integrates the moment equations over every tick with DOP853
(rtol 1e-12, ``STOSPLINE_ORACLE_KERNEL=numpy``) and shares no code with the C loops, evaluating
the designer's own law (the unquantized table).

Then ``stospline design`` end to end, a new process per run, on the problem written as a file.

``--previous`` also times a reference implementation at n = 3 (the designer's
per-tick Magnus exponential of the d^2 + 1 square moment generator, kernel="numpy", and the
DOP853 oracle): tens of seconds at n = 12, so only n = 3 by default.
"""
from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse                                     # noqa: E402
import subprocess                                   # noqa: E402
import sys                                          # noqa: E402
import tempfile                                     # noqa: E402
import time                                         # noqa: E402
from pathlib import Path                            # noqa: E402

import numpy as np                                  # noqa: E402
from scipy.integrate import solve_ivp               # noqa: E402

from stospline.design.continuous import design_continuous, noise_operator   # noqa: E402
from stospline.design import varying                # noqa: E402
from stospline.design.zoh import design_zoh         # noqa: E402
from stospline.pipeline import design_problem       # noqa: E402
from stospline.problem import parse_problem         # noqa: E402
from stospline.problem.toml_writer import problem_to_toml   # noqa: E402
from stospline.oracle import evaluate as oracle                    # noqa: E402
from stospline.oracle.evaluate import evaluate_table     # noqa: E402
from stospline.table.format import table_of         # noqa: E402

HORIZON, STAGES, SAMPLE_DT = 3.3, 3, 0.1


def varying_chain(blocks: int, hz: int = 1000, seed: int = 11):
    """The benchmark problem (see the module docstring)."""
    rng = np.random.default_rng(seed)
    n, m = 3 * blocks, blocks
    ts = np.round(np.arange(0.0, HORIZON + 1e-9, SAMPLE_DT), 10)
    damp, act = rng.uniform(0.1, 0.5, blocks), rng.uniform(2.0, 5.0, blocks)
    spring, phase = rng.uniform(0.2, 1.0, blocks), rng.uniform(0, 2 * np.pi, blocks)
    As = []
    for t in ts:
        A = np.zeros((n, n))
        for b in range(blocks):
            i, w = 3 * b, 1 + 0.5 * np.sin(1.7 * t + phase[b])
            A[i, i + 1] = A[i + 1, i + 2] = 1.0
            A[i + 1, i + 1], A[i + 2, i + 2] = -damp[b] * w, -act[b] * w
            if b:
                k = spring[b] * w
                A[i + 1, i - 3] += k; A[i + 1, i] -= k
                A[i - 2, i] += k; A[i - 2, i - 3] -= k
        As.append(A.tolist())
    B = np.zeros((n, m))
    B[3 * np.arange(blocks) + 2, np.arange(blocks)] = act
    noise = []
    for b in range(blocks):
        vals = []
        for t in ts:
            G = np.zeros((n, 2))
            G[3 * b + 1, b % 2] = 0.3 * (1 + 0.5 * np.cos(1.1 * t + phase[b]))
            vals.append(G.tolist())
        noise.append({"state": 3 * b + 1, "G": {"t": ts.tolist(), "values": vals}})
    C = np.zeros((blocks, n))
    C[np.arange(blocks), 3 * np.arange(blocks)] = 1.0
    knots = [{"t": round(HORIZON / STAGES * (k + 1), 10),
              "constraint": {"C": C.tolist(), "value": rng.normal(size=blocks).tolist()}}
             for k in range(STAGES)]
    return parse_problem({
        "name": "varying", "x0": rng.normal(size=n).tolist(), "tick_hz": hz,
        "dynamics": {"A": {"t": ts.tolist(), "values": As}, "B": B.tolist(), "noise": noise},
        "cost": {"R": (0.1 * np.eye(m)).tolist(), "Q": (0.01 * np.eye(n)).tolist()},
        "knots": knots})


DENSE_HORIZON, DENSE_MZ = 3.441, 8


def dense_chain(varying_noise: bool, hz: int = 1000, seed: int = 5):
    """The dense benchmark problem (see the module docstring)."""
    rng = np.random.default_rng(seed)
    base = varying_chain(4, hz)
    n, m = 12, 4
    ts = np.round(np.linspace(0.0, DENSE_HORIZON, 5 * STAGES + 1), 10)
    noise = []
    for i in range(n + m):
        G0, G1 = rng.normal(scale=0.05, size=(2, n, DENSE_MZ))
        vals = [(G0 * (1 + 0.5 * np.cos(1.1 * t)) + G1 * np.sin(0.7 * t)).tolist() for t in ts]
        entry = {"G": {"t": ts.tolist(), "values": vals} if varying_noise else vals[0]}
        entry["state" if i < n else "input"] = i if i < n else i - n
        noise.append(entry)
    A = [base.stages[0].at(min(t, HORIZON)).A.tolist() for t in ts]
    C = np.zeros((4, n))
    C[np.arange(4), 3 * np.arange(4)] = 1.0
    knots = [{"t": round(DENSE_HORIZON / STAGES * (k + 1), 10),
              "constraint": {"C": C.tolist(), "value": rng.normal(size=4).tolist()}}
             for k in range(STAGES)]
    return parse_problem({
        "name": "dense", "x0": rng.normal(size=n).tolist(), "tick_hz": hz,
        "dynamics": {"A": {"t": ts.tolist(), "values": A},
                     "B": base.stages[0].B.tolist(), "noise": noise},
        "cost": {"R": (0.1 * np.eye(m)).tolist(), "Q": (0.01 * np.eye(n)).tolist()},
        "knots": knots})


def riccati_baseline(problem) -> np.ndarray:
    """P(t0) of the continuous-time feedback Riccati equation by solve_ivp (the baseline)."""
    n = problem.n
    P = np.zeros((n, n))
    for k in range(len(problem.knots) - 1, -1, -1):
        pen = problem.knots[k].penalty
        if pen is not None:
            P = P + pen.weight * pen.C.T @ pen.C
        stage = problem.stages[k]

        def rhs(t, y, stage=stage):
            s = stage.at(t)
            Pt = y.reshape(n, n)
            GH = s.noise_tensor[:n]
            PBS = Pt @ s.B + s.S
            dP = s.A.T @ Pt + Pt @ s.A + s.Q + noise_operator(GH, Pt) \
                - PBS @ np.linalg.solve(s.R, PBS.T)
            return -dP.ravel()

        scale = max(float(np.abs(P).max()), 1.0)
        res = solve_ivp(rhs, (problem.times[k + 1], problem.times[k]), P.ravel(),
                        method="DOP853", rtol=1e-12, atol=1e-12 * scale)
        P = res.y[:, -1].reshape(n, n)
    return P


def cold():
    """Forget the samples and tick maps cached by earlier runs, as a new process would."""
    varying._CACHE.clear()
    varying._PAYS.clear()
    oracle._MAPS.clear()


def median_times(fn, repeat: int) -> tuple[float, float]:
    """Median wall time and median CPU time (every thread of the process) of `repeat` cold
    runs after a warm-up."""
    cold()
    fn()
    walls, cpus = [], []
    for _ in range(repeat):
        cold()
        c, t = time.process_time(), time.perf_counter()
        fn()
        walls.append(time.perf_counter() - t)
        cpus.append(time.process_time() - c)
    return float(np.median(walls)), float(np.median(cpus))


def median_time(fn, repeat: int) -> float:
    return median_times(fn, repeat)[0]


def speed(repeat: int) -> None:
    print("| problem | ticks | design | whole (`design_problem`) | solve_ivp baseline "
          "| full continuous design | baseline / whole |")
    print("|---|---|---|---|---|---|---|")
    for blocks, hz in ((1, 1000), (4, 100), (4, 1000), (4, 10000)):
        p = varying_chain(blocks, hz)
        t_design = median_time(lambda: design_zoh(p), repeat)
        t_whole = median_time(lambda: design_problem(p), repeat)
        t_base = median_time(lambda: riccati_baseline(p), 1 if blocks > 1 else repeat)
        t_cont = median_time(lambda: design_continuous(p), 1)
        ticks = int(round(HORIZON * hz))
        print(f"| n = {3 * blocks}, {hz} Hz | {ticks} | {t_design * 1e3:.0f} ms "
              f"({t_design / ticks * 1e6:.1f} us/tick) | {t_whole * 1e3:.0f} ms "
              f"({t_whole / ticks * 1e6:.1f} us/tick) | {t_base * 1e3:.0f} ms "
              f"| {t_cont * 1e3:.0f} ms | **{t_base / t_whole:.1f}x** |", flush=True)


def dense(repeat: int) -> None:
    """The dense case: the whole design against the baseline, timed in the same run, in wall
    time and in CPU time (the whole runs its two oracle passes in two threads: on a loaded
    machine its wall time depends on the other jobs more than the baseline's does). The whole
    and the baseline are timed in turn, run by run, so that a change of load falls on both;
    the ratios are the medians of the runs' ratios."""
    print("\n| dense problem (n 12, m 4, 16 noise terms, mz 8, 3 441 ticks at 1 kHz) | design "
          "| whole (`design_problem`) | solve_ivp baseline | baseline / whole "
          "| the same in CPU time |")
    print("|---|---|---|---|---|---|")
    for varying_noise in (False, True):
        p = dense_chain(varying_noise)
        t_design, c_design = median_times(lambda: design_zoh(p), repeat)
        pairs = [(median_times(lambda: design_problem(p), 1),
                  median_times(lambda: riccati_baseline(p), 1)) for _ in range(repeat)]
        (t_whole, c_whole), (t_base, c_base) = (
            tuple(float(np.median([r[i][j] for r in pairs])) for j in (0, 1)) for i in (0, 1))
        wall = float(np.median([b[0] / w[0] for w, b in pairs]))
        cpu = float(np.median([b[1] / w[1] for w, b in pairs]))
        ticks = int(round(DENSE_HORIZON * 1000))
        print(f"| noise {'varying' if varying_noise else 'constant'} | {t_design * 1e3:.0f} ms "
              f"({t_design / ticks * 1e6:.0f} us/tick; CPU {c_design * 1e3:.0f} ms) "
              f"| {t_whole * 1e3:.0f} ms (CPU {c_whole * 1e3:.0f} ms) "
              f"| {t_base * 1e3:.0f} ms (CPU {c_base * 1e3:.0f} ms) "
              f"| **{wall:.2f}x** | **{cpu:.2f}x** |", flush=True)


def end_to_end(repeat: int) -> None:
    """`stospline design` as a user runs it (a new process: imports, parsing, design, tables,
    oracle, files written), on the problem written as a TOML file."""
    print("\n| problem | `stospline design` end to end (median of %d) |" % repeat)
    print("|---|---|")
    cli = Path(sys.executable).with_name("stospline")
    for blocks, hz in ((1, 1000), (4, 1000)):
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "varying.toml"
            path.write_text(problem_to_toml(varying_chain(blocks, hz)))
            times = []
            for _ in range(repeat + 1):                # the first builds nothing: cached
                t = time.perf_counter()
                subprocess.run([str(cli), "design", str(path), "--out", tmp, "--quiet"],
                               check=True, stdout=subprocess.DEVNULL)
                times.append(time.perf_counter() - t)
        print(f"| n = {3 * blocks}, {hz} Hz | {np.median(times[1:]):.2f} s |", flush=True)


def accuracy() -> None:
    print("\n| problem | J0 (designer) | J, reference oracle (DOP853 per tick) | designer rel. "
          "error | C oracle rel. error |")
    print("|---|---|---|---|---|")
    for blocks, hz in ((1, 100), (1, 1000), (4, 100), (4, 1000)):
        p = varying_chain(blocks, hz)
        d = design_zoh(p)
        table = table_of(d, quantize=False)
        j_c = evaluate_table(p, table, path=False).J
        os.environ["STOSPLINE_ORACLE_KERNEL"] = "numpy"
        try:
            j_ref = evaluate_table(p, table, path=False).J
        finally:
            del os.environ["STOSPLINE_ORACLE_KERNEL"]
        print(f"| n = {3 * blocks}, {hz} Hz | {d.J0:.15g} | {j_ref:.15g} | "
              f"{abs(d.J0 - j_ref) / abs(j_ref):.1e} | {abs(j_c - j_ref) / abs(j_ref):.1e} |",
              flush=True)


def previous() -> None:
    p = varying_chain(1, 1000)
    t = time.perf_counter()
    d = design_zoh(p, kernel="numpy")
    t_design = time.perf_counter() - t
    os.environ["STOSPLINE_ORACLE_KERNEL"] = "numpy"
    try:
        t = time.perf_counter()
        evaluate_table(p, table_of(d, quantize=False), path=False)
        t_oracle = time.perf_counter() - t
    finally:
        del os.environ["STOSPLINE_ORACLE_KERNEL"]
    print(f"\nprevious, n = 3, 1000 Hz: design {t_design:.2f} s, one oracle pass "
          f"{t_oracle:.2f} s (the whole ran the oracle twice)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--accuracy", action="store_true")
    ap.add_argument("--previous", action="store_true")
    ap.add_argument("--dense-only", action="store_true", help="only the dense case")
    args = ap.parse_args()
    if args.dense_only:
        dense(args.repeat)
        return
    speed(args.repeat)
    dense(args.repeat)
    end_to_end(args.repeat)
    if args.accuracy:
        accuracy()
    if args.previous:
        previous()


if __name__ == "__main__":
    main()
