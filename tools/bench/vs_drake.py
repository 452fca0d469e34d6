"""Design time against a peer: Drake's finite-horizon LQR on the deterministic sub-problem.

Usage: .venv/bin/python tools/bench/vs_drake.py [--repeat 3] [--sizes 4,12,24,32]

Times are printed as "CPU s (wall s)".

Drake (``pip install drake``) is an optional benchmark dependency, not a runtime one: when
``pydrake`` cannot be imported its column says "not installed" and only stospline is timed.
Every time is the median of `--repeat` runs after one warm-up run (which also builds the
cached C kernels), in one process, each run cold (the tick maps and samples cached by the run
before are dropped); BLAS threads are pinned to 1 before numpy is imported. Each is given as
CPU time (``time.process_time``: all threads of the process, what load from other processes
inflates least) and wall time (``time.perf_counter``); the ratios, taken within the run, are of
the CPU times (the machine may be loaded).

Problem
-------
The sub-problem both tools can state: LTI dynamics, running cost ``(x - x_f)'Q(x - x_f) +
u'Ru``, a terminal penalty ``w |x(T) - x_f|^2``, no noise, no constraints, over ``T = 3`` s.
`chain(n)`: n/2 masses on a line joined by springs and dampers (states: positions, then
velocities; m = n/2 forces, one per mass), seeded; n up to the firmware's STSP_MAX_NX = 32
(m = 16 = STSP_MAX_NU). stospline states the cost with ``q = -Q x_f``, ``rho = x_f'Q x_f`` and
the terminal penalty as a knot penalty on ``C = I``.

Measured
--------
"Drake": `FiniteHorizonLinearQuadraticRegulator` of the `LinearSystem` (its Riccati ODE
integrated to its default accuracy, `options.xd` the constant x_f, `options.Qf` = w I). The
last column checks that both solve the same problem: Drake's optimal cost from x0 against the
continuous design's J0 (they differ by the integrators' tolerances).
"exact ZOH" and "continuous": `design_problem` as `stospline design` runs it at 1 kHz, the
whole of it (the design, the float32 table and the exact oracle on the design's law and on the
table), with ``discretization = "exact-zoh"`` (default) or ``"continuous"``.
"""
from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse                                     # noqa: E402
import sys                                          # noqa: E402
import time                                         # noqa: E402
from pathlib import Path                            # noqa: E402

import numpy as np                                  # noqa: E402

from stospline.pipeline import design_problem       # noqa: E402
from stospline.problem import parse_problem         # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from varying_design import cold                     # noqa: E402  (cold runs, as there)

HORIZON, HZ, WEIGHT = 3.0, 1000, 10.0


def chain(n: int, seed: int = 7):
    """A, B, Q, R, x0, x_f of the benchmark problem (see the module docstring)."""
    rng = np.random.default_rng(seed)
    k = n // 2
    spring, damp, mass = rng.uniform(0.5, 2.0, k), rng.uniform(0.1, 0.5, k), rng.uniform(
        0.5, 2.0, k)
    Kmat, Dmat = np.zeros((k, k)), np.zeros((k, k))
    for i in range(k):                               # spring i joins mass i to i-1 (or wall)
        Kmat[i, i] += spring[i]
        Dmat[i, i] += damp[i]
        if i:
            Kmat[i - 1, i - 1] += spring[i]
            Kmat[i, i - 1] -= spring[i]
            Kmat[i - 1, i] -= spring[i]
    A = np.zeros((n, n))
    A[:k, k:] = np.eye(k)
    A[k:, :k] = -Kmat / mass[:, None]
    A[k:, k:] = -Dmat / mass[:, None]
    B = np.zeros((n, k))
    B[k:, :] = np.diag(1.0 / mass)
    Q = np.diag(rng.uniform(0.5, 2.0, n))
    R = np.diag(rng.uniform(0.05, 0.2, k))
    return A, B, Q, R, rng.normal(size=n), rng.normal(size=n)


def stospline_problem(n: int, discretization: str):
    A, B, Q, R, x0, xf = chain(n)
    return parse_problem({
        "name": f"chain{n}", "x0": x0.tolist(), "tick_hz": HZ,
        "design": {"discretization": discretization},
        "dynamics": {"A": A.tolist(), "B": B.tolist()},
        "cost": {"Q": Q.tolist(), "R": R.tolist(), "q": (-Q @ xf).tolist(),
                 "rho": float(xf @ Q @ xf)},
        "knots": [{"t": HORIZON, "penalty": {"C": np.eye(n).tolist(), "target": xf.tolist(),
                                             "weight": WEIGHT}}]})


def drake_solver(n: int):
    """A closure running Drake's finite-horizon LQR on `chain(n)`, or None without pydrake."""
    try:
        from pydrake.systems.controllers import (FiniteHorizonLinearQuadraticRegulator,
                                                 FiniteHorizonLinearQuadraticRegulatorOptions)
        from pydrake.systems.primitives import LinearSystem
        from pydrake.trajectories import PiecewisePolynomial
    except ImportError:
        return None
    A, B, Q, R, x0, xf = chain(n)
    system = LinearSystem(A, B, np.eye(n), np.zeros((n, B.shape[1])))
    context = system.CreateDefaultContext()
    system.get_input_port().FixValue(context, np.zeros(B.shape[1]))
    context.SetContinuousState(x0)

    def solve():
        options = FiniteHorizonLinearQuadraticRegulatorOptions()
        options.Qf = WEIGHT * np.eye(n)
        options.xd = PiecewisePolynomial(xf)
        return FiniteHorizonLinearQuadraticRegulator(system, context, 0.0, HORIZON, Q, R,
                                                     options)
    return solve


def median_times(fn, repeat: int) -> tuple[float, float]:
    """``(cpu, wall)``: the medians of `repeat` cold runs of `fn` after a warm-up."""
    cold()
    fn()
    cpu, wall = [], []
    for _ in range(repeat):
        cold()
        c, w = time.process_time(), time.perf_counter()
        fn()
        cpu.append(time.process_time() - c)
        wall.append(time.perf_counter() - w)
    return float(np.median(cpu)), float(np.median(wall))


def same_problem(n: int, drake_result, problem) -> float:
    """The relative difference of the two optimal costs from x0: Drake's ``s0(0)`` (its
    nominal state is x0, so ``x - x0 = 0`` at t = 0) and the continuous design's J0 (the two
    Riccati integrations' tolerances)."""
    from stospline.design.continuous import design_continuous
    j_drake = float(np.ravel(drake_result.s0.value(0.0))[0])
    j_ours = design_continuous(problem).J0
    return abs(j_drake - j_ours) / abs(j_ours)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--sizes", default="4,12,24,32")
    args = ap.parse_args()
    print("| n, m | Drake FH-LQR | exact ZOH, whole | continuous, whole "
          "| Drake / exact ZOH | Drake / continuous | J0 continuous vs Drake |")
    print("|---|---|---|---|---|---|---|")

    def both(t):
        return f"{t[0]:.3f} s ({t[1]:.3f} s)"
    for n in (int(s) for s in args.sizes.split(",")):
        solve = drake_solver(n)
        t_drake = median_times(solve, args.repeat) if solve is not None else None
        zoh, cont = (stospline_problem(n, d) for d in ("exact-zoh", "continuous"))
        t_zoh = median_times(lambda: design_problem(zoh), args.repeat)
        t_cont = median_times(lambda: design_problem(cont, discretization="continuous"),
                              args.repeat)
        if t_drake is None:
            drake, r_zoh, r_cont, agree = "not installed", "-", "-", "-"
        else:
            drake = both(t_drake)
            r_zoh = f"**{t_drake[0] / t_zoh[0]:.2f}x**"
            r_cont = f"**{t_drake[0] / t_cont[0]:.2f}x**"
            agree = f"{same_problem(n, solve(), cont):.1e}"
        print(f"| {n}, {n // 2} | {drake} | {both(t_zoh)} | {both(t_cont)} | {r_zoh} "
              f"| {r_cont} | {agree} |", flush=True)


if __name__ == "__main__":
    main()
