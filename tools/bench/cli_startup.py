#!/usr/bin/env python3
"""How fast `stospline design examples/robot_corridor.toml --json` answers.

Prints the median (and min) wall time of N runs of the installed `stospline` command, the CPU
time the runs took (user + sys: what the command costs on an idle machine), the time of each
phase in one process (import, load, design, JSON), and where import time goes
(`python -X importtime`, cumulative microseconds of the biggest top-level imports).

    .venv/bin/python tools/bench/cli_startup.py [--runs 10] [PROBLEM]

Only the standard library and the installed stospline are used. Run it on an idle machine:
wall time on a loaded one measures the other processes too (the CPU column does not).
"""
from __future__ import annotations

import argparse
import re
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

PHASES = r"""
import sys, time
t0 = time.perf_counter()
import stospline.cli, stospline.pipeline
t1 = time.perf_counter()
from stospline.problem import load_problem
p = load_problem(sys.argv[1])
t2 = time.perf_counter()
from stospline.pipeline import design_problem, generated_files
d = design_problem(p)
t3 = time.perf_counter()
files = generated_files(d, "x.toml", with_c=False)
t4 = time.perf_counter()
print(f"{t1 - t0:.4f} {t2 - t1:.4f} {t3 - t2:.4f} {t4 - t3:.4f}")
"""


def timed_runs(cmd: list[str], runs: int) -> tuple[list[float], list[float]]:
    walls, cpus = [], []
    for _ in range(runs):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t = time.perf_counter()
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
        walls.append(time.perf_counter() - t)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpus.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return walls, cpus


def import_breakdown(python: str, problem: str, top: int) -> list[tuple[int, str]]:
    """Cumulative import time (us) of the imports at nesting depth <= 1, largest first."""
    res = subprocess.run([python, "-X", "importtime", "-m", "stospline.cli", "design", problem,
                          "--json"], capture_output=True, text=True, check=True)
    rows = []
    for line in res.stderr.splitlines():
        m = re.match(r"import time:\s+(\d+) \|\s+(\d+) \|( *)(\S+)", line)
        if m and len(m.group(3)) <= 3:     # one space for depth 0, three for depth 1
            rows.append((int(m.group(2)), ("  " if len(m.group(3)) > 1 else "") + m.group(4)))
    return sorted(rows, reverse=True)[:top]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("problem", nargs="?", default=str(ROOT / "examples" / "robot_corridor.toml"))
    ap.add_argument("--runs", type=int, default=10)
    ap.add_argument("--top", type=int, default=12, help="import rows to show")
    args = ap.parse_args()
    python = sys.executable
    exe = str(Path(python).parent / "stospline")
    cmd = [exe, "design", args.problem, "--json"]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)     # warm: kernels built, disk cache
    walls, cpus = timed_runs(cmd, args.runs)
    print(f"{' '.join(Path(c).name if i < 2 else c for i, c in enumerate(cmd))}")
    print(f"  wall   median {statistics.median(walls):.3f} s   min {min(walls):.3f} s   "
          f"({args.runs} runs)")
    print(f"  cpu    median {statistics.median(cpus):.3f} s   (user + sys)")
    base, base_cpu = timed_runs([python, "-c", "import numpy"], max(3, args.runs // 2))
    print(f"  floor  python + import numpy: median {statistics.median(base):.3f} s wall, "
          f"{statistics.median(base_cpu):.3f} s cpu")
    phases = [subprocess.run([python, "-c", PHASES, args.problem], capture_output=True,
                             text=True, check=True).stdout.split() for _ in range(3)]
    med = [statistics.median(float(p[i]) for p in phases) for i in range(4)]
    print("  phases (one process, median of 3): " + ", ".join(
        f"{name} {v * 1e3:.0f} ms" for name, v in
        zip(("import", "load problem", "design + oracle", "JSON summary"), med)))
    print("  imports (python -X importtime, cumulative):")
    for us, name in import_breakdown(python, args.problem, args.top):
        print(f"    {us / 1e3:8.1f} ms  {name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
