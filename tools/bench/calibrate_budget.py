"""Check the memory/time estimates of `stospline.budget` against real runs on this machine.

Usage: .venv/bin/python tools/bench/calibrate_budget.py [--quick]

Runs each case below as the CLI runs it (``stospline design|simulate FILE --quiet``, a fresh
process, so the times include start-up) and prints, per case, the estimate beside the measured
wall time and peak resident memory (``ru_maxrss`` of the child), with their ratios. The
constants in ``host/stospline/budget.py`` were set from these runs so that the estimate is
within a factor of about 3 of every case (docs/guide/problem-file.md, "Limits"). Cases: the robot
at 1 and 20 kHz, float32, Q15 and continuous; a 12-state, 4-input chain; 250 short stages (the firmware takes at most 256);
a joint design with 32 constrained knots; a simulation with 2000 paths.
"""
from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
STOSPLINE = [sys.executable, "-m", "stospline.cli"]


def chain(n: int, m: int, stages: int, hz: int, *, rows: int = 0, mode="stagewise") -> str:
    """A seeded chain of n states and m inputs, `stages` knots over 1 s, noise on state 0;
    with `rows`, every knot constrains its first `rows` states (else a penalty)."""
    rng = np.random.default_rng(1)
    A = (rng.standard_normal((n, n)) * 0.3 - np.eye(n)).tolist()
    B = rng.standard_normal((n, m)).tolist()
    G = np.zeros((n, 1))
    G[0, 0] = 0.1
    lines = ['name = "chain"', f"x0 = {[1.0] * n}", f"tick_hz = {hz}",
             f'[design]\nmode = "{mode}"',
             f"[dynamics]\nA = {A}\nB = {B}\nnoise = [{{ state = 0, G = {G.tolist()} }}]",
             f"[cost]\nR = {np.eye(m).tolist()}\nQ = {np.eye(n).tolist()}"]
    for k in range(stages):
        t = (k + 1) / stages
        if rows:
            c = f"constraint = {{ C = {np.eye(n)[:rows].tolist()}, value = {[0.5] * rows} }}"
        else:
            c = f"penalty = {{ C = {np.eye(n)[:1].tolist()}, target = [1.0], weight = 1.0 }}"
        lines.append(f"[[knots]]\nt = {t!r}\n{c}")
    return "\n".join(lines) + "\n"


def robot(hz: int) -> str:
    text = (ROOT / "examples" / "robot_corridor.toml").read_text()
    return text.replace("tick_hz = 1000\n", f"tick_hz = {hz}\n")


CASES = [  # (label, file text, command line after FILE, quick)
    ("robot 1 kHz", robot(1000), ["design"], True),
    ("robot 20 kHz", robot(20000), ["design"], False),
    ("robot 1 kHz q15", robot(1000), ["design", "--arith", "q15"], True),
    ("robot 1 kHz continuous", robot(1000), ["design", "--discretization", "continuous"], False),
    ("chain n=12 m=4, 4 stages, 2 kHz", chain(12, 4, 4, 2000), ["design"], False),
    ("chain n=2 m=1, 250 stages", chain(2, 1, 250, 4000), ["design"], False),
    ("chain n=6 m=2, joint, 32 knots x 2 rows", chain(6, 2, 32, 3200, rows=2, mode="joint"),
     ["design"], False),
    ("robot simulate 2000 paths", robot(1000),
     ["simulate", "--paths", "2000", "--substeps", "2"], True),
    ("robot 10 kHz simulate 20 paths", robot(10000), ["simulate", "--paths", "20"], False),
]


def run(text: str, cmd: list[str], tmp: Path) -> tuple[float, float]:
    """Wall seconds and peak RSS bytes of one CLI run in a fresh process."""
    src = tmp / "case.toml"
    src.write_text(text)
    argv = [*STOSPLINE, cmd[0], str(src), *cmd[1:], "--quiet", "--max-time", "1e9",
            "--max-memory", "1e6"]
    if cmd[0] == "design":
        argv += ["--out", str(tmp / "out")]
    # ru_maxrss of RUSAGE_CHILDREN is the largest child so far: run each case in a wrapper
    # process so that the figure is this case's.
    wrapper = ("import resource, subprocess, sys; r = subprocess.run(sys.argv[1:]); "
               "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss); "
               "sys.exit(r.returncode)")
    t = time.perf_counter()
    env = {**os.environ, "STOSPLINE_BUILD": str(tmp / "build")}   # compile, as a user would
    r = subprocess.run([sys.executable, "-c", wrapper, *argv], capture_output=True, text=True,
                       env=env)
    wall = time.perf_counter() - t
    if r.returncode != 0:
        raise SystemExit(f"{cmd}: exit {r.returncode}: {r.stderr}")
    return wall, float(r.stdout.split()[-1]) * 1024


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="only the cases that take seconds")
    args = ap.parse_args()
    from stospline import budget
    from stospline.problem import parse_problem
    import tomllib
    print(f"| case | estimate | measured | est/meas time | est/meas memory |")
    print(f"|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for label, text, cmd, quick in CASES:
            if args.quick and not quick:
                continue
            problem = parse_problem(tomllib.loads(text))
            opts = {"command": cmd[0], "mode": problem.options.get("mode", "stagewise"),
                    "discretization": "continuous" if "continuous" in cmd else "exact-zoh",
                    "arith": "q15" if "q15" in cmd else "float32",
                    "paths": int(cmd[cmd.index("--paths") + 1]) if "--paths" in cmd else 0}
            est = budget.estimate(problem, **opts)
            wall, rss = run(text, cmd, Path(tmp))
            print(f"| {label} | {budget.format_seconds(est.seconds)}, "
                  f"{budget.format_bytes(est.bytes)} | {budget.format_seconds(wall)}, "
                  f"{budget.format_bytes(rss)} | {est.seconds / wall:.2f} | "
                  f"{est.bytes / rss:.2f} |", flush=True)


if __name__ == "__main__":
    os.environ.setdefault("PYTHONHASHSEED", "0")
    main()
