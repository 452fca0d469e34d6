#!/usr/bin/env python3
"""How fast a table's C text is written: the table kernel's literals (`literal_kernel.c`)
against numpy's `format_float_scientific`, the baseline, timed in the same run on the same
tables; the two texts must be the same bytes.

    PYTHONPATH=host .venv/bin/python tools/bench/c_text.py [--repeat 5] [EXAMPLE.toml ...]

Per table: float32 numbers written, the median CPU time of `generate_c` each way (numpy's
tick loop is not involved: the design is done once, before timing), and the ratio. Also a
dense per-tick table of 12 states and 4 inputs over 3 441 ticks (random gains, seeded): the
size of C text a large time-varying design writes.
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]


def _median_time(fn, repeat: int) -> float:
    """The median CPU time of `repeat` calls (``time.process_time``: load from other processes
    inflates it least; both ways are timed alike, so the ratio holds)."""
    times = []
    for _ in range(repeat):
        t = time.process_time()
        fn()
        times.append(time.process_time() - t)
    return statistics.median(times)


def _numbers(table) -> int:
    return sum(np.size(getattr(table, a)) for a in ("K", "k0", "L", "Lambda", "lambda0"))


def _dense_table(base):
    """The robot's table widened to 12 states and 4 inputs over 3 441 ticks (seeded)."""
    rng = np.random.default_rng(20261128)
    T, m, n = 3441, 4, 12
    f32 = lambda *s: (rng.standard_normal(s) * 10.0 ** rng.uniform(-4, 2, s)).astype(np.float32)  # noqa: E731
    return replace(base, stage_start=np.array([0, T], np.uint32),
                   stage_n_latch=np.array([n], np.uint16), K=f32(T, m, n), k0=f32(T, m),
                   L=f32(T, m, n), Lambda=f32(1, n, n), lambda0=f32(1, n),
                   u_min=None, u_max=None, u_hold=None, band_qp=None, spline=None)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("examples", nargs="*", default=["robot_corridor.toml", "coupled_axes.toml"])
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args(argv)
    if args.repeat < 1:
        print("c_text: --repeat must be at least 1", file=sys.stderr)
        return 2
    from stospline import design_problem, load_problem
    from stospline.table import codegen, kernels
    if kernels._kernel() is None:
        print("c_text: the table kernel is not built (no C compiler?)", file=sys.stderr)
        return 2
    tables = []
    for name in args.examples:
        path = Path(name) if Path(name).exists() else ROOT / "examples" / name
        if not path.is_file():
            print(f"c_text: no problem file {name}", file=sys.stderr)
            return 2
        tables.append((path.stem, design_problem(load_problem(path)).table))
    tables.append(("dense 12x4, 3441 ticks", _dense_table(tables[0][1])))
    print(f"{'table':<26}{'numbers':>10}{'numpy s':>10}{'kernel s':>10}{'ratio':>8}  same bytes")
    for name, table in tables:
        fast = codegen.generate_c(table)
        t_fast = _median_time(lambda: codegen.generate_c(table), args.repeat)
        os.environ["STOSPLINE_TABLE_KERNEL"] = "numpy"
        try:
            slow = codegen.generate_c(table)
            t_slow = _median_time(lambda: codegen.generate_c(table), args.repeat)
        finally:
            del os.environ["STOSPLINE_TABLE_KERNEL"]
        print(f"{name:<26}{_numbers(table):>10}{t_slow:>10.3f}{t_fast:>10.3f}"
              f"{t_slow / t_fast:>8.1f}  {fast == slow}")
        if fast != slow:
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
