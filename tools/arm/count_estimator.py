#!/usr/bin/env python3
"""Report: instructions per stsp_est_step call (the controller on a sensor) on Cortex-M4F under
QEMU, for the robot with a position sensor (gains/robot_position_sensor.*).

    python3 tools/arm/count_estimator.py [--build DIR] [--arith float32|q15|q31] [--spline]
                                         [--replay-only]

Compiles tools/arm/estimator_bench_main.c with firmware/src/*.c and the robot's tables
(arm-none-eabi-gcc -O2, -mcpu=cortex-m4 hard float, -ffp-contract=off, the generic build:
the estimator is not specialised by STSP_FIXED_*), runs it in qemu-system-arm mps2-an386 with
the method of tools/arm/count_instructions.py (-singlestep, -d exec,nochain, -dfilter on
stsp_est_step, everything it calls and the caller bench_step; every traced address checked
against the disassembly) and prints instructions per call by kind of tick. Instructions, not
cycles. With --arith q15: the Q15 build on gains/robot_position_sensor_q15.*, and then the
whole plan replayed on the target (built with -DBENCH_HASH) with the readings of
tests/c/estimator_q_expected.h: its hash of every command and prediction must be that file's
EST_HASH (the host's integer reference, bit for bit), else exit status 1; --replay-only
does that alone (the ctest arm_estimator_q15_replay). With --arith q31 the same on
gains/robot_position_sensor_q31.* against tests/c/estimator_q31_expected.h (the ctest
arm_estimator_q31_replay). With --spline (float32): the spline
tables (gains/robot_position_sensor_spline.*: the spline law, the filter's gains from its
spline, stsp_est_init_spline), counted as above, then the whole plan replayed on the target
beside a per-tick twin holding the host's evaluation of the spline's gains
(tests/c/estimator_spline_expected.h): every command and prediction must be the same bits,
else exit status 1 (--replay-only: that alone, the ctest arm_estimator_spline_replay).
Standard library only.
"""
from __future__ import annotations

import argparse
import re
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from count_instructions import (ROOT, callees, instructions_per_call, run,  # noqa: E402
                                symbols, trace_run)

FLAGS = ["-mcpu=cortex-m4", "-mthumb", "-mfpu=fpv4-sp-d16", "-mfloat-abi=hard", "-std=c99",
         "-O2", "-ffp-contract=off", "-ffunction-sections", "-fdata-sections", "-Wall",
         "-Wextra", "-Wpedantic", "-Wconversion", "-Wshadow", "-Werror"]


SUFFIX = {"float32": "f32", "q15": "q15", "q31": "q31"}
# The host's integer reference of each fixed-point build (tests/c/estimator_q_reference.py).
EXPECTED = {"q15": "estimator_q_expected.h", "q31": "estimator_q31_expected.h"}


def build(out: Path, arith: str = "float32", hashes: bool = False, spline: bool = False) -> Path:
    elf = out / f"{'hash' if hashes else 'bench'}_estimator_{arith}{'_spline' * spline}.elf"
    arm = ROOT / "tools" / "arm"
    name = "robot_position_sensor" + ("" if arith == "float32" else f"_{arith}") + \
        ("_spline" if spline else "")
    defs = ([] if arith == "float32" else [f"-DSTSP_ARITH_{arith.upper()}"]) + \
        (["-DSTSP_EST_SPLINE"] if spline else [])
    run(["arm-none-eabi-gcc", *FLAGS, *defs, *(["-DBENCH_HASH"] if hashes else []),
         f"-I{ROOT / 'firmware/include'}", f"-I{ROOT / 'firmware/src'}", f"-I{ROOT / 'gains'}",
         f"-I{ROOT / 'tests/c'}",
         *sorted(str(p) for p in (ROOT / "firmware/src").glob("*.c")),
         str(ROOT / f"gains/{name}.c"), str(arm / "estimator_bench_main.c"),
         str(arm / "startup.c"), "--specs=rdimon.specs", "-T", str(arm / "mps2-an386.ld"),
         "-Wl,--gc-sections", "-o", str(elf)])
    return elf


def count(elf: Path, arith: str = "float32") -> tuple[list[dict], int]:
    syms = symbols(elf)
    entry = f"stsp_est_step_{SUFFIX[arith]}"
    funcs = callees(elf, syms, entry)
    ranges = {n: syms[n] for n in funcs + ["bench_step"]}
    trace = elf.with_suffix(".trace")
    insns, out = trace_run(elf, ranges, trace)
    calls = [{"tick": int(m[0]), "status": int(m[1]), "reading": m[2] == "1"}
             for m in re.findall(r"call \d+ tick (\d+) status (-?\d+) reading (\d)", out)]
    size = int(re.search(r"sizeof (\d+)", out).group(1))
    counts = instructions_per_call(trace, insns, {syms[entry][0]},
                                   [ranges["bench_step"]])
    if len(counts) != len(calls):
        raise SystemExit(f"count: {len(counts)} calls traced, the bench reports {len(calls)}")
    for c, k in zip(calls, counts):
        c["insns"] = k
    return calls, size


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--build", type=Path, default=ROOT / "build" / "arm-estimator")
    ap.add_argument("--arith", choices=sorted(SUFFIX), default="float32")
    ap.add_argument("--spline", action="store_true",
                    help="the spline tables (float32): the filter's gains from its spline")
    ap.add_argument("--replay-only", action="store_true",
                    help="only the whole-plan replay against the host reference (fixed point) "
                         "or the per-tick twin (--spline)")
    args = ap.parse_args()
    args.build.mkdir(parents=True, exist_ok=True)
    if args.spline and args.arith != "float32":
        ap.error("--spline: the estimator's gain spline is float32")
    if args.replay_only:
        if args.spline:
            return check_spline_replay(args.build)
        if args.arith == "float32":
            ap.error("--replay-only replays a fixed-point build: give --arith q15, q31 or --spline")
        return check_hash(args.build, args.arith)
    calls, size = count(build(args.build, args.arith, spline=args.spline), args.arith)
    every = 20
    kinds = {
        "tick 0: reading, latch of stage 0": lambda c: c["tick"] == 0,
        "ordinary tick, no reading (predict only)":
            lambda c: 0 < c["tick"] < 3000 and c["tick"] % every and c["status"] == 0,
        "ordinary tick with a reading": lambda c: 0 < c["tick"] < 2999 and not c["tick"] % every,
        "skip to 2999 (predicts over 2957 ticks)": lambda c: c["tick"] == 2999,
        "tick 3000: reading, latch of stage 1": lambda c: c["tick"] == 3000,
    }
    what = f"{args.arith}{', spline tables' if args.spline else ''}"
    print(f"| stsp_est_step ({what}), Cortex-M4F (QEMU) | calls | instructions (median) "
          f"| min-max |")
    print("|---|---|---|---|")
    for name, sel in kinds.items():
        k = [c["insns"] for c in calls if sel(c)]
        print(f"| {name} | {len(k)} | {statistics.median(k):.0f} | {min(k)}-{max(k)} |")
    print(f"\nsizeof(stsp_est_t) = {size} bytes")
    if args.spline:
        return check_spline_replay(args.build)
    return 0 if args.arith == "float32" else check_hash(args.build, args.arith)


def check_spline_replay(out: Path) -> int:
    """The whole plan on the target, the spline tables beside their per-tick twin: no command
    or prediction may differ by a bit."""
    elf = build(out, "float32", hashes=True, spline=True)
    text = run(["timeout", "600", "qemu-system-arm", "-M", "mps2-an386", "-nographic",
                "-monitor", "none", "-semihosting-config", "enable=on,target=native",
                "-kernel", str(elf)])
    got = re.search(r"replay (\d+) ticks, (\d+) differing, hash (0x[0-9A-F]{8})", text)
    ok = got is not None and got.group(2) == "0"
    print(f"whole plan replayed on the M4F, spline gains against the per-tick twin: "
          f"{got.group(0) if got else 'no output'} {'ok' if ok else 'DIFFERS'}")
    return 0 if ok else 1


def check_hash(out: Path, arith: str) -> int:
    """The whole plan on the target against the EST_HASH of tests/c/EXPECTED[arith]."""
    elf = build(out, arith, hashes=True)
    got = re.search(r"hash (0x[0-9A-F]{8})", run(
        ["timeout", "600", "qemu-system-arm", "-M", "mps2-an386", "-nographic", "-monitor",
         "none", "-semihosting-config", "enable=on,target=native", "-kernel", str(elf)]))
    want = re.search(r"#define EST_HASH (0x[0-9A-F]{8})u",
                     (ROOT / "tests/c" / EXPECTED[arith]).read_text()).group(1)
    ok = got is not None and got.group(1) == want
    print(f"whole plan replayed: M4F {got.group(1) if got else 'none'}, host reference {want} "
          f"{'ok' if ok else 'DIFFERS'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
