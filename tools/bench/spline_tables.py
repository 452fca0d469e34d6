"""Spline tables against per-tick tables: flash, cost, constraint residual, compression time.

Usage: .venv/bin/python tools/bench/spline_tables.py [--repeat 3] [--examples a.toml,b.toml]
           [--tolerances 1e-4,1e-5,1e-6] [--profile] [--arith q15,q31]

`--arith q15,q31`: instead, the fixed-point spline tables (`pipeline.fixed_point_spline`)
against the per-tick Q tables of the same scales: flash, ratio, the oracle's cost of each law
as stored (integer gains and latch maps in real units), the spline's excess over the per-tick
Q table and over J0, the residuals, the error bound of each (|u_fixed - u_double| per input,
the largest over the inputs, in the command's LSBs and in its units), the span length per
stage and the time of `fixed_point_spline` (fit, latch re-solve, three oracle evaluations);
and, cold as below, the compression step alone (`qspline.q_spline_table`: scales, fit,
evaluation, latch re-solve, error bound; after the per-tick Q table, as
`pipeline.fixed_point_spline` runs it) against the design alone and against the design in
that arithmetic: the design, its double table, the state range that sets the scales and the
per-tick Q table (what `pipeline.fixed_point_table` and `stospline design --arith q15`
compute before a spline exists; medians of `--repeat` processes).

`--rounding N`: instead, the latch maps' float32 rounding (`spline_latch.round_latch`) against
rounding them to nearest and against the per-tick table: the residual at x0, the worst over N
other starts (seed 0), with the t0 latch in binary32, and the cost against the exact re-solve.

`--profile`: instead of the table, where the warm compression of the first example at the
first tolerance spends its time (cProfile, the functions of `stospline.table`); with
`--arith`, the first arithmetic's (`qspline.q_spline_table`).

For every example and tolerance: the per-tick float32 table's flash and the spline table's
(`stospline.table.flash.flash_bytes`, what the generated C takes on a 32-bit target), their
ratio; the exact oracle's cost of each law as the firmware runs it (J per-tick, J spline) and
the spline's excess over the per-tick table's and over the designed optimum J0; the worst
E-constraint residual of each (|E{C2 x} - value| at the knots, for a band row the distance
outside it, oracle), also with the t0 latch as the firmware computes it (``v = lambda0 +
Lambda x0`` in binary32, `first_latch_in_float32`; the oracle takes it in float64); and the
compression
time (fit + evaluation + latch re-solve, `spline_table`) against the time of
`design_problem` with a per-tick table (the design, the float32 table and the oracle on both
laws: what `stospline design` computes), twice: "warm", medians of `--repeat` runs after a
warm-up in this process (the designer's caches of tick maps hit: the least a design costs),
and "cold", the first call of each in a fresh process, as in one `stospline design` run
(medians of `--repeat` processes). `time.perf_counter` (wall clock: the design runs its two
oracle evaluations in two threads, the compression in one), BLAS pinned to one thread.
Figures are in docs/evidence/spline-tables.md.
"""
from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse                                                    # noqa: E402
import numpy as np                                                 # noqa: E402
import statistics                                                  # noqa: E402
import time                                                        # noqa: E402
from pathlib import Path                                           # noqa: E402

import stospline                                                   # noqa: E402
from stospline.design.varying import mean_maps                     # noqa: E402
from stospline.refine.spline_certificate import (constraint_residual,  # noqa: E402
                                               first_latch_in_float32)
from stospline.table.spline import spline_table                    # noqa: E402
from stospline.table.flash import flash_bytes                      # noqa: E402
from stospline.table.format import table_of                        # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
# robot_bands has its band dual re-solved for the spline's gains; robot_monotone (regions at
# every tick) and robot_narrow_corridor (bands beyond the 8 rows of a band dual) latch the state
# and have their feed-forward restored (`--examples robot_monotone.toml,...`: their residuals
# are over every row, region rows at every tick included).
EXAMPLES = ["robot_corridor.toml", "robot_corridor_eps01.toml", "robot_patrol_60s.toml",
            "coupled_axes.toml", "population.toml", "investment.toml", "quadrotor.toml",
            "robot_bands.toml"]
_COLD = """
import os, sys, time
for v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(v, "1")
import stospline
from stospline.design.varying import mean_maps
from stospline.oracle.evaluate import state_range
from stospline.table.spline import spline_table
from stospline.table.format import table_of
from stospline.table.qformat import quantize_table
from stospline.table.spline.fixed_point import q_spline_table
p = stospline.load_problem(sys.argv[1])
tolerance, arith = float(sys.argv[2]), sys.argv[3]
t = time.perf_counter()
d = stospline.design_problem(p, table="per-tick", mode=p.options.get("mode", "stagewise"))
t_design = time.perf_counter() - t
t = time.perf_counter()
exact = table_of(d.design, quantize=False)
if arith == "float32":
    t_arith = t_design
    t = time.perf_counter()
    spline_table(p, exact, tolerance, per_tick=d.table, varying_maps=mean_maps)
else:                   # after the per-tick Q table, as `pipeline.fixed_point_spline` runs it
    x_range = state_range(p, d.table)
    quantize_table(exact, arith, x_range)
    t_arith = t_design + time.perf_counter() - t      # `pipeline.fixed_point_table`'s design
    t = time.perf_counter()
    q_spline_table(p, exact, arith, x_range, tolerance, varying_maps=mean_maps)
print(t_design, t_arith, time.perf_counter() - t)
"""


def _cold(path: Path, tolerance: float, repeat: int, arith: str = "float32"
          ) -> tuple[float, float, float]:
    """``(design s, design in arith s, compress s)``, each the first call in a fresh process
    (the C kernels are built already, the caches empty): what one `stospline design` run
    spends on each; the medians of `repeat` processes. The design in Q15/Q31 adds to the
    design what `pipeline.fixed_point_table` computes (the double table, the state range
    that sets the scales, the per-tick Q table); in float32 it is the design."""
    import subprocess
    import sys
    env = {**os.environ, "PYTHONPATH": str(ROOT / "host")}
    runs = [subprocess.run([sys.executable, "-c", _COLD, str(path), repr(tolerance), arith],
                           env=env, check=True, capture_output=True, text=True).stdout.split()
            for _ in range(repeat)]
    return tuple(statistics.median(float(r[i]) for r in runs) for i in (0, 1, 2))


def _f32_latch_residual(problem, table, path: bool = False) -> str:
    """The residual with the t0 latch as the firmware computes it, in binary32 from x0
    (`first_latch_in_float32`); "n/a" for a band table (its t0 latch solves the band dual).
    ``path``: regions at every tick, whose rows need the mean path."""
    if table.band_qp is not None:
        return "n/a"
    m = stospline.evaluate_table(problem, first_latch_in_float32(problem, table), path=path)
    return f"{constraint_residual(problem, m):.2e}"


def _ratio(r: float) -> str:
    """A compression ratio: whole above 100, three digits below (a spline larger than the
    per-tick table shows below 1)."""
    return f"{r:.0f}" if r >= 100 else f"{r:.3g}"


def _median_time(work, repeat: int):
    work()                                    # warm-up: C kernels built, caches filled
    times, out = [], None
    for _ in range(repeat):
        start = time.perf_counter()
        out = work()
        times.append(time.perf_counter() - start)
    return out, statistics.median(times)


def _profile(name: str, tolerance: float, repeat: int, arith: str = "float32") -> None:
    import cProfile
    import pstats
    problem = stospline.load_problem(str(ROOT / "examples" / name))
    d = stospline.design_problem(problem, table="per-tick")
    exact = table_of(d.design, quantize=False)
    if arith == "float32":
        def compress():
            spline_table(problem, exact, tolerance, per_tick=d.table, varying_maps=mean_maps)
    else:
        from stospline.oracle.evaluate import state_range
        from stospline.table.spline.fixed_point import q_spline_table
        x_range = state_range(problem, d.table)

        def compress():
            q_spline_table(problem, exact, arith, x_range, tolerance, varying_maps=mean_maps)
    compress()                                                  # warm-up
    profile = cProfile.Profile()
    profile.enable()
    for _ in range(repeat):
        compress()
    profile.disable()
    print(f"{name} at {tolerance:g}, {arith}: cumulative ms per compression (cProfile adds "
          f"overhead)")
    stats = pstats.Stats(profile).stats
    rows = [(ct / repeat * 1e3, f"{Path(file).name}:{func}")
            for (file, _, func), (_, _, _, ct, _) in stats.items()
            if "stospline" in file and ("table" in file or func == "spline_table")]
    for ms, where in sorted(rows, reverse=True)[:16]:
        print(f"{ms:8.2f}  {where}")


def _rounding(examples: list[str], tolerances: list[float], n_starts: int) -> None:
    """The latch maps' float32 rounding: the residual at x0, the worst over `n_starts` other
    starts (x0 plus normal noise of 0.1 (1 + max|x0|) per entry, seed 0) and the cost of
    the per-tick table, of the spline table with its re-solved maps rounded to nearest, and
    of the shipped rounding (`spline_latch.round_latch`); costs relative to the oracle's of
    the spline with the exact (float64) re-solved maps."""
    from dataclasses import replace
    from stospline.design.varying import mean_maps
    from stospline.table.spline.latch import resolve_latch
    print("| example | tolerance | per-tick: x0 | others | t0 f32 | J | nearest: x0 | others | "
          "t0 f32 | J | shipped: x0 | others | t0 f32 | J |")
    print("|---|" + "---|" * 13)
    for name in examples:
        problem = stospline.load_problem(str(ROOT / "examples" / name))
        d = stospline.design_problem(problem, table="per-tick",
                                     mode=problem.options.get("mode", "stagewise"))
        exact = table_of(d.design, quantize=False)
        rng = np.random.default_rng(0)
        x0 = np.asarray(problem.x0, dtype=float)
        starts = [x0 + rng.normal(0.0, 0.1 * (1 + np.abs(x0).max()), x0.shape)
                  for _ in range(n_starts)]
        for tol in tolerances:
            sp = spline_table(problem, exact, tol, per_tick=d.table, varying_maps=mean_maps)
            Lam, lam0 = resolve_latch(problem, sp, sp.spline, mean_maps)
            J64 = stospline.evaluate_table(problem, replace(sp, Lambda=Lam, lambda0=lam0),
                                           path=False).J
            nearest = replace(sp, Lambda=Lam.astype(np.float32),
                              lambda0=lam0.astype(np.float32))
            cells = []
            for t in (d.table, nearest, sp):
                m = stospline.evaluate_table(problem, t, path=False)
                others = max(constraint_residual(problem, stospline.evaluate_table(
                    replace(problem, x0=x), t, path=False)) for x in starts)
                cells += [f"{constraint_residual(problem, m):.2e}", f"{others:.2e}",
                          _f32_latch_residual(problem, t), f"{(m.J - J64) / abs(J64):+.1e}"]
            print(f"| {name.removesuffix('.toml')} | {tol:g} | " + " | ".join(cells) + " |",
                  flush=True)


def _fixed_point(examples: list[str], tolerances: list[float], ariths: list[str],
                 repeat: int) -> None:
    print("| example | arith | tolerance | span ticks per stage | per-tick B | spline B | ratio | "
          "J per-tick | J spline | excess vs per-tick | excess vs J0 | residual per-tick | "
          "residual spline | bound per-tick LSB | bound spline LSB | bound spline (units) | "
          "time s | cold: design s | design in arith s | compress s | vs design | "
          "vs design in arith |")
    print("|---|" + "---|" * 21)
    for name in examples:
        problem = stospline.load_problem(str(ROOT / "examples" / name))
        d = stospline.design_problem(problem, table="spline")
        for arith in ariths:
            for tol in tolerances:
                start = time.perf_counter()
                _, c = stospline.pipeline.fixed_point_spline(d, arith, tolerance=tol)
                took = time.perf_counter() - start
                c_design, c_arith, c_comp = _cold(ROOT / "examples" / name, tol, repeat,
                                                  arith)
                print(f"| {name.removesuffix('.toml')} | {arith} | {tol:g} | {c['span_ticks']} | "
                      f"{c['per_tick_flash_bytes']:,} | {c['flash_bytes']:,} | "
                      f"{c['compression_ratio']:.0f} | {c['per_tick_oracle_J']:.10g} | "
                      f"{c['oracle_J']:.10g} | {c['excess_over_per_tick']:+.2e} | "
                      f"{c['excess_over_J0']:+.2e} | {c['per_tick_constraint_residual']:.2e} | "
                      f"{c['constraint_residual']:.2e} | "
                      f"{max(c['per_tick_u_error_bound_lsb']):g} | "
                      f"{max(c['u_error_bound_lsb']):g} | {max(c['u_error_bound']):.3g} | "
                      f"{took:.2f} | {c_design:.3f} | {c_arith:.3f} | {c_comp:.3f} | "
                      f"{c_comp / c_design:.0%} | {c_comp / c_arith:.0%} |",
                      flush=True)


def _checked_arguments(ap: argparse.ArgumentParser, args) -> list[float]:
    """The tolerances; any bad value ends the run with one line naming it (exit 2)."""
    from stospline.errors import ProblemError
    from stospline.table_options import check_spline_tolerance
    if args.repeat < 1:
        ap.error(f"--repeat must be at least 1, not {args.repeat}")
    if args.rounding < 0:
        ap.error(f"--rounding must be at least 0, not {args.rounding}")
    for name in args.examples.split(","):
        if not (ROOT / "examples" / name).is_file():
            ap.error(f"--examples: no examples/{name}")
    for arith in (args.arith.split(",") if args.arith else []):
        if arith not in ("q15", "q31"):
            ap.error(f"--arith: {arith!r} is not q15 or q31")
    try:
        return [check_spline_tolerance(float(t), "--tolerances")
                for t in args.tolerances.split(",")]
    except ProblemError as exc:               # a ValueError too: first
        ap.error(str(exc))
    except ValueError:
        ap.error(f"--tolerances: {args.tolerances!r} is not a list of numbers")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--examples", default=",".join(EXAMPLES))
    ap.add_argument("--tolerances", default="1e-5")
    ap.add_argument("--profile", action="store_true")
    ap.add_argument("--arith", default=None)
    ap.add_argument("--rounding", type=int, default=0, metavar="STARTS",
                    help="instead, the latch maps' rounding at x0 and STARTS other starts")
    args = ap.parse_args()
    tolerances = _checked_arguments(ap, args)
    if args.profile:
        _profile(args.examples.split(",")[0], tolerances[0], args.repeat,
                 (args.arith or "float32").split(",")[0])
        return
    if args.arith:
        _fixed_point(args.examples.split(","), tolerances, args.arith.split(","),
                     args.repeat)
        return
    if args.rounding:
        _rounding(args.examples.split(","), tolerances, args.rounding)
        return
    print("| example | ticks | tolerance | spans per stage | per-tick B | spline B | ratio | "
          "J per-tick | J spline | excess vs per-tick | excess vs J0 | residual per-tick | "
          "residual spline | residual per-tick, t0 latch f32 | residual spline, t0 latch f32 | "
          "warm: design s | compress s | ratio | cold: design s | compress s | ratio |")
    print("|---|" + "---|" * 20)
    for name in args.examples.split(","):
        problem = stospline.load_problem(str(ROOT / "examples" / name))
        mode = problem.options.get("mode", "stagewise")       # the file's: joint for bands
        d, t_design = _median_time(lambda: stospline.design_problem(problem, table="per-tick",
                                                                    mode=mode),
                                   args.repeat)
        exact = table_of(d.design, quantize=False)
        for tol in tolerances:
            sp, t_comp = _median_time(lambda: spline_table(problem, exact, tol, per_tick=d.table,
                                                           varying_maps=mean_maps),
                                      args.repeat)
            # Regions at every tick: the residual over their rows needs the mean path.
            path = bool(d.problem.tick_regions)
            m = stospline.evaluate_table(d.problem, sp, path=path)
            per_tick = (stospline.evaluate_table(d.problem, d.table, path=True) if path
                        else d.implemented)
            f32 = [_f32_latch_residual(d.problem, t, path) for t in (d.table, sp)]
            c_design, _, c_comp = _cold(ROOT / "examples" / name, tol, args.repeat)
            print(f"| {name.removesuffix('.toml')} | {d.table.n_ticks} | {tol:g} | "
                  f"{[int(sp.spline.spans(s)) for s in range(sp.n_stages)]} | "
                  f"{flash_bytes(d.table):,} | {flash_bytes(sp):,} | "
                  f"{_ratio(flash_bytes(d.table) / flash_bytes(sp))} | {d.implemented.J:.10g} | "
                  f"{m.J:.10g} | {(m.J - d.implemented.J) / abs(d.implemented.J):+.2e} | "
                  f"{(m.J - d.design.J0) / abs(d.design.J0):+.2e} | "
                  f"{constraint_residual(d.problem, per_tick):.2e} | "
                  f"{constraint_residual(d.problem, m):.2e} | "
                  f"{f32[0]} | {f32[1]} | "
                  f"{t_design:.3f} | {t_comp:.3f} | {t_comp / t_design:.0%} | "
                  f"{c_design:.3f} | {c_comp:.3f} | {c_comp / c_design:.0%} |", flush=True)


if __name__ == "__main__":
    main()
