#!/usr/bin/env python3
"""How fast a Q15/Q31 design finds its state scales (`oracle.state_range`: the exact moments
at every tick of the plan): the oracle's C tick loop recording the path against its numpy
loop (``STOSPLINE_ORACLE_KERNEL=numpy``), the baseline, timed in the same run on the same
tables; the two ranges must agree to rounding.

    PYTHONPATH=host .venv/bin/python tools/bench/state_range.py [--repeat 3] [EXAMPLE.toml ...]
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_util import example_args, example_path, median_time, numpy_baseline  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    args = example_args("state_range", __doc__, argv,
                        ["robot_corridor.toml", "robot_patrol_60s.toml"], 3)
    if args is None:
        return 2
    from stospline import design_problem, load_problem
    from stospline.oracle import evaluate as oracle
    if oracle._c_kernel() is None:
        print("state_range: the oracle kernel is not built (no C compiler?)", file=sys.stderr)
        return 2
    print(f"{'example':<24}{'ticks':>8}{'numpy s':>10}{'C s':>9}{'ratio':>8}  max rel. diff")
    for name in args.examples:
        path = example_path(name)
        if path is None:
            print(f"state_range: no problem file {name}", file=sys.stderr)
            return 2
        problem = load_problem(path)
        table = design_problem(problem, table="per-tick").table
        t_c, r_c = median_time(lambda: oracle.state_range(problem, table), args.repeat)
        with numpy_baseline("STOSPLINE_ORACLE_KERNEL"):
            t_np, r_np = median_time(lambda: oracle.state_range(problem, table), args.repeat)
        diff = float(np.max(np.abs(r_c - r_np) / np.abs(r_np)))
        print(f"{path.stem:<24}{table.n_ticks:>8}{t_np:>10.3f}{t_c:>9.3f}{t_np / t_c:>8.1f}"
              f"  {diff:.1e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
