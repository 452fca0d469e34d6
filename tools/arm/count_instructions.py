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
from typing import Iterator

ROOT = Path(__file__).resolve().parents[2]
CPU_FLAGS = {
    "cortex-m4": ["-mcpu=cortex-m4", "-mthumb", "-mfpu=fpv4-sp-d16", "-mfloat-abi=hard"],
    "cortex-m0plus": ["-mcpu=cortex-m0plus", "-mthumb", "-mfloat-abi=soft"],
}


# Instructions after which the next pc need not be the next address (branches, returns).
BRANCH = re.compile(r"(b|bl|blx|bx|cbz|cbnz|tbb|tbh)(\.[nw])?\b"
                    r"|b(eq|ne|cs|hs|cc|lo|mi|pl|vs|vc|hi|ls|ge|lt|gt|le)(\.[nw])?\b"
                    r"|(pop|ldm\w*)(\.[nw])?\s.*\bpc\b"
                    r"|(mov|add)(\.[nw])?\s+pc\b")  # libgcc's soft-float jump tables (M0+)


def run(cmd: list[str], **kw) -> str:
    return subprocess.run(cmd, check=True, capture_output=True, text=True, **kw).stdout


def symbols(elf: Path) -> dict[str, tuple[int, int]]:
    """name -> (address, size) of the sized function/object symbols (Thumb bit cleared). A
    static function defined in two objects (stsp_controller.c and stsp_spline.c share private
    headers) appears twice: the second and later as name@address."""
    out = {}
    for line in run(["arm-none-eabi-nm", "-S", str(elf)]).splitlines():
        parts = line.split()
        if len(parts) == 4:
            addr, name = int(parts[0], 16) & ~1, parts[3]
            if name in out and out[name][0] != addr:
                name = f"{name}@{addr:x}"
            out[name] = (addr, int(parts[1], 16))
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
            if m and a <= int(m.group(1), 16) < a + s:
                continue  # ARMv6-M: GCC uses bl as a far jump inside a large function
            if m:
                target = by_addr.get(int(m.group(1), 16))
                if target is None:
                    raise SystemExit(f"count: {name} calls an unknown address {m.group(1)}")
                todo.append(target)
                continue
            # Tail calls: a plain branch to the first instruction of another function.
            m = re.match(r"b(\.[nw])?\s+([0-9a-f]+)\b", insn)
            if m:
                dest = int(m.group(2), 16)
                if not a <= dest < a + s and dest in by_addr:
                    todo.append(by_addr[dest])
    return seen


def dfilter(ranges: dict[str, tuple[int, int]]) -> str:
    """QEMU's -dfilter of the address `ranges` (name -> (start, size))."""
    return ",".join(f"{a:#x}+{s:#x}" for a, s in ranges.values())


def trace_run(elf: Path, ranges: dict[str, tuple[int, int]], trace: Path,
              machine: str = "mps2-an386", timeout: int = 600) -> tuple[dict[int, str], str]:
    """Run `elf` in QEMU one instruction a translation block (-singlestep, -d exec,nochain),
    tracing only the address `ranges` (name -> (start, size)) into `trace`: returns the
    disassembly of the ranges (address -> instruction) and the image's output."""
    insns: dict[int, str] = {}
    for a, s in ranges.values():
        insns.update(disassemble(elf, a, s))
    out = run(["timeout", str(timeout), "qemu-system-arm", "-M", machine, "-nographic",
               "-monitor", "none", "-semihosting-config", "enable=on,target=native",
               "-kernel", str(elf), "-singlestep", "-d", "exec,nochain", "-D", str(trace),
               "-dfilter", dfilter(ranges)])
    return insns, out


def traced_pcs(trace: Path, insns: dict[int, str]) -> Iterator[int]:
    """The program counters of `trace` (`trace_run`) in order, each checked: an instruction
    boundary of the disassembly, and one line per instruction (control leaves the sequential
    order only after a branch)."""
    following = dict(zip(sorted(insns), sorted(insns)[1:]))
    pat = re.compile(r"Trace \d+: 0x[0-9a-f]+ \[[0-9a-f]+/([0-9a-f]+)/")
    prev = None
    with trace.open() as fh:
        for line in fh:
            m = pat.match(line)
            if not m:
                continue
            pc = int(m.group(1), 16)
            if pc not in insns:
                raise SystemExit(f"count: traced pc {pc:#x} is not an instruction boundary")
            if prev is not None and pc != following.get(prev) and not BRANCH.match(insns[prev]):
                raise SystemExit(f"count: {prev:#x} ({insns[prev]}) -> {pc:#x}: an instruction "
                                 "ran without its own trace line")
            prev = pc
            yield pc



def instructions_per_call(trace: Path, insns: dict[int, str], entries: set[int],
                          callers: list[tuple[int, int]]) -> list[int]:
    """Instructions of each call in `trace`: from an address of `entries` (a function's first
    instruction) until control is back in one of the `callers` (start, size)."""
    counts, current = [], None
    for pc in traced_pcs(trace, insns):
        if pc in entries and current is None:
            current = 0
        if any(lo <= pc < lo + n for lo, n in callers):
            if current is not None:
                counts.append(current)
                current = None
        elif current is not None:
            current += 1
    return counts

# The suffix of the controller's external symbols (STSP_NAME: stsp_step_f32, stsp_step_q15, ...)
# per variant suffix of VARIANTS.
API_SUFFIX = {"": "_f32", "_q15": "_q15", "_q31": "_q31"}


def api_symbol(syms: dict, base: str) -> str:
    """The image's controller symbol `base` (one arithmetic per image: stsp_step_f32, ...)."""
    names = [base + s for s in API_SUFFIX.values() if base + s in syms]
    if len(names) != 1:
        raise SystemExit(f"count: expected one of {base}_f32/_q15/_q31, found {names}")
    return names[0]


def trace_calls(build: Path, image: str, machine: str = "mps2-an386"
                ) -> tuple[list[dict], list[str], dict]:
    elf = build / image
    trace = build / f"trace_{Path(image).stem}.log"
    syms = symbols(elf)
    step = api_symbol(syms, "stsp_step")
    funcs = callees(elf, syms, step)
    # A spline table's tick is called through the table's ops pointer (blx to a register, which
    # the scan above cannot follow): when linked, its code is a root of its own.
    spline = [n for n in syms if n.split(".")[0] == "stsp_spline_step"]
    for root in spline:
        funcs += [f for f in callees(elf, syms, root) if f not in funcs]
    ranges = {n: syms[n] for n in funcs + ["bench_step"]}
    insns, out = trace_run(elf, ranges, trace, machine, timeout=300)
    calls = []
    for line in out.splitlines():
        m = re.match(r"call (\d+) table (\d) tick (\d+) stage (\d+) latch (\d) status (-?\d+)"
                     r"(?: span (\d))?", line)
        if m:
            calls.append({"table": int(m.group(2)), "tick": int(m.group(3)),
                          "stage": int(m.group(4)), "latch": m.group(5) == "1",
                          "status": int(m.group(6)), "span": m.group(7) == "1"})
    entry = syms[step][0]
    in_caller = lambda pc: ranges["bench_step"][0] <= pc < sum(ranges["bench_step"])  # noqa: E731
    counts, current, lines = [], None, 0
    # Multiplies: FP (vmul/vmla/vnmla/vfma...) and integer (mul/mla/mls, smull/smlal, smulxy/smlaxy).
    fmul = re.compile(r"(v(n?mul|n?mla|n?mls|fma|fms|fnma|fnms)\.f32|muls?|mla|mls|[su]mull|[su]mlal"
                      r"|smla[bt][bt]|smul[bt][bt]|smlaw[bt]|smulw[bt])(\.[nw])?\b")
    for pc in traced_pcs(trace, insns):
        lines += 1
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
    dims = re.search(r"table nx (\d+) nu (\d+) n_latch (\d+) stage_n_latch([ \d]+)", out)
    return calls, funcs, {"trace_lines": lines, "dfilter": dfilter(ranges),
                          "sizeof_ctrl": int(m.group(1)) if m else None,
                          "nx": int(dims.group(1)), "nu": int(dims.group(2)),
                          "n_latch": int(dims.group(3)),
                          "stage_n_latch": [int(v) for v in dims.group(4).split()]}


def size_rows(build: Path, cpu: str, controller: str, sfx: str = ""
              ) -> list[tuple[str, int, int, int]]:
    """(what, text, data, bss) for compiled objects and API-only links of one controller
    library (libstsp_<arith>.a or libstsp_fixed_robot_corridor<sfx>.a) with the robot tables of
    the same variant (sfx "", "_q15", "_q31")."""
    rows = []
    ctl = build / controller
    tables = build / f"libstsp_gains_robot_corridor{sfx}.a"

    def totals(files):
        """text, data, bss summed over the controller's objects (stsp_controller, stsp_table,
        stsp_crc32, stsp_qconv:
        the libraries also hold other firmware modules, e.g. stsp_bandqp, which the
        controller does not use) and every object of the other archives."""
        t = d = b = 0
        for line in run(["arm-none-eabi-size", *map(str, files)]).strip().splitlines()[1:]:
            parts = line.split()
            obj = parts[5] if len(parts) > 5 else ""
            if f"ex {ctl}" in line and not obj.startswith(("stsp_controller.", "stsp_table.",
                                                          "stsp_crc32.", "stsp_qconv.")):
                continue
            t, d, b = t + int(parts[0]), d + int(parts[1]), b + int(parts[2])
        return t, d, b

    rows.append(("controller objects (stsp_controller, stsp_table, stsp_crc32, stsp_qconv)",
                 *totals([ctl])))
    rows.append(("controller + robot tables objects", *totals([ctl, tables])))
    roots = [f"stsp_{f}{API_SUFFIX[sfx]}" for f in ("init", "reset", "step")]
    links = [("controller linked (API roots)", [], [ctl]),
             ("controller + tables linked", [f"robot_corridor{sfx}_table"], [tables, ctl])]
    if not sfx:
        # float32: also the spline table of the robot's shape (tools/arm/spline_bench_table.c).
        links.append(("controller + spline bench table linked", ["spline_bench_table"],
                      [build / "libstsp_spline_bench_table.a", ctl]))
    else:
        # Q15/Q31: also the robot's spline table of that arithmetic (and the spline code it links).
        links.append(("controller + spline tables linked",
                      [f"robot_corridor{sfx}_spline_table"],
                      [build / f"libstsp_gains_robot_corridor{sfx}_spline.a", ctl]))
    for what, extra_roots, libs in links:
        kind = ("spline" if "spline_bench_table" in extra_roots else
                "qspline" if any(r.endswith("_spline_table") for r in extra_roots) else
                "tables" if extra_roots else "ctl")
        elf = build / f"footprint_{Path(controller).stem}_{kind}.elf"
        cmd = (["arm-none-eabi-gcc", *CPU_FLAGS[cpu], "-nostdlib", "-nostartfiles",
                "-Wl,--gc-sections", f"-Wl,-e,stsp_step{API_SUFFIX[sfx]}", "-o", str(elf)]
               + [f"-Wl,-u,{r}" for r in roots + extra_roots] + [str(p) for p in libs]
               + ["-lc", "-lgcc"])
        run(cmd)
        size_line = run(["arm-none-eabi-size", str(elf)]).splitlines()[1]
        t, d, b = (int(v) for v in size_line.split()[:3])
        rows.append((what, t, d, b))
        if not extra_roots and not sfx:
            # A program with a band table links the band solver (stsp_bandqp_t.solve_f32): here
            # forced by --undefined=stsp_bandqp_solve.
            band_elf = elf.with_name(elf.stem + "_band.elf")
            band_cmd = [str(band_elf) if c == str(elf) else c for c in cmd]
            band_cmd.insert(band_cmd.index(str(libs[0])), "-Wl,--undefined=stsp_bandqp_solve")
            run(band_cmd)
            size_line = run(["arm-none-eabi-size", str(band_elf)]).splitlines()[1]
            bt, bd, bb = (int(v) for v in size_line.split()[:3])
            rows.append(("controller linked with the band solver (a band table)", bt, bd, bb))
        if not extra_roots:
            lib = {n: sz for n, (_, sz) in symbols(elf).items()
                   if sz and not n.startswith(("stsp_", "robot_corridor"))}
            rows.append(("  pulled from newlib/libgcc: "
                         + (", ".join(f"{n} {sz} B" for n, sz in sorted(lib.items())) or "none"),
                         -1, -1, -1))
    return rows


def stack_usage(build: Path, target: str) -> dict[str, int]:
    out = {}
    for su in build.glob(f"CMakeFiles/{target}.dir/**/*.su"):
        for line in su.read_text().splitlines():
            parts = line.split("\t")
            out[parts[0].rsplit(":", 1)[-1]] = int(parts[1])
    return out


TABLES = {0: "no limits", 1: "limits +-1000 (inactive)", 2: "limits +-0.5 (clamping)"}
# (cpu, image, what): float32 on the M4F only; Q15/Q31 on both. The cortex-m0plus code runs on
# QEMU's mps2-an385 (a Cortex-M3: QEMU has no M0+ board; ARMv6-M code runs unchanged on it, and
# every instruction counted is an ARMv6-M one).
VARIANTS = (("", "float32"), ("_q15", "Q15"), ("_q31", "Q31"))
MACHINE = {"cortex-m4": "mps2-an386", "cortex-m0plus": "mps2-an385"}


def images(cpu: str):
    for sfx, arith in VARIANTS:
        if cpu != "cortex-m4" and not sfx:
            continue
        yield (f"bench{sfx}.elf", f"{arith}, generic dimensions (libstsp_{arith.lower()}.a)")
        yield (f"bench_fixed{sfx}.elf",
               f"{arith}, STSP_FIXED 4/2/4 (libstsp_fixed_robot_corridor{sfx}.a)")
    # The robot's Q15/Q31 spline tables (gains/robot_corridor_<arith>_spline.c).
    for sfx, arith in VARIANTS:
        if not sfx:
            continue
        yield (f"bench{sfx}_spline.elf", f"{arith} spline table (gains/robot_corridor{sfx}_spline.c), "
               f"generic dimensions (libstsp_{arith.lower()}.a)")
        yield (f"bench{sfx}_spline_fixed.elf", f"{arith} spline table "
               f"(gains/robot_corridor{sfx}_spline.c), STSP_FIXED 4/2/4 "
               f"(libstsp_fixed_robot_corridor{sfx}_spline.a)")
    # The spline table of tools/arm/spline_bench_table.c (float32; soft float on the M0+).
    yield ("bench_spline.elf", "float32 spline table (tools/arm/spline_bench_table.c), "
           "generic dimensions (libstsp_float32.a)")
    yield ("bench_spline_fixed.elf", "float32 spline table (tools/arm/spline_bench_table.c), "
           "STSP_FIXED 4/2/4 (libstsp_fixed_robot_corridor.a)")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--m4", type=Path, default=ROOT / "build" / "arm-m4f")
    ap.add_argument("--m0plus", type=Path, default=ROOT / "build" / "arm-m0plus")
    ap.add_argument("--json", type=Path, help="also write the figures as JSON here")
    ap.add_argument("--only", default="", help="comma-separated image names (default: all)")
    args = ap.parse_args()
    report: dict = {"instructions": {}, "sizes": {}}
    builds = {"cortex-m4": args.m4, "cortex-m0plus": args.m0plus}
    only = set(filter(None, args.only.split(",")))

    for cpu, build in builds.items():
        for image, variant in images(cpu):
            if only and image not in only:
                continue
            calls, funcs, info = trace_calls(build, image, MACHINE[cpu])
            nx, nu, np_of_stage, nl = info["nx"], info["nu"], info["stage_n_latch"], info["n_latch"]
            where = ("Cortex-M4F, QEMU mps2-an386" if cpu == "cortex-m4" else
                     "Cortex-M0+ code (-mcpu=cortex-m0plus) on QEMU mps2-an385 (Cortex-M3)")
            print(f"== Instructions per stsp_step call, {where}, {variant}")
            print(f"   -singlestep -d exec,nochain; {image}; counted functions: "
                  f"{', '.join(funcs)}; {len(calls)} calls, {info['trace_lines']} trace lines")
            print(f"   {'table':26s} {'ticks':20s} {'calls':>5s} {'median':>6s} {'max':>5s} "
                  f"{'min':>5s} {'MACs':>5s} {'median/MAC':>10s} {'muls run':>9s}")
            rows = report["instructions"].setdefault(f"{cpu}/{image}", [])

            def row(tlabel, label, sel, macs):
                n = [c["insns"] for c in sel]
                med = statistics.median(n)
                ratio = f"{med / macs:10.1f}" if macs else f"{'-':>10s}"
                muls = sorted({c["fmuls"] for c in sel})
                mul_text = "/".join(str(m) for m in muls)
                print(f"   {tlabel:26s} {label:20s} {len(n):5d} {med:6.0f} {max(n):5d} "
                      f"{min(n):5d} {macs if macs else '-':>5} {ratio} {mul_text:>9s}")
                rows.append({"table": tlabel, "ticks": label, "calls": len(n), "median": med,
                             "max": max(n), "min": min(n), "macs": macs,
                             "statuses": sorted({c["status"] for c in sel})})

            spline = image.startswith("bench_spline")          # float32: spans cached
            qspline = "spline" in image and not spline          # Q15/Q31: every tick alike
            for tab, tlabel in TABLES.items():
                for latch in (False, True):
                    kind = "latch" if latch else "ordinary"
                    for st in range(len(np_of_stage)):
                        p = np_of_stage[st]
                        macs = nu * nx + nu * p + (p * nx if latch else 0)
                        sel = [c for c in calls
                               if c["table"] == tab and c["latch"] == latch and c["stage"] == st
                               and not c["span"]]
                        row(tlabel, f"{kind}, stage {st} (np={p})", sel,
                            0 if (spline or qspline) else macs)
                if spline:
                    sel = [c for c in calls if c["table"] == tab and c["span"]]
                    row(tlabel, "new span, stage 0", sel, 0)
            skipped = [c["insns"] for c in calls if c["status"] == 1 and c["table"] == 0]
            if spline:
                print("   Spline table: per stage 10 stored entries (4 K, 2 k0, 4 L); k0 + L v "
                      "is folded into one spline per input at each span change and latch, so "
                      "an ordinary tick evaluates 4 gains of x and 2 folded splines (4 "
                      "multiply-adds each, plus 1 per gain of x for the command) after the "
                      "basis (5 divisions); 'new span': the first tick of a span (it folds "
                      "the span's k0 + L v), once per 100 ticks here.")
            elif qspline:
                print("   Fixed-point spline table: every tick evaluates each stored entry of "
                      "its stage (4 products of 32 x 32 -> 64 bits and one rounding shift) and "
                      "multiplies it into the command (one multiply-accumulate); no span cache.")
            else:
                print("   MACs = nu*nx + nu*np (+ np*nx on a latch tick): the multiply-adds the law "
                      f"needs; the firmware runs nu*(nx + n_latch) = {nu * (nx + nl)} on every "
                      "tick (L over all n_latch columns)")
            print("   muls run = multiply instructions executed (FP vmul/vnmul/vmls/vnmla/...; integer mul/mla/"
                  "smlal/...; on the M0+, Q31's 64-bit products are libgcc __aeabi_lmul calls).")
            print(f"   Ordinary stage 0 (no limits) includes {len(skipped)} calls reached by a "
                  f"skip (WARN_TICK_SKIPPED), {min(skipped)}..{max(skipped)} instructions.\n")
            report["sizeof_ctrl"] = info["sizeof_ctrl"]
            report.setdefault("sizeof_ctrl_by_image", {})[f"{cpu}/{image}"] = info["sizeof_ctrl"]

    print("== Flash / RAM (arm-none-eabi-size; flash = text + data, static RAM = data + bss)")
    for cpu, build in builds.items():
        label = {"cortex-m4": "cortex-m4 (FPv4-SP, hard float)",
                 "cortex-m0plus": "cortex-m0plus (soft float)"}[cpu]
        for sfx, arith in VARIANTS:
            for controller, target in ((f"libstsp_{arith.lower()}.a", f"stsp_{arith.lower()}"),
                                       (f"libstsp_fixed_robot_corridor{sfx}.a",
                                        f"stsp_fixed_robot_corridor{sfx}")):
                su = stack_usage(build, target)
                print(f"   {label}, {arith}, {controller}:")
                rows = size_rows(build, cpu, controller, sfx)
                report["sizes"][f"{cpu}/{controller}"] = {
                    what.strip(): {"flash": t + d, "ram": d + b}
                    for what, t, d, b in rows if t >= 0}
                for what, t, d, b in rows:
                    if t < 0:
                        print(f"     {what}")
                        continue
                    print(f"     {what:60.60s} flash {t + d:7d} B  static RAM {d + b:4d} B  "
                          f"(text {t}, data {d}, bss {b})")
                api = API_SUFFIX[sfx]   # the external ones carry the arithmetic
                stack = {k: su.get(k, su.get(k + api)) for k in ("stsp_step", "stsp_law_rows",
                                                "stsp_step_cold",
                                                "stsp_step_fixup",
                                                "stsp_limit", "stsp_init", "stsp_table_crc32",
                                                "stsp_spline_step", "stsp_step_next_span",
                                                "stsp_step_cold_spline",
                                                "stsp_spline_law_other")}
                report["sizes"][f"{cpu}/{controller}"]["stack"] = stack
                print("     stack (-fstack-usage, own frame): "
                      + ", ".join(f"{k} {v} B" for k, v in stack.items() if v is not None))
    print("   per instance (caller-owned, STSP_MAX_LATCH = 16), sizeof(stsp_ctrl_t) printed by "
          "each bench image: " + ", ".join(f"{k} {v} B" for k, v in
                                           report.get("sizeof_ctrl_by_image", {}).items()))
    if args.json:
        import json
        args.json.write_text(json.dumps(report, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
