#!/usr/bin/env python3
"""How fast `stospline design examples/robot_corridor.toml --json --out DIR` answers.

Prints the median (and min) wall time of N whole-process runs of ``python -m stospline``
(imports, design, oracle, C text, JSON, the files written), the CPU time the runs took (user +
sys: what the command costs on an idle machine), the same for ``python -c "import numpy"`` as
the floor and the ratio of the two medians, the time of each phase in one process (import,
load, design and oracle, JSON, C text, writing the files), where import time goes (`python -X
importtime`, cumulative microseconds of the biggest top-level imports) and the load average
before and after the runs.

    .venv/bin/python tools/bench/cli_startup.py [--runs 10] [PROBLEM]

Only the standard library and the installed stospline are used. Run it on an idle machine:
wall time on a loaded one measures the other processes too (the CPU column less so). Two ways
of running are timed, taking turns with the floor:

* "installed": the bytecode cached (in a temporary ``PYTHONPYCACHEPREFIX``, even where
  ``PYTHONDONTWRITEBYTECODE`` is set), as an installed package has it;
* "sources": the same, except that stospline's own modules are compiled from source in every
  run, as a source checkout without ``__pycache__`` runs under ``PYTHONDONTWRITEBYTECODE=1``
  (Python's and numpy's bytecode stays cached).
"""
from __future__ import annotations

import argparse
import os
import re
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
# Bytecode cached as for an installed package (see the module docstring).
ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
ENV["PYTHONPYCACHEPREFIX"] = tempfile.mkdtemp(prefix="stospline-startup-pyc-")

PHASES = r"""
import sys, tempfile, time
t = [time.perf_counter()]
import stospline.cli, stospline.pipeline
t.append(time.perf_counter())
from stospline.cli import load_problem
p = load_problem(sys.argv[1])
t.append(time.perf_counter())
from stospline.pipeline import design_files, design_problem, write_outputs
d = design_problem(p)
t.append(time.perf_counter())
design_files(d, "x.toml", with_c=False)
t.append(time.perf_counter())
files, _ = design_files(d, "x.toml")
t.append(time.perf_counter())
with tempfile.TemporaryDirectory() as out:
    t.append(time.perf_counter())
    write_outputs(out, files, [sys.argv[1]])
    t.append(time.perf_counter())
dt = [b - a for a, b in zip(t, t[1:])]
dt[4] -= dt[3]                   # the C text alone (the JSON summary is made again)
# What finding the three cached kernels costs a run (their C read and hashed, the cache
# directory listed), measured again now that they are loaded.
from stospline.design.kernels import build_kernels
from stospline.oracle.kernel import build_kernel as build_oracle_kernel
from stospline.table.kernels import build_kernel as build_table_kernel
k = time.perf_counter()
build_kernels(), build_oracle_kernel(), build_table_kernel()
print(" ".join(f"{v:.5f}" for v in dt[:5] + dt[6:] + [time.perf_counter() - k]))
"""
PHASE_NAMES = ("import", "load problem", "design + oracle", "JSON summary", "C text",
               "files written", "looking up the 3 cached kernels (in the design, C text)")


def sources_env() -> dict[str, str]:
    """`ENV` for the "sources" runs (module docstring): a copy of the warm bytecode cache
    without stospline's, and no bytecode written."""
    from importlib.util import find_spec
    package = Path(find_spec("stospline").origin).resolve().parent
    prefix = tempfile.mkdtemp(prefix="stospline-startup-src-pyc-")
    shutil.copytree(ENV["PYTHONPYCACHEPREFIX"], prefix, dirs_exist_ok=True)
    shutil.rmtree(Path(prefix + str(package)), ignore_errors=True)
    return {**ENV, "PYTHONPYCACHEPREFIX": prefix, "PYTHONDONTWRITEBYTECODE": "1"}


def timed_run(cmd: list[str], env: dict[str, str]) -> tuple[float, float]:
    """Wall and CPU (user + sys) seconds of one run of `cmd`."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, env=env)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime


def timed_runs(commands: list[tuple[list[str], dict]], runs: int
               ) -> list[tuple[list[float], list[float]]]:
    """``(walls, cpus)`` of each ``(command, environment)``, the commands taking turns so that
    a change in the machine's load weighs on all of them alike."""
    times = [([], []) for _ in commands]
    for _ in range(runs):
        for (cmd, env), (walls, cpus) in zip(commands, times):
            wall, cpu = timed_run(cmd, env)
            walls.append(wall)
            cpus.append(cpu)
    return times


def import_breakdown(python: str, problem: str, top: int) -> list[tuple[int, str]]:
    """Cumulative import time (us) of the imports at nesting depth <= 1, largest first."""
    res = subprocess.run([python, "-X", "importtime", "-m", "stospline", "design", problem,
                          "--json"], capture_output=True, text=True, check=True, env=ENV)
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
    out = tempfile.mkdtemp(prefix="stospline-startup-")    # each run replaces the same files
    cmd = [python, "-m", "stospline", "design", args.problem, "--json", "--out", out]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, env=ENV)   # warm: kernels, bytecode
    subprocess.run([python, "-c", "import numpy"], check=True, env=ENV)
    load = os.getloadavg()
    runs = timed_runs([(cmd, ENV), (cmd, sources_env()),
                       ([python, "-c", "import numpy"], ENV)], args.runs)
    print(" ".join(["python", *cmd[1:-1], "DIR"]) + f"   ({args.runs} runs each, taking turns)")
    print(f"  load average {load[0]:.2f} before, {os.getloadavg()[0]:.2f} after (1 min)")
    base, base_cpu = runs[-1]
    print(f"  floor      python -c 'import numpy': median {statistics.median(base):.3f} s wall, "
          f"{statistics.median(base_cpu):.3f} s cpu")
    for name, (walls, cpus) in zip(("installed", "sources"), runs):
        print(f"  {name:<10} wall median {statistics.median(walls):.3f} s (min "
              f"{min(walls):.3f}), cpu median {statistics.median(cpus):.3f} s; "
              f"{statistics.median(walls) / statistics.median(base):.2f}x the floor (wall), "
              f"{statistics.median(cpus) / statistics.median(base_cpu):.2f}x (cpu)")
    phases = [subprocess.run([python, "-c", PHASES, args.problem], capture_output=True,
                             text=True, check=True, env=ENV).stdout.split() for _ in range(3)]
    med = [statistics.median(float(p[i]) for p in phases) for i in range(len(PHASE_NAMES))]
    print("  phases (installed, one process, median of 3): " + ", ".join(
        f"{name} {v * 1e3:.1f} ms" for name, v in zip(PHASE_NAMES, med)))
    print("  imports (python -X importtime, cumulative):")
    for us, name in import_breakdown(python, args.problem, args.top):
        print(f"    {us / 1e3:8.1f} ms  {name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
