#!/usr/bin/env python3
"""Report: flash bytes and instructions per tick on Cortex-M4F under QEMU of the examples
with runtime parameters: the robot with its goal as a parameter (gains/robot_goal*) and the
drone through gates whose six coordinates are parameters (gains/drone_gates*), through
stsp_step() (no parameters) and through stsp_param_step() (theta set inside the range).

    python3 tools/arm/count_params.py [--build DIR] [--example robot_goal|drone_gates|all]
                                      [--arith float32|q15|q31|spline|q15-spline|q31-spline]

Bytes: the const data of gains/<name>.c (the table) and of gains/<name>_params.c (the columns,
nominal and range, and the 76-byte stsp_params_table_t), compiled for the M4F
(arm-none-eabi-size). The default, --example all, prints both examples in float32; Q15/Q31
and spline tables exist for the robot only (--arith q15 with the drone: exit status 2).

Compiles tools/arm/params_bench_main.c with firmware/src/*.c and the robot's tables
(arm-none-eabi-gcc -O2, -mcpu=cortex-m4 hard float, -ffp-contract=off, the generic build),
runs it in qemu-system-arm mps2-an386 with the method of tools/arm/count_instructions.py
(-singlestep, -d exec,nochain, -dfilter on both entry points, everything they call and the
bench callers; every traced address checked against the disassembly) and prints instructions
per call by kind of tick. Instructions, not cycles. Then, built with -DBENCH_HASH, the same
image runs the three runs of tests/c/test_params.c on the target and their command hashes must
be tests/c/params_expected.h's (the float32 specification's, bit for bit), else exit status 1.
With --arith q15 or q31: the fixed-point build on gains/robot_goal_<arith>* (the same ticks,
states in Q scales), its hashes against tests/c/params_q_expected.h (the host's bit-exact
reference). With --arith spline: the float32 build on gains/robot_goal_spline* (the spline
table with its spline columns, tools/params_tables.py --spline), its hashes against
tests/c/params_spline_expected.h. With --arith q15-spline or q31-spline: the fixed-point
build on gains/robot_goal_<arith>_spline* (the Q spline gain table with its fixed-point spline
columns, tools/params_tables.py --fixed), its hashes against tests/c/params_qspline_expected.h
(tests/c/params_q_reference.py --spline). The drone's hashes are tests/c/params_drone_expected.h's
(tests/c/params_reference.py --example drone_gates). Standard library only.
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
CALLERS = ("bench_plain", "bench_param")
EXAMPLES = ("robot_goal", "drone_gates")     # gains/<name>* with runtime parameters
SUFFIX = {"float32": "f32", "q15": "q15", "q31": "q31", "spline": "f32",
          "q15-spline": "q15", "q31-spline": "q31"}
SPLINE = ("spline", "q15-spline", "q31-spline")


def entries(arith: str) -> tuple[str, str]:
    return (f"stsp_step_{SUFFIX[arith]}", f"stsp_param_step_{SUFFIX[arith]}")


def table_name(example: str, arith: str) -> str:
    """gains/<name>.c of `example`'s table in `arith` (spline: float32 spline columns)."""
    return example if arith == "float32" else f"{example}_{arith.replace('-', '_')}"


def build(out: Path, arith: str = "float32", hashes: bool = False,
          example: str = "robot_goal") -> Path:
    elf = out / (f"hash_{example}_{arith}.elf" if hashes else f"bench_{example}_{arith}.elf")
    arm = ROOT / "tools" / "arm"
    name = table_name(example, arith)
    defs = {"float32": [], "spline": ["-DPARAMS_SPLINE"]}.get(
        arith, [f"-DSTSP_ARITH_{arith.split('-')[0].upper()}"])
    defs += ["-DPARAMS_SPLINE"] if arith.endswith("-spline") else []
    defs += ["-DBENCH_DRONE"] if example == "drone_gates" else []
    run(["arm-none-eabi-gcc", *FLAGS, *defs, *(["-DBENCH_HASH"] if hashes else []),
         f"-I{ROOT / 'firmware/include'}", f"-I{ROOT / 'firmware/src'}", f"-I{ROOT / 'gains'}",
         f"-I{ROOT / 'tests/c'}",
         *sorted(str(p) for p in (ROOT / "firmware/src").glob("*.c")),
         str(ROOT / f"gains/{name}.c"), str(ROOT / f"gains/{name}_params.c"),
         str(arm / "params_bench_main.c"), str(arm / "startup.c"), "--specs=rdimon.specs",
         "-T", str(arm / "mps2-an386.ld"), "-Wl,--gc-sections", "-o", str(elf)])
    return elf


def count(elf: Path, arith: str = "float32") -> list[dict]:
    syms = symbols(elf)
    ENTRIES = entries(arith)
    # A spline table's code is reached through its ops pointer (blx to a register, which
    # callees cannot follow): when linked, its tick and the parameters' law are roots too.
    roots = list(ENTRIES) + [n for n in syms if n.split(".")[0] in ("stsp_spline_step",
                                                                    "stsp_spline_param_law",
                                                                    "stsp_qspline_param_law")]
    funcs = sorted({f for e in roots for f in callees(elf, syms, e)})
    ranges = {n: syms[n] for n in funcs + list(CALLERS)}
    trace = elf.with_suffix(".trace")
    insns, out = trace_run(elf, ranges, trace)
    calls = [{"kind": int(m[0]), "tick": int(m[1]), "status": int(m[2])}
             for m in re.findall(r"call \d+ kind (\d) tick (\d+) status (-?\d+)", out)]
    counts = instructions_per_call(trace, insns, {syms[e][0] for e in ENTRIES},
                                   [ranges[c] for c in CALLERS])
    if len(counts) != len(calls):
        raise SystemExit(f"count: {len(counts)} calls traced, the bench reports {len(calls)}")
    for c, k in zip(calls, counts):
        c["insns"] = k
    return calls


def flash(out: Path, example: str, defs: tuple = ()) -> tuple[int, int]:
    """Bytes of const data of gains/<example>.c and gains/<example>_params.c for the M4F
    (compiled with `defs`: a fixed-point table's arithmetic)."""
    sizes = []
    for stem in (example, f"{example}_params"):
        obj = out / f"{stem}.o"
        run(["arm-none-eabi-gcc", *FLAGS, *defs, f"-I{ROOT / 'firmware/include'}",
             f"-I{ROOT / 'gains'}", "-c", str(ROOT / f"gains/{stem}.c"), "-o", str(obj)])
        sizes.append(sum(int(m) for m in re.findall(r"^\.(?:rodata|data)\S*\s+(\d+)",
                                                     run(["arm-none-eabi-size", "-A", str(obj)]),
                                                     re.M)))
    return sizes[0], sizes[1]


def check_hashes(out: Path, arith: str = "float32", example: str = "robot_goal") -> bool:
    """Runs A, B, C on the target against tests/c/params_expected.h (fixed point:
    tests/c/params_q_expected.h's section of `arith`; the drone: params_drone_expected.h);
    prints each."""
    elf = build(out, arith, hashes=True, example=example)
    got = dict(re.findall(r"hash ([ABC]) (0x[0-9A-F]{8})", run(
        ["timeout", "600", "qemu-system-arm", "-M", "mps2-an386", "-nographic", "-monitor",
         "none", "-semihosting-config", "enable=on,target=native", "-kernel", str(elf)])))
    if example == "drone_gates":
        text, what = (ROOT / "tests/c/params_drone_expected.h").read_text(), "specification"
    elif arith == "float32":
        text, what = (ROOT / "tests/c/params_expected.h").read_text(), "specification"
    elif arith == "spline":
        text, what = (ROOT / "tests/c/params_spline_expected.h").read_text(), "specification"
        text = text.replace("PSP_", "PAR_")
    elif arith in SPLINE:
        text, what = (ROOT / "tests/c/params_qspline_expected.h").read_text(), "host reference"
        text = text.split(f"defined(STSP_ARITH_{SUFFIX[arith].upper()})")[1].split("#e")[0]
    else:
        text, what = (ROOT / "tests/c/params_q_expected.h").read_text(), "host reference"
        text = text.split(f"defined(STSP_ARITH_{arith.upper()})")[1].split("#e")[0]
    want = dict(re.findall(r"#define PAR_HASH_([ABC]) (0x[0-9A-F]{8})u", text))
    for k in "ABC":
        print(f"run {k}: M4F 0x{int(got.get(k, '0'), 16):08X}, {what} {want[k]}"
              f" {'ok' if got.get(k) == want[k] else 'DIFFERS'}")
    return got == want


def report(out: Path, example: str, arith: str) -> bool:
    """Prints `example`'s bytes and instructions per kind of tick; True if its hashes on the
    target are the reference's."""
    calls = count(build(out, arith, example=example), arith)
    sw = max(c["tick"] for c in calls) - 1          # the first tick of stage 1
    kinds = {
        "tick 0 (latch of stage 0)": lambda c: c["tick"] == 0,
        "ordinary tick": lambda c: 0 < c["tick"] < 21 and c["status"] == 0,
        "skip to the tick before stage 1": lambda c: c["tick"] == sw - 1,
        f"first tick of stage 1 (tick {sw})": lambda c: c["tick"] == sw,
    }
    print(f"| {example} ({arith}), Cortex-M4F (QEMU) | stsp_step (median) | "
          f"stsp_param_step (median) |")
    print("|---|---|---|")
    for name, sel in kinds.items():
        med = [statistics.median([c["insns"] for c in calls if sel(c) and c["kind"] == k])
               for k in (0, 1)]
        print(f"| {name} | {med[0]:.0f} | {med[1]:.0f} |")
    if arith in ("float32", *SPLINE):
        name = table_name(example, arith)
        fixed = () if arith in ("float32", "spline") else \
            (f"-DSTSP_ARITH_{SUFFIX[arith].upper()}",)
        table, params = flash(out, name, fixed)
        print(f"\n{name}: table {table:,} B, parameters {params:,} B "
              f"(+{100 * params / table:.1f} %; gains/{name}.c, gains/{name}_params.c, "
              f"const data for the M4F)")
    print()
    return check_hashes(out, arith, example)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--build", type=Path, default=ROOT / "build" / "arm-params")
    ap.add_argument("--example", choices=("all", *EXAMPLES), default="all")
    ap.add_argument("--arith", choices=sorted(SUFFIX), default="float32")
    args = ap.parse_args()
    examples = EXAMPLES if args.example == "all" else (args.example,)
    if args.arith != "float32" and "drone_gates" in examples:
        if args.example == "drone_gates":
            ap.error(f"--arith {args.arith}: gains/ has float32 per-tick parameter tables "
                     f"only for drone_gates")
        examples = ("robot_goal",)
    args.build.mkdir(parents=True, exist_ok=True)
    ok = [report(args.build, ex, args.arith) for ex in examples]
    return 0 if all(ok) else 1


if __name__ == "__main__":
    sys.exit(main())
