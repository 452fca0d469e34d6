#!/usr/bin/env python3
"""Peak memory of a Monte Carlo run against its path count: streamed statistics (the default)
beside per-path records (``per_path=True``, what every run kept before the statistics
streamed), in the same run.

Each point is a fresh process (`simulate` of the robot corridor at 10 Hz, 60 ticks, one
plant step per tick, in that process: workers=1) whose peak resident set (``ru_maxrss``) is
printed with its growth over the smallest path count.

    PYTHONPATH=host .venv/bin/python tools/bench/harness_memory.py [--paths 20000,200000,2000000]
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

_RUN = """
import resource, sys, tomllib
from stospline.pipeline import design_problem
from stospline.problem import parse_problem
from stospline.harness.controller import build_controller
from stospline.harness.montecarlo import simulate
doc = tomllib.loads(open(sys.argv[1]).read())
doc["tick_hz"] = 10
p = parse_problem(doc)
ctl = build_controller(design_problem(p).table)
simulate(p, ctl, paths=int(sys.argv[2]), seed=1, substeps=1, workers=1,
         per_path=sys.argv[3] == "1")
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024)
"""


def peak(paths: int, per_path: bool) -> int:
    env = {**os.environ, "PYTHONPATH": str(ROOT / "host")}
    out = subprocess.run([sys.executable, "-c", _RUN, str(ROOT / "examples" /
                                                          "robot_corridor.toml"),
                          str(paths), "1" if per_path else "0"], env=env, check=True,
                         capture_output=True, text=True).stdout
    return int(out.split()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--paths", default="20000,200000,2000000")
    args = ap.parse_args()
    counts = [int(v) for v in args.paths.split(",")]
    print("robot corridor at 10 Hz (60 ticks), one process; peak resident set, MiB")
    print(f"{'paths':>9} {'streamed':>9} {'growth':>8} {'per-path':>9} {'growth':>8}")
    peak(counts[0], False)            # a first run compiles the 10 Hz table's controller
    first = None
    for paths in counts:
        s, k = peak(paths, False), peak(paths, True)
        first = first or (s, k)
        print(f"{paths:>9} {s / 2**20:9.1f} {(s - first[0]) / 2**20:+8.1f} "
              f"{k / 2**20:9.1f} {(k - first[1]) / 2**20:+8.1f}")


if __name__ == "__main__":
    main()
