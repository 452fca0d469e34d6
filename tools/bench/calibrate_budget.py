"""Check the memory/time estimates of `stospline.budget` against real runs on this machine.

Usage: .venv/bin/python tools/bench/calibrate_budget.py [--quick | --peak]

Runs each case below as the CLI runs it (``stospline design|simulate FILE --quiet``, a fresh
process, so the times include start-up) and prints, per case, the estimate beside the measured
wall time and peak memory (`measure`), with their ratios. ``--peak`` runs the spread of
`PEAK_CASES` (corridors, worker processes, the tick-grid QP, a report) and prints the table
"estimate vs measured peak memory" of docs/evidence/performance.md; the estimate must not be
below the measurement (tests/python/cli/test_budget_vs_measured.py runs the same cases). The
constants in ``host/stospline/budget.py`` were set from these runs so that the estimate is
within a factor of about 3 of every case (docs/guide/problem-file.md, "Limits"). Cases: the robot
at 1 and 20 kHz, float32, Q15 and continuous; a 12-state, 4-input chain; 250 short stages (the firmware takes at most 256);
a joint design with 32 constrained knots; a simulation with 2000 paths.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import threading
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


def robot_corridors(count: int) -> str:
    """The robot with its corridor repeated `count` times."""
    text = robot(1000)
    i = text.index("[[corridors]]")
    return text[:i] + text[i:] * count


def robot_between_ticks(hz: int) -> str:
    """The robot, joint, with E{x} <= -1 at every tick and between ticks over [0, 6] (the
    tick-grid QP with a row between every two ticks)."""
    text = robot(hz)
    text = text[:text.index("# A reading")].replace(f"tick_hz = {hz}\n",
                                                     f'tick_hz = {hz}\n[design]\nmode = "joint"\n', 1)
    return text + ("[[regions]]\nt = [0.0, 6.0]\nevery = \"tick\"\nC = [[1, 0, 0, 0]]\n"
                   "lower = [-6.0]\nupper = [-1.0]\nbetween_ticks = true\n")


PEAK_CASES = [  # (label, file text, command line after FILE)
    ("design robot 1 kHz", robot(1000), ["design"]),
    ("simulate robot, 1 corridor x 100, 500 paths", robot_corridors(100),
     ["simulate", "--paths", "500", "--substeps", "1"]),
    ("simulate robot 4000 paths, 1 worker", robot(1000),
     ["simulate", "--paths", "4000", "--substeps", "1", "--workers", "1"]),
    ("simulate robot 4000 paths, 2 workers", robot(1000),
     ["simulate", "--paths", "4000", "--substeps", "1", "--workers", "2", "--force-workers"]),
    ("design robot_monotone 100 Hz (regions at every tick)",
     (ROOT / "examples" / "robot_monotone.toml").read_text(), ["design"]),
    ("design robot, region between ticks, 500 Hz (tick-grid QP)", robot_between_ticks(500),
     ["design"]),
    ("report robot 200 paths", robot(1000),
     ["report", "--paths", "200", "--substeps", "1", "--fault-paths", "0"]),
]


def _tree(pid: int) -> list[int]:
    """`pid` and its descendants (Linux /proc)."""
    out, todo = [], [pid]
    while todo:
        p = todo.pop()
        out.append(p)
        try:
            for task in os.listdir(f"/proc/{p}/task"):
                with open(f"/proc/{p}/task/{task}/children") as f:
                    todo += [int(c) for c in f.read().split()]
        except OSError:
            pass
    return out


def _pss(pid: int) -> int:
    """Proportional set size of a process in bytes (its share of pages it shares with
    others, so forked workers are not counted twice), 0 once it has gone."""
    try:
        with open(f"/proc/{pid}/smaps_rollup") as f:
            for line in f:
                if line.startswith("Pss:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


def measure(argv: list[str], env: dict | None = None) -> tuple[float, float, int, str]:
    """Wall seconds, peak memory in bytes, exit status and stderr of `argv` in a fresh
    process. The peak is the larger of the child's ``ru_maxrss`` (read in a wrapper process,
    so that it is this run's) and the largest total proportional set size of the child and
    its worker processes, sampled every 10 ms."""
    wrapper = ("import resource, subprocess, sys; r = subprocess.run(sys.argv[1:]); "
               "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, "
               "file=sys.stderr); sys.exit(r.returncode)")
    t = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-c", wrapper, *argv], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True, env=env)
    peak = [0]

    def sample():
        while proc.poll() is None:
            peak[0] = max(peak[0], sum(_pss(p) for p in _tree(proc.pid)[1:]))
            time.sleep(0.01)
    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    err = proc.communicate()[1]
    sampler.join()
    wall = time.perf_counter() - t
    *lines, maxrss = err.rstrip("\n").split("\n")
    return wall, max(peak[0], float(maxrss) * 1024), proc.returncode, "\n".join(lines)


def cli_argv(text: str, cmd: list[str], tmp: Path) -> list[str]:
    """The CLI run of one case on `text` (written to tmp/case.toml), limits out of the way."""
    src = tmp / "case.toml"
    src.write_text(text)
    argv = [*STOSPLINE, cmd[0], str(src), *cmd[1:], "--quiet", "--max-time", "1e9",
            "--max-memory", "1e6"]
    if cmd[0] == "design":
        argv += ["--out", str(tmp / "out")]
    if cmd[0] == "report":
        argv += ["--out", str(tmp / "report.html")]
    return argv


def run(text: str, cmd: list[str], tmp: Path) -> tuple[float, float]:
    """Wall seconds and peak memory bytes of one CLI run in a fresh process."""
    env = {**os.environ, "STOSPLINE_CACHE_DIR": str(tmp / "build")}   # compile, as a user would
    wall, peak, code, err = measure(cli_argv(text, cmd, tmp), env)
    if code != 0:
        raise SystemExit(f"{cmd}: exit {code}: {err}")
    return wall, peak


def case_estimate(text: str, cmd: list[str]):
    """`stospline.budget.estimate` of a case, with the options its command line gives."""
    import tomllib
    from stospline import budget
    from stospline.cli import REPORT_RECORD
    from stospline.problem import parse_problem
    from stospline.harness.montecarlo import usable_workers
    problem = parse_problem(tomllib.loads(text))

    def option(name, default):
        return int(cmd[cmd.index(name) + 1]) if name in cmd else default
    workers = usable_workers(option("--workers", None), "--force-workers" in cmd)
    return budget.estimate(
        problem, command=cmd[0], mode=problem.options.get("mode", "stagewise"),
        discretization="continuous" if "continuous" in cmd else "exact-zoh",
        arith="q15" if "q15" in cmd else "float32", paths=option("--paths", 0),
        substeps=option("--substeps", 2), workers=1 if cmd[0] == "design" else workers,
        record=REPORT_RECORD if cmd[0] == "report" else 0)


def peak_table() -> None:
    """The table "estimate vs measured peak memory" over `PEAK_CASES`."""
    from stospline import budget
    print("| case | estimate | measured peak | estimate / measured |")
    print("|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for label, text, cmd in PEAK_CASES:
            est = case_estimate(text, cmd)
            _, rss = run(text, cmd, Path(tmp))
            print(f"| {label} | {budget.format_bytes(est.bytes)} | {budget.format_bytes(rss)} "
                  f"| {est.bytes / rss:.2f} |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="only the cases that take seconds")
    ap.add_argument("--peak", action="store_true",
                    help="the estimate against the measured peak memory over a spread of "
                         "cases (docs/evidence/performance.md)")
    args = ap.parse_args()
    if args.peak:
        peak_table()
        return
    from stospline import budget
    print(f"| case | estimate | measured | est/meas time | est/meas memory |")
    print(f"|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for label, text, cmd, quick in CASES:
            if args.quick and not quick:
                continue
            est = case_estimate(text, cmd)
            wall, rss = run(text, cmd, Path(tmp))
            print(f"| {label} | {budget.format_seconds(est.seconds)}, "
                  f"{budget.format_bytes(est.bytes)} | {budget.format_seconds(wall)}, "
                  f"{budget.format_bytes(rss)} | {est.seconds / wall:.2f} | "
                  f"{est.bytes / rss:.2f} |", flush=True)


if __name__ == "__main__":
    os.environ.setdefault("PYTHONHASHSEED", "0")
    main()
