#!/usr/bin/env python3
"""What compiling a table's harness module costs, cold and beside the shared objects.

A harness module links the firmware's objects (one set per arithmetic and table shape), the
loops' object (one per shape, arithmetic and plant) and the table's own C with cffi's
wrappers (`stospline.harness.build`). The bench builds, each in an empty cache directory:

* cold: the robot's table, so the firmware, the loops and the module all compile (what a
  build cost when every table compiled everything: the baseline);
* beside the shared objects: a second table of the same shape and plant (the continuous-time
  design of the same problem) in the cache the first build left, so only its module compiles;

and prints the compiler's CPU time (user + sys of the compiler processes) and wall time of
each, and their ratio. Repeated `--runs` times; medians.

    PYTHONPATH=host .venv/bin/python tools/bench/harness_build.py [--runs 3] [PROBLEM]
"""
from __future__ import annotations

import argparse
import resource
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def compiler_time(fn) -> tuple[float, float]:
    """Wall seconds of ``fn()`` and the CPU seconds of the processes it ran (the compiler)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    fn()
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3, help="repetitions (default 3)")
    ap.add_argument("problem", nargs="?", default=str(ROOT / "examples/robot_corridor.toml"))
    args = ap.parse_args(argv)
    if args.runs < 1:
        ap.exit(2, f"harness_build.py: --runs: must be at least 1, not {args.runs}\n")
    if not Path(args.problem).is_file():
        ap.exit(2, f"harness_build.py: PROBLEM: no file {args.problem}\n")
    from stospline.harness.controller import build_controller
    from stospline.pipeline import design_problem
    from stospline.problem import load_problem
    problem = load_problem(args.problem)
    first = design_problem(problem)
    second = design_problem(problem, discretization="continuous")
    cold, warm = [], []
    for _ in range(args.runs):
        with tempfile.TemporaryDirectory(prefix="stospline-build-") as cache:
            cold.append(compiler_time(lambda: build_controller(first.table, build_dir=cache,
                                                               plant=problem)))
            warm.append(compiler_time(lambda: build_controller(second.table, build_dir=cache,
                                                               plant=problem)))
    rows = [("cold: firmware, loops and module", cold),
            ("beside the shared objects: module only", warm)]
    print(f"{Path(args.problem).name}, {args.runs} runs, medians")
    print(f"{'build':<42} {'compiler CPU (s)':>16} {'wall (s)':>9}")
    for name, runs in rows:
        print(f"{name:<42} {statistics.median(c for _, c in runs):>16.2f} "
              f"{statistics.median(w for w, _ in runs):>9.2f}")
    ratio = statistics.median(c for _, c in cold) / statistics.median(c for _, c in warm)
    print(f"compiler CPU, cold / beside the shared objects: {ratio:.1f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
