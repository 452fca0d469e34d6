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

import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_util import example_args, example_path, median_time, numpy_baseline  # noqa: E402


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
    args = example_args("c_text", __doc__, argv, ["robot_corridor.toml", "coupled_axes.toml"], 5)
    if args is None:
        return 2
    from stospline import design_problem, load_problem
    from stospline.table import codegen, kernels
    if kernels._kernel() is None:
        print("c_text: the table kernel is not built (no C compiler?)", file=sys.stderr)
        return 2
    tables = []
    for name in args.examples:
        path = example_path(name)
        if path is None:
            print(f"c_text: no problem file {name}", file=sys.stderr)
            return 2
        tables.append((path.stem, design_problem(load_problem(path)).table))
    tables.append(("dense 12x4, 3441 ticks", _dense_table(tables[0][1])))
    print(f"{'table':<26}{'numbers':>10}{'numpy s':>10}{'kernel s':>10}{'ratio':>8}  same bytes")
    for name, table in tables:
        fast = codegen.generate_c(table)
        write = lambda: codegen.generate_c(table)  # noqa: E731
        t_fast, _ = median_time(write, args.repeat, clock=time.process_time)
        with numpy_baseline("STOSPLINE_TABLE_KERNEL"):
            slow = codegen.generate_c(table)
            t_slow, _ = median_time(write, args.repeat, clock=time.process_time)
        print(f"{name:<26}{_numbers(table):>10}{t_slow:>10.3f}{t_fast:>10.3f}"
              f"{t_slow / t_fast:>8.1f}  {fast == slow}")
        if fast != slow:
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
