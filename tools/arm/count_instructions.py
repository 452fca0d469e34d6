#!/usr/bin/env python3
"""Report: instructions per stsp_step call on Cortex-M4F under QEMU, and flash/RAM footprints.

Run through ``tools/arm/count_instructions.sh`` (which runs tools/setup.sh and builds first).
Standard library only.

Instruction counts. ``bench.elf`` (tools/arm/bench_main.c) steps the robot table through
latch and ordinary ticks of both stages. QEMU 7.2 runs it with ``-singlestep`` (one guest
instruction per translation block) and ``-d exec,nochain`` (one ``Trace`` line per executed
block, chaining off so none is skipped), restricted by ``-dfilter`` to the address ranges of
``stsp_step``, every function it calls (found from its ``bl`` instructions, transitively:
GCC turns the zeroing loop into a ``memset`` call) and the caller ``bench_step``. A call is the
run of lines from the entry of ``stsp_step`` up to the next line in ``bench_step``. The script
checks that every traced address is an instruction boundary of the disassembly and that the
trace holds one entry per call the bench reports. These are instructions, not cycles: QEMU
does not model Cortex-M timing (FP ops, loads and taken branches cost 1-3 cycles each on an M4).

Footprints. ``arm-none-eabi-size`` of the compiled objects (controller alone, controller +
robot tables) for both targets, plus a link of only what the API pulls in (``-nostdlib``,
``--gc-sections``, roots stsp_init/stsp_reset/stsp_step), which adds newlib's ``memset`` and,
on the soft-float M0+, libgcc's ``__aeabi_fadd``/``__aeabi_fmul``.
"""
from __future__ import annotations

import argparse
import re
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
CPU_FLAGS = {
    "cortex-m4": ["-mcpu=cortex-m4", "-mthumb", "-mfpu=fpv4-sp-d16", "-mfloat-abi=hard"],
    "cortex-m0plus": ["-mcpu=cortex-m0plus", "-mthumb", "-mfloat-abi=soft"],
}


# Instructions after which the next pc need not be the next address (branches, returns).
BRANCH = re.compile(r"(b|bl|blx|bx|cbz|cbnz|tbb|tbh)(\.[nw])?\b"
                    r"|b(eq|ne|cs|hs|cc|lo|mi|pl|vs|vc|hi|ls|ge|lt|gt|le)(\.[nw])?\b"
                    r"|(pop|ldm\w*)(\.[nw])?\s.*\bpc\b")


def run(cmd: list[str], **kw) -> str:
    return subprocess.run(cmd, check=True, capture_output=True, text=True, **kw).stdout


def symbols(elf: Path) -> dict[str, tuple[int, int]]:
    """name -> (address, size) of the sized function/object symbols (Thumb bit cleared)."""
    out = {}
    for line in run(["arm-none-eabi-nm", "-S", str(elf)]).splitlines():
        parts = line.split()
        if len(parts) == 4:
            out[parts[3]] = (int(parts[0], 16) & ~1, int(parts[1], 16))
    return out


def disassemble(elf: Path, start: int, size: int) -> dict[int, str]:
    """address -> instruction text for [start, start + size)."""
    text = run(["arm-none-eabi-objdump", "-d", "--no-show-raw-insn",
                f"--start-address={start:#x}", f"--stop-address={start + size:#x}", str(elf)])
    ins = {}
    for line in text.splitlines():
        m = re.match(r"\s+([0-9a-f]+):\s+(.*)", line)
        if m:
            ins[int(m.group(1), 16)] = m.group(2).strip()
    return ins


def callees(elf: Path, syms: dict, root: str) -> list[str]:
    """`root` and every function reachable from it through bl/blx (transitively)."""
    by_addr = {a: n for n, (a, _) in syms.items()}
    seen, todo = [], [root]
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.append(name)
        a, s = syms[name]
        for insn in disassemble(elf, a, s).values():
            m = re.match(r"blx?\s+([0-9a-f]+)\b", insn)
            if m:
                target = by_addr.get(int(m.group(1), 16))
                if target is None:
                    raise SystemExit(f"count: {name} calls an unknown address {m.group(1)}")
                todo.append(target)
    return seen


def trace_calls(build: Path, trace: Path) -> tuple[list[dict], list[str], dict]:
    elf = build / "bench.elf"
    syms = symbols(elf)
    funcs = callees(elf, syms, "stsp_step")
    ranges = {n: syms[n] for n in funcs + ["bench_step"]}
    insns: dict[int, str] = {}
    for n, (a, s) in ranges.items():
        insns.update(disassemble(elf, a, s))
    addrs = sorted(insns)
    following = dict(zip(addrs, addrs[1:]))
    dfilter = ",".join(f"{a:#x}+{s:#x}" for a, s in ranges.values())
    out = run(["timeout", "120", "qemu-system-arm", "-M", "mps2-an386", "-nographic",
               "-monitor", "none", "-semihosting-config", "enable=on,target=native",
               "-kernel", str(elf), "-singlestep", "-d", "exec,nochain", "-D", str(trace),
               "-dfilter", dfilter])
    calls = []
    for line in out.splitlines():
        m = re.match(r"call (\d+) tick (\d+) stage (\d+) latch (\d) status (-?\d+)", line)
        if m:
            calls.append({"tick": int(m.group(2)), "stage": int(m.group(3)),
                          "latch": m.group(4) == "1", "status": int(m.group(5))})
    entry = syms["stsp_step"][0]
    in_caller = lambda pc: ranges["bench_step"][0] <= pc < sum(ranges["bench_step"])  # noqa: E731
    counts, current, lines, prev = [], None, 0, None
    fmul = re.compile(r"v(n?mul|mla|mls|fma|fms|fnma|fnms)\.f32")
    pat = re.compile(r"Trace \d+: 0x[0-9a-f]+ \[[0-9a-f]+/([0-9a-f]+)/")
    with trace.open() as fh:
        for line in fh:
            m = pat.match(line)
            if not m:
                continue
            lines += 1
            pc = int(m.group(1), 16)
            if pc not in insns:
                raise SystemExit(f"count: traced pc {pc:#x} is not an instruction boundary")
            # One line per instruction: control leaves the sequential order only after a branch.
            if prev is not None and pc != following.get(prev) and not BRANCH.match(insns[prev]):
                raise SystemExit(f"count: {prev:#x} ({insns[prev]}) -> {pc:#x}: an instruction "
                                 "ran without its own trace line")
            prev = pc
            if pc == entry:
                if current is not None:
                    raise SystemExit("count: stsp_step re-entered before returning")
                current = [0, 0]
            if in_caller(pc):
                if current is not None:
                    counts.append(current)
                    current = None
            elif current is not None:
                current[0] += 1
                current[1] += 1 if fmul.match(insns[pc]) else 0
    if len(counts) != len(calls):
        raise SystemExit(f"count: {len(counts)} calls in the trace, bench reports {len(calls)}")
    for c, (n, muls) in zip(calls, counts):
        c["insns"], c["fmuls"] = n, muls
    m = re.search(r"sizeof\(stsp_ctrl_t\) (\d+)", out)
    dims = re.search(r"table nx (\d+) nu (\d+) n_latch (\d+) stage_np([ \d]+)", out)
    return calls, funcs, {"trace_lines": lines, "dfilter": dfilter,
                          "sizeof_ctrl": int(m.group(1)) if m else None,
                          "nx": int(dims.group(1)), "nu": int(dims.group(2)),
                          "n_latch": int(dims.group(3)),
                          "stage_np": [int(v) for v in dims.group(4).split()]}


def size_rows(build: Path, cpu: str) -> list[tuple[str, int, int, int]]:
    """(what, text, data, bss) for compiled objects and API-only links."""
    rows = []
    ctl = build / "libstsp.a"
    tables = build / "libstsp_gains_robot_corridor.a"

    def totals(files):
        last = run(["arm-none-eabi-size", "-t", *map(str, files)]).strip().splitlines()[-1]
        t, d, b = (int(v) for v in last.split()[:3])
        return t, d, b

    rows.append(("controller objects (libstsp.a)", *totals([ctl])))
    rows.append(("controller + robot tables objects", *totals([ctl, tables])))
    roots = ["stsp_init", "stsp_reset", "stsp_step"]
    for what, extra_roots, libs in (("controller linked (API roots)", [], [ctl]),
                                    ("controller + tables linked", ["robot_corridor_table"],
                                     [tables, ctl])):
        elf = build / f"footprint_{'tables' if extra_roots else 'ctl'}.elf"
        cmd = (["arm-none-eabi-gcc", *CPU_FLAGS[cpu], "-nostdlib", "-nostartfiles",
                "-Wl,--gc-sections", "-Wl,-e,stsp_step", "-o", str(elf)]
               + [f"-Wl,-u,{r}" for r in roots + extra_roots] + [str(p) for p in libs]
               + ["-lc", "-lgcc"])
        run(cmd)
        size_line = run(["arm-none-eabi-size", str(elf)]).splitlines()[1]
        t, d, b = (int(v) for v in size_line.split()[:3])
        rows.append((what, t, d, b))
        if not extra_roots:
            lib = {n: sz for n, (_, sz) in symbols(elf).items()
                   if sz and not n.startswith(("stsp_", "robot_corridor_"))}
            rows.append(("  pulled from newlib/libgcc: "
                         + ", ".join(f"{n} {sz} B" for n, sz in sorted(lib.items())), -1, -1, -1))
    return rows


def stack_usage(build: Path) -> dict[str, int]:
    out = {}
    for su in build.glob("CMakeFiles/stsp.dir/**/*.su"):
        for line in su.read_text().splitlines():
            parts = line.split("\t")
            out[parts[0].rsplit(":", 1)[-1]] = int(parts[1])
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--m4", type=Path, default=ROOT / "build" / "arm")
    ap.add_argument("--m0plus", type=Path, default=ROOT / "build" / "arm-m0plus")
    args = ap.parse_args()

    calls, funcs, info = trace_calls(args.m4, args.m4 / "trace.log")
    nx, nu, np_of_stage = info["nx"], info["nu"], info["stage_np"]
    print("== Instructions per stsp_step call, Cortex-M4F (QEMU 7.2 mps2-an386, -singlestep "
          "-d exec,nochain)")
    print(f"   counted functions: {', '.join(funcs)}; {len(calls)} calls, "
          f"{info['trace_lines']} trace lines; -dfilter {info['dfilter']}")
    print(f"   {'ticks':26s} {'calls':>5s} {'median':>6s} {'max':>5s} {'min':>5s} "
          f"{'MACs':>5s} {'median/MAC':>10s} {'FP muls run':>11s}")

    def row(label, sel, macs):
        n = [c["insns"] for c in sel]
        med = statistics.median(n)
        ratio = f"{med / macs:10.1f}" if macs else f"{'-':>10s}"
        muls = sorted({c["fmuls"] for c in sel})
        mul_text = "/".join(str(m) for m in muls)
        print(f"   {label:26s} {len(n):5d} {med:6.0f} {max(n):5d} {min(n):5d} "
              f"{macs if macs else '-':>5} {ratio} {mul_text:>11s}")

    for latch in (False, True):
        kind = "latch" if latch else "ordinary"
        for s in range(len(np_of_stage)):
            p = np_of_stage[s]
            macs = nu * nx + nu * p + (p * nx if latch else 0)
            sel = [c for c in calls if c["latch"] == latch and c["stage"] == s]
            row(f"{kind}, stage {s} (np={p})", sel, macs)
        row(f"{kind}, both stages", [c for c in calls if c["latch"] == latch], 0)
    skipped = [c["insns"] for c in calls if c["status"] == 1]
    print("   MACs = nu*nx + nu*np (+ np*nx on a latch tick): multiply-adds the law needs;")
    print("   FP muls run = vmul/vmla/vfma instructions the firmware executed in those calls.")
    print(f"   Ordinary stage 0 includes {len(skipped)} calls reached by a skip (status WARN_TICK_"
          f"SKIPPED), {min(skipped)}..{max(skipped)} instructions.")

    print("\n== Flash / RAM (arm-none-eabi-size; flash = text + data, static RAM = data + bss)")
    su_m4, su_m0 = stack_usage(args.m4), stack_usage(args.m0plus)
    for cpu, build, su in (("cortex-m4 (FPv4-SP, hard float)", args.m4, su_m4),
                           ("cortex-m0plus (soft float)", args.m0plus, su_m0)):
        print(f"   {cpu}:")
        for what, t, d, b in size_rows(build, "cortex-m4" if "m4" in cpu else "cortex-m0plus"):
            if t < 0:
                print(f"     {what}")
                continue
            print(f"     {what:36s} flash {t + d:7d} B  static RAM {d + b:4d} B  "
                  f"(text {t}, data {d}, bss {b})")
        print(f"     stack (-fstack-usage, own frame): stsp_step {su.get('stsp_step')} B, "
              f"stsp_init {su.get('stsp_init')} B + stsp_table_crc32 "
              f"{su.get('stsp_table_crc32')} B + stsp_crc32_f32s {su.get('stsp_crc32_f32s')} B")
    print(f"   per instance: sizeof(stsp_ctrl_t) = {info['sizeof_ctrl']} B on the M4F "
          "(caller-owned, STSP_MAX_LATCH = 16; same AAPCS layout on the M0+)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
