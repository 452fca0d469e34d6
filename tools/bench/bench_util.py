"""Shared by the benches of tools/bench: the median time of repeated calls, the numpy
baseline of a compiled kernel switched on for a block, the example problem files."""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from contextlib import contextmanager
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def median_time(fn, repeat: int, *, warm_up: bool = False, clock=time.perf_counter):
    """``(seconds, result)``: the median time of `repeat` calls of `fn` (after one untimed
    call with `warm_up`) and the last call's result; wall time, or `clock`
    (``time.process_time``: CPU time, which load from other processes inflates least)."""
    if warm_up:
        fn()
    times, out = [], None
    for _ in range(repeat):
        t = clock()
        out = fn()
        times.append(clock() - t)
    return statistics.median(times), out


@contextmanager
def numpy_baseline(variable: str):
    """Inside the block, the environment `variable` (``STOSPLINE_*_KERNEL``) asks for the
    numpy reference instead of the compiled kernel."""
    os.environ[variable] = "numpy"
    try:
        yield
    finally:
        del os.environ[variable]


def example_path(name: str) -> Path | None:
    """The problem file `name`: a path, else a file of examples/; None where neither is."""
    path = Path(name) if Path(name).exists() else ROOT / "examples" / name
    return path if path.is_file() else None


def example_args(tool: str, doc: str, argv: list[str] | None, examples: list[str],
                 repeat: int):
    """The arguments of a bench over example problems (``EXAMPLE.toml ... [--repeat N]``), or
    None after one line naming the field where ``--repeat`` is below 1."""
    ap = argparse.ArgumentParser(description=doc.split("\n\n")[0])
    ap.add_argument("examples", nargs="*", default=examples)
    ap.add_argument("--repeat", type=int, default=repeat)
    args = ap.parse_args(argv)
    if args.repeat < 1:
        print(f"{tool}: --repeat must be at least 1", file=sys.stderr)
        return None
    return args
