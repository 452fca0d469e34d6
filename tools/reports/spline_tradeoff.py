"""Spline tables: tolerance against size and accuracy, and the compression's time
against the design's.

For each tolerance: spans per stage, bytes of the spline arrays, the largest relative gain
error (as the firmware evaluates the spline), and the exact oracle of the law with the
spline's gains against the float32 per-tick table's (the same design): the cost's relative
change and the worst knot-constraint residual |E{C2 x} - zeta|, with the latch maps re-solved
for the spline's gains (`spline_latch.resolve_latch`, rounded to float32) and with the design's.
Then the times: `compress` (fit, evaluate, re-solve) against `design_problem`, the first call
in this process (lazy imports, compiled kernels loaded) and warm (fresh problem objects),
each the best of --repeat runs. Last, coarse splines (the first fit's uniform spans kept,
tolerance 0.5): where re-solving the latch maps matters. Prints Markdown.

Usage: PYTHONPATH=host .venv/bin/python tools/reports/spline_tradeoff.py
           [--example robot_corridor] [--mode stagewise] [--tolerances 1e-3 1e-4 ...]
           [--repeat 20]
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from stospline.pipeline import design_problem
from stospline.problem import load_problem
from stospline.oracle.evaluate import evaluate_table
from stospline.table.format import table_of
from stospline.table.spline.fit import INITIAL_SPANS, max_relative_error
from stospline.table.spline.compress import compress

ROOT = Path(__file__).resolve().parents[2]
TOLERANCES = [1e-2, 1e-3, 1e-4, 1e-5, 1e-6]
COARSE_SPANS = [2, 4, 8]


def residual(problem, moments) -> float:
    return max(float(np.abs(moments.knot_constraint[k] - kn.constraint.value).max())
               for k, kn in enumerate(problem.knots) if kn.constraint is not None)


def best_of(repeat: int, fn) -> float:
    """The shortest of `repeat` runs of fn(), in seconds (the machine's noise is one-sided)."""
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--example", default="robot_corridor")
    ap.add_argument("--mode", default="stagewise", choices=["stagewise", "joint"])
    ap.add_argument("--tolerances", type=float, nargs="+", default=TOLERANCES)
    ap.add_argument("--repeat", type=int, default=20)
    args = ap.parse_args()
    path = ROOT / "examples" / f"{args.example}.toml"

    problem = load_problem(path)
    t = time.perf_counter()
    d = design_problem(problem, mode=args.mode)
    first = time.perf_counter() - t
    warm = best_of(args.repeat, lambda: design_problem(load_problem(path), mode=args.mode))
    exact, table = table_of(d.design, quantize=False), d.table
    base = evaluate_table(problem, table, path=False)
    per_tick = sum(a.nbytes for a in (table.K, table.k0, table.L))
    n, m, n_latch = table.dims

    print(f"{args.example} ({args.mode}): {table.n_ticks} ticks in {table.n_stages} stages, "
          f"n = {n}, m = {m}, {n_latch} latched multipliers. The float32 per-tick table: "
          f"K, k0, L {per_tick} bytes; oracle J = {base.J:.9f}, worst constraint residual "
          f"{residual(problem, base):.2e}.\n")
    header = ("| spans per stage | spline bytes | max rel gain error | "
              "J rel change, re-solved latch | J rel change, design's latch | "
              "residual, re-solved | residual, design's |")

    def row(tol, initial_spans=INITIAL_SPANS) -> str:
        sp, K, k0, L, Lam, lam0 = compress(problem, exact, table, tol,
                                           initial_spans=initial_spans)
        resolved = evaluate_table(problem, table.with_arrays(K=K, k0=k0, L=L, Lambda=Lam,
                                                             lambda0=lam0), path=False)
        design_latch = evaluate_table(problem, table.with_arrays(K=K, k0=k0, L=L), path=False)
        spans = ", ".join(str(sp.spans(s)) for s in range(sp.n_stages))
        return (f"| {spans} | {sp.nbytes} | {max_relative_error(sp, exact):.2e} | "
                f"{(resolved.J - base.J) / base.J:+.2e} | "
                f"{(design_latch.J - base.J) / base.J:+.2e} | "
                f"{residual(problem, resolved):.2e} | {residual(problem, design_latch):.2e} |")

    print("| tolerance " + header + " compress |")
    print("|---:|---|---:|---:|---:|---:|---:|---:|---:|")
    for tol in args.tolerances:
        spent = best_of(args.repeat, lambda: compress(problem, exact, table, tol))
        print(f"| {tol:g} " + row(tol) + f" {spent * 1e3:.1f} ms |")
    print(f"\ndesign_problem: {first * 1e3:.0f} ms the first call in this process, "
          f"{warm * 1e3:.1f} ms warm (best of {args.repeat}); compress times above are the "
          f"best of {args.repeat}.\n")
    print("Coarse splines (tolerance 0.5, the first fit's uniform spans kept):\n")
    print("| first fit " + header)
    print("|---:|---|---:|---:|---:|---:|---:|---:|")
    for spans in COARSE_SPANS:
        print(f"| {spans} spans " + row(0.5, spans))


if __name__ == "__main__":
    main()
