#!/usr/bin/env python3
"""Report: instructions per controller tick of every shipped table each board runs, worst case
over the plan, against the board's tick period in core cycles.

    PYTHONPATH=host .venv/bin/python tools/arm/board_timing.py [--build-dir DIR] [--only NAME]

For each board of `stospline board` (stospline.board.project.BOARDS) and each table in gains/
of the board's arithmetic, the controller is compiled as the board's project compiles it
(arm-none-eabi-gcc for the board's core, -O2, ISO C99, -ffp-contract=off, FIXED_SHAPE: the
STSP_FIXED_NX/NU/N_LATCH of the table's header) into tools/arm/plan_main.c, which steps every
tick of the plan once, in order. QEMU runs it on mps2-an386 (the same Cortex-M4F core as the
netduinoplus2's STM32F405; instruction counts do not depend on the board's peripherals) and
count_instructions.py's trace_calls() counts the instructions of each stsp_step call from
QEMU's execution trace (-singlestep -d exec,nochain, checked against the disassembly).

Printed per table: the worst ordinary tick and the worst latch tick (a stage start that
latches, or the first tick) in instructions, and the tick period at the board's clock in
cycles (clock_hz / tick_hz). These are instructions, not cycles: QEMU has no Cortex-M timing
model, and on the core a floating-point operation, a load or a taken branch takes 1-3 cycles
(plus flash wait states beyond what the flash accelerator hides), so the column "x3" (three
cycles per instruction) is the share of the period a pessimistic estimate takes. One fixed
state (tools/arm/plan_main.c): a band table's stage-0 latch searches active sets for that
state only (its worst case over states is 3^rows candidates, not measured here). Exit status
0, or 1 when a worst tick at three cycles per instruction does not fit its period.
"""
from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools" / "arm"))
import count_instructions as ci  # noqa: E402

# The micro:bit's Cortex-M0 code runs on QEMU's mps2-an385 (a Cortex-M3, as for the M0+ in
# count_instructions.py): the ARMv6-M instructions are the same on an ARMv7-M core, so their
# count is, and the trace runs under the same semihosting start-up as the M4F's.
CPU_FLAGS = {**ci.CPU_FLAGS, "cortex-m0": ["-mcpu=cortex-m0", "-mthumb", "-mfloat-abi=soft"]}
MACHINE = {**ci.MACHINE, "cortex-m0": "mps2-an385"}
HEADER = re.compile(r"#define ([A-Z0-9_]+)_(NX|NU|N_LATCH|N_TICKS|TICK_HZ|ARITH_Q15|ARITH_Q31) "
                    r"([0-9]+)u?$")


def header(h: Path) -> dict:
    """The dimension macros of a generated header (<NAME>_NX ... _TICK_HZ, _ARITH_Q15/Q31)."""
    name = h.stem.upper()
    out = {}
    for line in h.read_text().splitlines():
        m = HEADER.match(line)
        if m and m.group(1) == name:
            out[m.group(2)] = int(m.group(3))
    return out


def arith_of(dims: dict) -> str:
    return "q15" if "ARITH_Q15" in dims else ("q31" if "ARITH_Q31" in dims else "float32")


def build_image(table_c: Path, dims: dict, cpu: str, out: Path) -> Path:
    name = table_c.stem
    up = name.upper()
    elf = out / f"plan_{name}.elf"
    fw = ROOT / "firmware"
    subprocess.run(
        ["arm-none-eabi-gcc", *CPU_FLAGS[cpu], "-std=c99", "-O2", "-ffp-contract=off",
         "-Wall", "-Wextra", "-Werror",
         f"-DSTSP_FIXED_NX={dims['NX']}u", f"-DSTSP_FIXED_NU={dims['NU']}u",
         f"-DSTSP_FIXED_N_LATCH={dims['N_LATCH']}u",
         *([f"-DSTSP_ARITH_{arith_of(dims).upper()}"] if arith_of(dims) != "float32" else []),
         f"-I{fw / 'include'}", f"-I{fw / 'src'}", f"-I{table_c.parent}",
         "-include", str(table_c.with_suffix(".h")), f"-DPLAN_TABLE={name}_table",
         f"-DPLAN_NX={up}_NX", f"-DPLAN_NU={up}_NU", f"-DPLAN_TICKS={up}_N_TICKS",
         str(ROOT / "tools" / "arm" / "plan_main.c"), str(table_c),
         *sorted(str(p) for p in (fw / "src").glob("*.c")),
         str(ROOT / "tools" / "arm" / "startup.c"), "--specs=nano.specs", "--specs=rdimon.specs",
         "-T", str(ROOT / "tools" / "arm" / "mps2-an386.ld"), "-Wl,--gc-sections",
         "-o", str(elf)], check=True)
    return elf


def main(argv: list[str] | None = None) -> int:
    sys.path.insert(0, str(ROOT / "host"))
    from stospline.board.project import BOARDS
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--build-dir", type=Path, default=None,
                    help="where the images and traces go (default: a temporary directory)")
    ap.add_argument("--only", default=None, help="one table of gains/ (its stem)")
    args = ap.parse_args(argv)
    tables = sorted(p for p in (ROOT / "gains").glob("*.c") if not p.stem.endswith("_params"))
    if args.only is not None:
        tables = [t for t in tables if t.stem == args.only]
        if not tables:
            print(f"board_timing: --only: no gains/{args.only}.c", file=sys.stderr)
            return 2
    worst_ok = True
    with tempfile.TemporaryDirectory() as tmp:
        out = args.build_dir or Path(tmp)
        out.mkdir(parents=True, exist_ok=True)
        for board in BOARDS.values():
            if board.cpu not in MACHINE:
                print(f"board_timing: no QEMU machine for {board.cpu}", file=sys.stderr)
                return 1
            print(f"{board.name} ({board.cpu}, {board.clock_hz / 1e6:g} MHz), {board.arith} "
                  f"tables; instructions per stsp_step, worst over the plan")
            print(f"  {'table':30} {'ticks':>6} {'Hz':>5} {'ordinary':>8} {'latch':>6} "
                  f"{'period':>9} {'x3':>6}")
            for table_c in tables:
                dims = header(table_c.with_suffix(".h"))
                if arith_of(dims) != board.arith:
                    continue
                elf = build_image(table_c, dims, board.cpu, out)
                calls, _, _ = ci.trace_calls(out, elf.name, MACHINE[board.cpu])
                (out / f"trace_{elf.stem}.log").unlink(missing_ok=True)
                if len(calls) != dims["N_TICKS"] or any(c["status"] < 0 for c in calls):
                    print(f"board_timing: {table_c.name}: {len(calls)} calls of "
                          f"{dims['N_TICKS']}, or an error status", file=sys.stderr)
                    return 1
                ordinary = max((c["insns"] for c in calls if not c["latch"]), default=0)
                latch = max((c["insns"] for c in calls if c["latch"]), default=0)
                period = board.clock_hz // dims["TICK_HZ"]
                share = 3 * max(ordinary, latch) / period
                worst_ok &= share <= 1.0
                print(f"  {table_c.stem:30} {dims['N_TICKS']:>6} {dims['TICK_HZ']:>5} "
                      f"{ordinary:>8} {latch:>6} {period:>9} {100 * share:>5.2f}%", flush=True)
    return 0 if worst_ok else 1


if __name__ == "__main__":
    sys.exit(main())
