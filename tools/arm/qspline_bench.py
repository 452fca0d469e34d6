#!/usr/bin/env python3
"""Report: the fixed-point spline gains' evaluation (firmware/src/stsp_qspline.c) on Cortex-M
under QEMU, for the robot's Q15 and Q31 spline tables (`pipeline.fixed_point_spline`, default
tolerance): bit for bit with the host, and instructions per tick.

    PYTHONPATH=host .venv/bin/python tools/arm/qspline_bench.py [--out build/arm-qspline]

For each core (Cortex-M4F: QEMU mps2-an386; Cortex-M0+ code on mps2-an385, a Cortex-M3, as
tools/arm/run_replay.sh) and arithmetic, arm-none-eabi-gcc -O2 builds tools/arm/qspline_main.c
with stsp_qspline.c, the table's arrays (generated here) and tools/arm/startup.c:

* ``check``: every gain of every tick (6000 ticks), hashed (FNV-1a of the int32 values), against
  the hash of `evaluate_q`'s gains: "bit-exact" when equal (QEMU's exit status 0);
* ``count``: the first 100 ticks of each stage under ``-singlestep -d exec,nochain`` restricted
  to ``stsp_qspline_gains`` and its callees (tools/arm/count_instructions.py's method: one trace
  line per executed instruction; the callees include ``memset``, which zeroes the row, and on
  the M0+ libgcc's 64-bit multiply); instructions per call, split at the entries of
  ``stsp_qspline_gains`` (lines before the first entry, the start-up's ``memset``, dropped):
  median, min and max per stage. Instructions, not cycles.
"""
from __future__ import annotations

import argparse
import re
import statistics
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools" / "arm"))
from count_instructions import CPU_FLAGS, api_symbol, callees, symbols  # noqa: E402

MACHINE = {"cortex-m4": "mps2-an386", "cortex-m0plus": "mps2-an385"}
COUNT_TICKS = 100


def _fnv(gains: np.ndarray) -> int:
    h = 2166136261
    for b in np.ascontiguousarray(gains, dtype="<i4").tobytes():
        h = ((h ^ b) * 16777619) & 0xFFFFFFFF
    return h


def _c_array(ctype: str, name: str, values) -> str:
    body = ", ".join(str(int(v)) for v in np.asarray(values).ravel())
    return f"static const {ctype} {name}[] = {{{body}}};\n"


def table_source(ft) -> tuple[str, int]:
    """The C arrays of `ft.spline` and the expected hash of every tick's gains."""
    sp = ft.spline
    scalar = "int16_t" if ft.arith == "q15" else "int32_t"
    nz = sp.nx + 1 + sp.n_latch
    G = np.concatenate([ft.K, ft.k0[:, :, None], ft.L], axis=2).astype(np.int64)
    src = ['#include "stsp_qspline.h"\n',
           _c_array("uint8_t", "span_log2", sp.span_log2),
           _c_array("uint16_t", "row_start", sp.row_start),
           _c_array("uint8_t", "col", sp.col), _c_array("uint8_t", "shift", sp.shift),
           _c_array("uint32_t", "coef_start", sp.coef_start),
           _c_array(scalar, "coef", sp.coef),
           f"const uint32_t qspline_stage_start[] = {{"
           f"{', '.join(f'{int(v)}u' for v in ft.stage_start)}}};\n",
           f"const uint32_t qspline_n_stages = {sp.n_stages}u;\n",
           f"const uint32_t qspline_nu = {sp.nu}u;\n",
           f"const uint32_t qspline_nz = {nz}u;\n",
           f"const uint32_t qspline_expected_hash = {_fnv(G):#010x}u;\n",
           f"const stsp_qspline_t qspline_robot = {{{sp.n_entries}u, {sp.coef.size}u, span_log2, "
           f"row_start, col, shift, coef_start, coef, NULL}};\n"]
    return "".join(src), _fnv(G)


def build(out: Path, cpu: str, arith: str, data: Path, count: bool) -> Path:
    elf = out / f"qspline_{cpu}_{arith}{'_count' if count else ''}.elf"
    fw = ROOT / "firmware"
    cmd = (["arm-none-eabi-gcc", *CPU_FLAGS[cpu], "-std=c99", "-O2", "-ffunction-sections",
            "-fdata-sections", "-Wall", "-Wextra", "-Werror", f"-DSTSP_ARITH_{arith.upper()}",
            f"-I{fw / 'include'}", f"-I{fw / 'src'}"]
           + ([f"-DBENCH_COUNT={COUNT_TICKS}u"] if count else [])
           + [str(ROOT / "tools/arm/qspline_main.c"), str(fw / "src/stsp_qspline.c"), str(data),
              str(ROOT / "tools/arm/startup.c"), "--specs=rdimon.specs",
              "-T", str(ROOT / "tools/arm/mps2-an386.ld"), "-Wl,--gc-sections", "-o", str(elf)])
    subprocess.run(cmd, check=True)
    return elf


def qemu(elf: Path, cpu: str, extra=()) -> subprocess.CompletedProcess:
    return subprocess.run(["timeout", "600", "qemu-system-arm", "-M", MACHINE[cpu], "-nographic",
                           "-monitor", "none", "-semihosting-config", "enable=on,target=native",
                           "-kernel", str(elf), *extra], capture_output=True, text=True)


def count(elf: Path, cpu: str, out: Path, stage_calls: list[int]) -> list[list[int]]:
    syms = symbols(elf)
    gains = api_symbol(syms, "stsp_qspline_gains")   # stsp_qspline_gains_q15 or _q31
    funcs = callees(elf, syms, gains)
    ranges = {n: syms[n] for n in funcs}
    trace = out / (elf.stem + ".trace")
    dfilter = ",".join(f"{a:#x}+{s:#x}" for a, s in ranges.values())
    run = qemu(elf, cpu, ["-singlestep", "-d", "exec,nochain", "-D", str(trace),
                          "-dfilter", dfilter])
    if run.returncode != 0:
        raise SystemExit(f"qspline_bench: {elf.name} failed: {run.stdout}{run.stderr}")
    entry = syms[gains][0]
    per_call, lines = [], None
    for line in trace.read_text().splitlines():
        m = re.search(r"\[[0-9a-f]+/([0-9a-f]+)/", line)
        if not m:
            continue
        pc = int(m.group(1), 16)
        if pc == entry:
            if lines is not None:
                per_call.append(lines)
            lines = 0
        if lines is not None:      # before the first call: start-up code (memset of .bss)
            lines += 1
    per_call.append(lines)
    trace.unlink()
    if len(per_call) != sum(stage_calls) + 1:
        raise SystemExit(f"qspline_bench: {len(per_call)} calls traced, "
                         f"{sum(stage_calls) + 1} made")
    per_call.pop()                 # the sentinel (qspline_main.c)
    split, k = [], 0
    for c in stage_calls:
        split.append(per_call[k:k + c])
        k += c
    return split


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(ROOT / "build" / "arm-qspline"))
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    import stospline
    from stospline.pipeline import fixed_point_spline
    robot = stospline.load_problem(str(ROOT / "examples/robot_corridor.toml"))
    d = stospline.design_problem(robot, table="spline")
    print("| core | arith | entries per stage | bit-exact (6000 ticks) | instructions per tick, "
          "median [min, max] per stage | text B of stsp_qspline.o |")
    print("|---|---|---|---|---|---|")
    for arith in ("q15", "q31"):
        ft, _ = fixed_point_spline(d, arith)
        src, expected = table_source(ft)
        data = out / f"qspline_data_{arith}.c"
        data.write_text(src)
        sp, start = ft.spline, ft.stage_start.astype(int)
        entries = [int(sp.row_start[(s + 1) * sp.nu] - sp.row_start[s * sp.nu])
                   for s in range(sp.n_stages)]
        stage_calls = [min(COUNT_TICKS, int(start[s + 1] - start[s]))
                       for s in range(sp.n_stages)]
        for cpu in ("cortex-m4", "cortex-m0plus"):
            run = qemu(build(out, cpu, arith, data, False), cpu)
            exact = run.returncode == 0 and f"hash {expected:08x}" in run.stdout
            counts = count(build(out, cpu, arith, data, True), cpu, out, stage_calls)
            obj = out / "stsp_qspline.o"
            subprocess.run(["arm-none-eabi-gcc", *CPU_FLAGS[cpu], "-std=c99", "-O2",
                            f"-DSTSP_ARITH_{arith.upper()}", f"-I{ROOT / 'firmware/include'}",
                            f"-I{ROOT / 'firmware/src'}", "-c",
                            str(ROOT / "firmware/src/stsp_qspline.c"), "-o", str(obj)],
                           check=True)
            size = subprocess.run(["arm-none-eabi-size", str(obj)],
                                  check=True, capture_output=True, text=True).stdout
            text_b = int(size.splitlines()[1].split()[0])
            per_stage = "; ".join(f"{int(statistics.median(c))} [{min(c)}, {max(c)}]"
                                  for c in counts)
            verdict = "yes" if exact else "NO: " + run.stdout.strip()
            print(f"| {cpu} | {arith} | {entries} | {verdict} | {per_stage} | {text_b} |",
                  flush=True)


if __name__ == "__main__":
    main()
