"""Spline tables against per-tick tables: flash, cost, constraint residual, compression time.

Usage: .venv/bin/python tools/bench/spline_tables.py [--repeat 3] [--examples a.toml,b.toml]
           [--tolerances 1e-4,1e-5,1e-6]

For every example and tolerance: the per-tick float32 table's flash and the spline table's
(`stospline.table.flash.flash_bytes`, what the generated C takes on a 32-bit target), their
ratio; the exact oracle's cost of each law as the firmware runs it (J per-tick, J spline) and
the spline's excess over the per-tick table's and over the designed optimum J0; the worst
E-constraint residual of each (|E{C2 x} - value| at the knots, oracle); and the compression
time (fit + evaluation + latch re-solve, `spline_table`) against the time of
`design_problem` with a per-tick table (the design, the float32 table and the oracle on both
laws: what `stospline design` computes). Times are medians of `--repeat` runs after a warm-up,
`time.perf_counter`, BLAS pinned to one thread. Figures are in docs/evidence/spline-tables.md.
"""
from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse                                                    # noqa: E402
import statistics                                                  # noqa: E402
import time                                                        # noqa: E402
from pathlib import Path                                           # noqa: E402

import stospline                                                   # noqa: E402
from stospline.sim.spline_certificate import spline_table          # noqa: E402
from stospline.table.flash import flash_bytes                      # noqa: E402
from stospline.table.format import table_of                        # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ["robot_corridor.toml", "robot_corridor_eps01.toml", "robot_patrol_60s.toml",
            "coupled_axes.toml", "investment.toml", "population.toml"]


def _median_time(work, repeat: int):
    work()                                    # warm-up: C kernels built, caches filled
    times, out = [], None
    for _ in range(repeat):
        start = time.perf_counter()
        out = work()
        times.append(time.perf_counter() - start)
    return out, statistics.median(times)


def _residual(problem, moments) -> float:
    worst = 0.0
    for k, kn in enumerate(problem.knots):
        if kn.constraint is not None:
            lo, _ = kn.constraint.bounds
            worst = max(worst, float(abs(moments.knot_constraint[k] - lo).max()))
    return worst


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--examples", default=",".join(EXAMPLES))
    ap.add_argument("--tolerances", default="1e-5")
    args = ap.parse_args()
    tolerances = [float(t) for t in args.tolerances.split(",")]
    print("| example | ticks | tolerance | spans per stage | per-tick B | spline B | ratio | "
          "J per-tick | J spline | excess vs per-tick | excess vs J0 | residual per-tick | "
          "residual spline | design s | compress s | compress / design |")
    print("|---|" + "---|" * 15)
    for name in args.examples.split(","):
        problem = stospline.load_problem(str(ROOT / "examples" / name))
        d, t_design = _median_time(lambda: stospline.design_problem(problem), args.repeat)
        exact = table_of(d.design, quantize=False)
        for tol in tolerances:
            sp, t_comp = _median_time(lambda: spline_table(problem, exact, d.table, tol),
                                      args.repeat)
            m = stospline.evaluate_table(problem, sp, path=False)
            print(f"| {name.removesuffix('.toml')} | {d.table.n_ticks} | {tol:g} | "
                  f"{[int(sp.spline.spans(s)) for s in range(sp.n_stages)]} | "
                  f"{flash_bytes(d.table):,} | {flash_bytes(sp):,} | "
                  f"{flash_bytes(d.table) / flash_bytes(sp):.0f} | {d.implemented.J:.10g} | "
                  f"{m.J:.10g} | {(m.J - d.implemented.J) / abs(d.implemented.J):+.2e} | "
                  f"{(m.J - d.design.J0) / abs(d.design.J0):+.2e} | "
                  f"{_residual(problem, d.implemented):.2e} | {_residual(problem, m):.2e} | "
                  f"{t_design:.3f} | {t_comp:.3f} | {t_comp / t_design:.1%} |", flush=True)


if __name__ == "__main__":
    main()
