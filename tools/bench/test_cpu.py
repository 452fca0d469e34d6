"""CPU seconds of the longest parts of `bash tools/test.sh`, in this checkout and in a baseline
revision exported beside it (`git archive`), timed in the same run.

    .venv/bin/python tools/bench/test_cpu.py [--base main] [ITEM ...]

Items (default: all):
  clang    the clang variant build (ctest clang_build: tests/c/nested_build.cmake into a new
           directory), then its default fuzz tier (clang_fuzz_step: ctest -L '^fuzz$'), with
           each fuzzer's final coverage (cov, ft), which must not move;
  arm      the Cortex-M0+ cross build of every table and image (ctest arm_m0plus_build:
           tools/arm/build.sh --preset arm-m0plus into a new directory);
  arm-m4f  the same for the Cortex-M4F (the build arm_qemu_replay makes);
  records  the host's QEMU replay records (tools/arm/make_replay.py) of the M0+ variants:
           before, arm_m0plus_qemu_replay recorded them again after arm_qemu_replay; now
           arm_replay_records writes them once for both (the base's figure; 0 here);
  regen    tests/python/table/test_gains_regenerate_elsewhere*.py through pytest (-n 0).

CPU is user + system time of the child processes (resource.RUSAGE_CHILDREN), which load
from other processes inflates far less than wall time; the wall time is printed too. The
builds go to temporary directories, removed afterwards.
"""
from __future__ import annotations

import argparse
import os
import re
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
M0PLUS_VARIANTS = "q15,q31,spline,bands_spline,q15_spline,q31_spline"


def _timed(cmd: list[str], cwd: Path, env: dict | None = None) -> tuple[float, float, str]:
    """``(cpu, wall, output)`` of `cmd`; exits on failure with its output."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    proc = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        sys.exit(f"test_cpu: {' '.join(cmd)} failed:\n{proc.stdout[-3000:]}{proc.stderr[-3000:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return cpu, wall, proc.stdout + proc.stderr


def _env(tree: Path) -> dict:
    return {**os.environ, "PYTHONPATH": str(tree / "host"),
            "STOSPLINE_CACHE_DIR": os.environ.get("STOSPLINE_CACHE_DIR",
                                                  str(ROOT / "build" / "cffi"))}


def clang(tree: Path, work: Path) -> dict:
    build = work / "clang"
    cpu_b, wall_b, _ = _timed(["cmake", f"-DSRC={tree}", f"-DBIN={build}", "-DCC=clang",
                               "-DGENERATOR=Ninja", "-P", str(tree / "tests/c/nested_build.cmake")],
                              tree)
    steps = sum(1 for line in (build / ".ninja_log").read_text().splitlines()[1:])
    cpu_f, wall_f, _ = _timed(["ctest", "--test-dir", str(build), "--no-tests=error",
                               "-L", "^fuzz$"], tree)
    log = (build / "Testing/Temporary/LastTest.log").read_text()
    cov = dict(re.findall(r"Test: (\w+)\n(?:(?!\d+/\d+ Test: ).*\n)*?#\d+\s+DONE\s+"
                          r"cov: (\d+ ft: \d+)", log))
    return {"clang build": (cpu_b, wall_b, f"{steps} build steps"),
            "clang fuzz tier": (cpu_f, wall_f, ", ".join(f"{k} cov {v}" for k, v in cov.items()))}


def arm(tree: Path, work: Path, preset: str = "arm-m0plus") -> dict:
    build = work / preset
    cpu, wall, _ = _timed(["bash", str(tree / "tools/arm/build.sh"), "--preset", preset,
                           "--build-dir", str(build)], tree)
    steps = sum(1 for line in (build / ".ninja_log").read_text().splitlines()[1:])
    name = {"arm-m0plus": "M0+", "arm-m4f": "M4F"}[preset]
    return {f"{name} cross build": (cpu, wall, f"{steps} build steps")}


def records(tree: Path, work: Path, base: bool) -> dict:
    if not base:
        return {"M0+ replay records": (0.0, 0.0, "written once by arm_replay_records")}
    cpu, wall, _ = _timed(["bash", str(ROOT / "tools/arm/run_replay.sh"), "--no-setup",
                           "--records-only", "--arith", M0PLUS_VARIANTS,
                           "--build-dir", str(work / "records")], ROOT, _env(ROOT))
    return {"M0+ replay records": (cpu, wall, "recorded again by arm_m0plus_qemu_replay")}


def regen(tree: Path, work: Path) -> dict:
    files = sorted(str(p) for p in (tree / "tests/python/table").glob(
        "test_gains_regenerate_elsewhere*.py"))
    cpu, wall, out = _timed([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                             "-n", "0", *files], tree, _env(tree))
    summary = out.strip().splitlines()[-1]
    return {"regenerate elsewhere": (cpu, wall, f"{len(files)} file(s): {summary}")}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", default="main", help="baseline revision (default: main)")
    ap.add_argument("items", nargs="*", choices=["clang", "arm", "arm-m4f", "records", "regen"],
                    default=["clang", "arm", "arm-m4f", "records", "regen"])
    args = ap.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory(prefix="stsp-test-cpu-") as tmp:
        base = Path(tmp) / "base"
        base.mkdir()
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", args.base],
                                 capture_output=True, check=True).stdout
        subprocess.run(["tar", "-x", "-C", str(base)], input=archive, check=True)
        for name, tree in ((args.base, base), ("this checkout", ROOT)):
            work = Path(tmp) / ("work-base" if tree is base else "work")
            work.mkdir()
            for item in args.items:
                if item == "clang":
                    got = clang(tree, work)
                elif item in ("arm", "arm-m4f"):
                    got = arm(tree, work, "arm-m0plus" if item == "arm" else item)
                elif item == "records":
                    got = records(tree, work, tree is base)
                else:
                    got = regen(tree, work)
                for what, (cpu, wall, note) in got.items():
                    rows.append((what, name, cpu, wall, note))
                    print(f"{what:22s} {name:14s} cpu {cpu:7.1f} s  wall {wall:7.1f} s  {note}",
                          flush=True)
    print("\nCPU seconds, baseline -> this checkout (wall under the machine's load at the time):")
    for what in dict.fromkeys(r[0] for r in rows):
        b = next(r for r in rows if r[0] == what and r[1] == args.base)
        n = next(r for r in rows if r[0] == what and r[1] != args.base)
        print(f"  {what:22s} {b[2]:7.1f} -> {n[2]:7.1f}  ({n[2] - b[2]:+.1f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
