#!/usr/bin/env python3
"""The tick-grid QP's active-set guess from OSQP against the interior point it keeps.

Usage: PYTHONPATH=host python tools/bench/tick_qp_osqp.py [--rates 100,1000] [--eps 1e-6]
           [--example examples/robot_monotone.toml]

`stospline.design.tick_qp` guesses the active set with its own interior point, then corrects
the guess with exact KKT solves. This bench swaps the guess for OSQP (ADMM, the solver in the
lock; equality rows ``l = u``, polishing on) and runs the same exact corrections on top: per
rate, the wall time of the whole `design_tick_qp` (after one warm-up run), the guesser's
iterations, the exact corrections, and whether the design (active set, J0, the offsets and
their sensitivity to x0) is bit-identical to the interior point's. A guess is an OSQP row
multiplier beyond 1e-7 of the largest. BLAS pinned to one thread. Figures are in
docs/evidence/performance.md.
"""
from __future__ import annotations

import argparse
import os
import time
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def osqp_guess(eps: float):
    """A replacement for `tick_qp._interior_point`: OSQP's multipliers' signs as the guess,
    with no lower bound and no primal iterate for the degenerate cases."""
    import numpy as np
    import osqp
    from scipy import sparse

    def guess(g, x0, eq):
        A = sparse.vstack([g.E, g.C], format="csc")
        rhs = g.rhs(x0)
        solver = osqp.OSQP()
        solver.setup(sparse.triu(g.P, format="csc"), np.zeros(g.nv), A,
                     np.concatenate([rhs, g.lo]), np.concatenate([rhs, g.hi]), verbose=False,
                     eps_abs=eps, eps_rel=eps, max_iter=200_000, polishing=True)
        res = solver.solve()
        y = res.y[g.n_eq:]
        big = np.abs(y) > 1e-7 * max(1.0, float(np.abs(y).max()))
        active = np.where(big, np.sign(y), 0).astype(int)
        active[eq] = 1
        return active, res.info.iter, -np.inf, None
    return guess


def rates(text: str) -> list[int]:
    """``--rates``: comma-separated tick rates, each a positive integer."""
    try:
        out = [int(r) for r in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be comma-separated integers, got {text!r}")
    if any(r < 1 for r in out):
        raise argparse.ArgumentTypeError(f"every rate must be at least 1 Hz, got {text!r}")
    return out


def tolerance(text: str) -> float:
    """``--eps``: OSQP's absolute and relative tolerance, in (0, 1)."""
    try:
        eps = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number, got {text!r}")
    if not 0 < eps < 1:
        raise argparse.ArgumentTypeError(f"must be in (0, 1), got {text!r}")
    return eps


def example(text: str) -> Path:
    """``--example``: an existing problem file."""
    if not Path(text).is_file():
        raise argparse.ArgumentTypeError(f"no such file: {text!r}")
    return Path(text)


def timed(design, p):
    design(p)                                   # warm-up: caches, first-call imports
    t = time.perf_counter()
    d = design(p)
    return d, time.perf_counter() - t


def main() -> None:
    import numpy as np
    import stospline
    from stospline.design import tick_qp
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rates", type=rates, default="100,1000")
    ap.add_argument("--eps", type=tolerance, default=1e-6)
    ap.add_argument("--example", type=example,
                    default=str(ROOT / "examples" / "robot_monotone.toml"))
    args = ap.parse_args()
    print(f"{args.example.name}: design_tick_qp, interior point (ours) vs OSQP "
          f"(eps {args.eps:g}) as the active-set guess, exact corrections on top of both")
    print("| rate | ours: time | iterations | corrections | OSQP: time | iterations | "
          "corrections | identical design | J0 OSQP / ours - 1 |")
    print("|---|---|---|---|---|---|---|---|---|")
    ours_guess = tick_qp._interior_point
    for rate in args.rates:
        p = replace(stospline.load_problem(args.example), tick_hz=rate)
        tick_qp._interior_point = ours_guess
        a, ta = timed(tick_qp.design_tick_qp, p)
        tick_qp._interior_point = osqp_guess(args.eps)
        try:
            b, tb = timed(tick_qp.design_tick_qp, p)
        finally:
            tick_qp._interior_point = ours_guess
        same = all(np.array_equal(getattr(a, k), getattr(b, k))
                   for k in ("active", "delta", "D")) and a.J0 == b.J0
        print(f"| {rate} Hz | {ta:.2f} s | {a.ipm_iterations} | {a.rounds} | {tb:.2f} s | "
              f"{b.ipm_iterations} | {b.rounds} | {'yes' if same else 'no'} | "
              f"{b.J0 / a.J0 - 1:.2e} |", flush=True)


if __name__ == "__main__":
    main()
