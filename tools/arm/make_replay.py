#!/usr/bin/env python3
"""Record closed-loop runs of the host build of the firmware for the QEMU replay test.

The robot example is designed (``design_problem(...).table``), compiled with the firmware
sources through the cffi harness, and run in closed loop on a seeded exponential
Euler-Maruyama simulation of the noisy plant. Every record is one call of ``stsp_step``: the
tick, the float32 state given to it, and what the host build answered: the status, the
command, and the instance's public fields afterwards (``next_tick``, ``stage``, ``latched``,
``sat_mask``). The target must give the same, bit for bit. Records are written as exact
hexadecimal float literals (``INFINITY``/``NAN`` for the non-finite states of probes) into a
C file that ``tests/arm/replay_main.c`` links against, as one or more *runs*: a fresh
instance per run, optionally on the table with other limits (``u_min``/``u_max`` and the
CRC-32 of the table with them, as the host computed it).

Per-tick tables (``--table per-tick``, the default): one run, a subset of the ticks (the first
and last ticks of every stage, which include both latch ticks, plus every ``--stride``-th
tick); the target steps only those, so the status it must return is ``STSP_OK`` after the
previous tick and ``STSP_WARN_TICK_SKIPPED`` after a gap (the host stepped every tick). With
``--arith q15|q31`` the fixed-point tables (``stospline.pipeline.fixed_point_table``, the same
as the committed ``gains/robot_corridor_<arith>.c``) are used instead: the plant state is
converted to the Q format (round half up, saturated) before each step, the integer command is
scaled back for the plant, and the records hold the integers.

Spline tables (``--table spline``, float32; ``gains/robot_corridor_spline.c``): every call of
two closed-loop runs, which the target repeats call for call (so its ordinary ticks take the
same span-cached path as the host's): every tick in order (every span change), with ticks
skipped inside a span, across a span boundary and over a whole span, ticks repeated with
another state (at both latch ticks, at a span's first and last tick), probes with NaN/+-Inf
states (before the first latch, at the stage-1 latch tick, at a span's first tick) and with
huge finite states, and after the plan a tick past the end, one backwards and a repeat of the
last. The first run uses the table as committed (no limits: the robot's); the second the same
table with limits at about the 90th percentile of the first run's |u| (so that commands
saturate, at latch ticks too), and enters stage 1 late (by a skip).

Fixed-point spline tables (``--arith q15|q31 --table spline``;
``gains/robot_corridor_<arith>_spline.c``, ``stospline.pipeline.fixed_point_spline``): the same
two runs, every call in order, with the state converted to the Q format as for per-tick Q tables;
repeats at both latch ticks and at a span's first and last tick, skips inside a span, across a
span boundary and over a whole span, probes with states at the ends of the Q range (a large
command, clamped in the second run; the real call is then a repeat), and the calls after the
plan. The second run has limits at about the 90th percentile of the first run's |u_q|.

The output is deterministic (no time stamps) and is only rewritten when its content changes,
so an unchanged ARM build is not relinked. It belongs in the build directory, not in git.

    .venv/bin/python tools/arm/make_replay.py --out build/arm-m4f/replay_records.c
    .venv/bin/python tools/arm/make_replay.py --table spline --out build/arm-m4f/replay_records_spline.c
    .venv/bin/python tools/arm/make_replay.py --table spline --problem examples/robot_bands.toml \
        --out build/arm-m4f/replay_records_bands_spline.c

The band spline table (``gains/robot_bands_spline.c``) gets the same spline schedule: its
stage-0 latch solves the band dual (W non-symmetric: the solver's Gaussian elimination), with
the NaN probe before it and the repeat after it.
"""
from __future__ import annotations

import argparse
import dataclasses
import re
import sys
from pathlib import Path

import numpy as np

from stospline.design.discretize import zoh
from stospline.harness.controller import build_controller
from stospline.pipeline import design_problem, fixed_point_spline, fixed_point_table
from stospline.problem import load_problem
from stospline.table.format import table_crc32

ROOT = Path(__file__).resolve().parents[2]

STATUS_OK, STATUS_SKIPPED, STATUS_REPEATED, STATUS_SATURATED = 0, 1, 2, 3


@dataclasses.dataclass
class Record:
    """One call of stsp_step and the host build's answer."""
    tick: int
    x: np.ndarray           # the state given (float32 or the Q integers)
    status: int             # the status the target must return
    u: np.ndarray           # the command written
    next_tick: int          # the instance's public fields after the call
    stage: int
    latched: int
    sat_mask: int


@dataclasses.dataclass
class Run:
    """A fresh instance stepped through `records`; `table` the table it was bound to."""
    table: object
    records: list[Record]
    limits: bool            # the table's limits differ from the committed one's
    note: str


def select_ticks(stage_start: np.ndarray, head: int, tail: int, stride: int) -> list[int]:
    """First `head` and last `tail` ticks of every stage, plus every `stride`-th tick."""
    ticks: set[int] = set()
    for a, b in zip(stage_start[:-1].tolist(), stage_start[1:].tolist()):
        ticks.update(range(a, min(a + head, b)))
        ticks.update(range(max(a, b - tail), b))
        ticks.update(range(a, b, stride))
    return sorted(ticks)


def committed_crc(gains_c: Path, prefix: str) -> int | None:
    """The crc32 field of ``<prefix>_table`` in generated C: the hex literal that precedes the
    problem_sha256 byte array (format 2 puts u_min/u_max before it)."""
    text = gains_c.read_text()
    start = text.find(f"const stsp_table_t {prefix}_table")
    m = re.search(r"0x([0-9A-Fa-f]{8})u,\s*\{", text[start:]) if start >= 0 else None
    return int(m.group(1), 16) if m else None


def c_f32(value: np.float32) -> str:
    """Exact C99 literal of a binary32 value: hexadecimal for a finite one, <math.h>'s
    INFINITY and NAN (constant expressions of type float) otherwise."""
    v = float(value)
    if np.isnan(v):
        return "NAN"
    if np.isinf(v):
        return "INFINITY" if v > 0 else "-INFINITY"
    mant, exp = float.hex(v).split("p")
    if "." in mant:
        mant = mant.rstrip("0").rstrip(".")
    return f"{mant}p{exp}f"


def c_int(value) -> str:
    """C literal of a Q15/Q31 integer (-2^31 has no literal of its own)."""
    v = int(value)
    return "(-2147483647 - 1)" if v == -(1 << 31) else str(v)


class HostController:
    """One instance of the host build on `table`: ``call(tick, x) -> Record``."""

    def __init__(self, table):
        self.ctl = build_controller(table)
        self.step = self.ctl.stepper(1)
        self.inst = self.step.instances[0]

    def call(self, tick: int, x) -> Record:
        U, status = self.step(tick, np.asarray(x)[None, :])
        c = self.inst
        return Record(int(tick), np.array(x, copy=True), int(status[0]), U[0].copy(),
                      int(c.next_tick), int(c.stage), int(c.latched), int(c.sat_mask))


def plant_stepper(problem, table, *, seed: int, substeps: int):
    """``advance(stage, x, u) -> x``: one tick of the seeded noisy plant (float64 state,
    zero-order hold of u, `substeps` exponential Euler-Maruyama steps)."""
    rng = np.random.default_rng(seed)
    dt = 1.0 / table.tick_hz / substeps
    mats = []
    for st in problem.stages[:table.n_stages]:
        Ad, Bd = zoh(st.A, st.B, dt)
        mats.append((Ad, Bd, st.G))                # G[i] (n x mz) multiplies x_i

    def advance(k: int, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        Ad, Bd, G = mats[k]
        for _ in range(substeps):
            dZ = rng.standard_normal(G.shape[2]) * np.sqrt(dt)
            x = Ad @ x + Bd @ u + np.einsum("i,iak,k->a", x, G, dZ)
        return x
    return advance


def simulate(problem, table, ticks: set[int], *, seed: int, substeps: int) -> list[Record]:
    """Closed loop of the host C controller on the plant, every tick stepped; the records of
    `ticks`, with the status the target (which steps only those) must return."""
    host = HostController(table)
    ctl = host.ctl
    if ctl.arith == "float32":
        to_input, to_command = (lambda x: x.astype(np.float32)), (lambda U: U.astype(float))
    else:
        F = table.frac_bits

        def to_input(x):
            q = np.clip(np.floor(x / table.x_lsb + 0.5), -(1 << F), (1 << F) - 1)
            return q.astype(ctl.dtype)

        def to_command(U):
            return U * table.u_lsb
    advance = plant_stepper(problem, table, seed=seed, substeps=substeps)
    x = np.array(problem.x0, dtype=float)
    rows: list[Record] = []
    for k in range(table.n_stages):
        for j in range(int(table.stage_start[k]), int(table.stage_start[k + 1])):
            rec = host.call(j, to_input(x))        # exactly what the controller sees
            if rec.status != STATUS_OK:
                raise RuntimeError(f"host stsp_step at tick {j}: {ctl.status_str(rec.status)}")
            if j in ticks:
                expect_next = rows[-1].tick + 1 if rows else 0
                rec.status = STATUS_OK if j == expect_next else STATUS_SKIPPED
                rows.append(rec)
            x = advance(k, x, to_command(rec.u))
    return rows


class _Events(dict):
    """A spline run's call schedule, by tick (`spline_events`, `q_spline_events`)."""

    def add(self, tick: int, kind: str, value=True) -> None:
        d = self.setdefault(tick, {})
        if kind == "probe":
            d.setdefault("probe", []).append(value)
        else:
            d[kind] = value

    def skips(self, b0: list[int], b1: list[int]) -> None:
        """Ticks not stepped: inside a span, across a span boundary, over a whole span (of
        stage 0, span boundaries `b0`), and in stage 1 (`b1`)."""
        mid = (b0[4] + b0[5]) // 2
        for t in [*range(mid, mid + 4), b0[6] - 1, b0[6], *range(b0[8] - 1, b0[9] + 1),
                  *range(b1[4] - 2, b1[4] + 3)]:
            self.add(t, "skip")

    def late_entry(self, start: int) -> None:
        """Stage 1 (first tick `start`) entered, and latched, late: its first ticks skipped."""
        for t in range(start - 2, start + 2):
            self.pop(t, None)
            self.add(t, "skip")


def spline_events(table, *, late_stage_entry: bool) -> dict:
    """The call schedule of a spline run, by tick: 'skip' (not stepped), 'repeat' (stepped
    again with another state), 'probe' (a list of states stepped first: non-finite, refused
    with the instance unchanged; or huge, which overflows or gives an enormous command, the
    real state's call then being a repeat)."""
    sp = table.spline
    start = [int(s) for s in table.stage_start]
    bps = []                                       # span boundaries, absolute ticks
    for s in range(table.n_stages):
        U = sp.knots(s)
        bps.append([start[s] + int(b) for b in U[4:-4]])
    b0, b1 = bps[0], bps[1]
    nan, inf = np.float32(np.nan), np.float32(np.inf)
    ev = _Events()
    add = ev.add
    # Latch ticks: a NaN state before the first latch (refused: no latch), the stage-0 latch
    # repeated (no new latch); the stage-1 latch after a NaN probe, repeated.
    add(start[0], "probe", {0: nan})
    add(start[0], "repeat")
    add(start[1], "probe", {3: nan})
    add(start[1], "repeat")
    # Spans: a repeat at a span's first and at a span's last tick; +-Inf at a span's first
    # tick and inside a span.
    add(b0[0], "repeat")
    add(b0[1] - 1, "repeat")
    add(b0[2], "probe", {2: -inf})
    add((b0[3] + b0[4]) // 2, "probe", {1: inf})
    add(b1[2], "probe", {0: inf, 1: -inf})
    ev.skips(b0, b1)
    # Huge finite states: the command overflows (STSP_ERR_NONFINITE_OUTPUT), or the sum of the
    # state overflows while the command (position gains below 1 in stage 1) does not: the
    # spline fast path's false alarm, an enormous command, and the real call a repeat.
    add(b0[10] + 7, "probe", {0: np.float32(3e38), 1: np.float32(-3e38),
                              2: np.float32(3e38), 3: np.float32(-3e38)})
    add(b0[11] + 3, "probe", {1: np.float32(3e38), 3: np.float32(3e38)})
    add(b1[6] + 5, "probe", {0: np.float32(3e38), 2: np.float32(3e38)})
    if late_stage_entry:
        ev.late_entry(start[1])
    return ev


def q_spline_events(table, *, late_stage_entry: bool) -> dict:
    """`spline_events` for a fixed-point spline table (spans of 2^k ticks): the same repeats
    and skips, and probes with states at the ends of the Q range instead of non-finite or huge
    ones (a fixed-point state is always valid)."""
    sp = table.spline
    start = [int(s) for s in table.stage_start]
    F = table.frac_bits
    lo, hi = -(1 << F), (1 << F) - 1
    bps = []
    for s in range(table.n_stages):
        D = 1 << int(sp.span_log2[s])
        bps.append(list(range(start[s] + D, start[s + 1], D)))
    b0, b1 = bps[0], bps[1]
    ev = _Events()
    add = ev.add
    add(start[0], "repeat")
    add(start[1], "probe", {3: hi})
    add(start[1], "repeat")
    add(b0[0], "repeat")
    add(b0[1] - 1, "repeat")
    add(b0[2], "probe", {2: lo})
    add((b0[3] + b0[4]) // 2, "probe", {0: hi, 1: lo, 2: hi, 3: lo})
    add(b1[2], "probe", {0: lo, 1: hi})
    ev.skips(b0, b1)
    if late_stage_entry:
        ev.late_entry(start[1])
    return ev


def simulate_calls(problem, table, *, seed: int, substeps: int,
                   late_stage_entry: bool) -> list[Record]:
    """A spline run: every call of the closed loop (`spline_events`, `q_spline_events`), in
    order."""
    host = HostController(table)
    fixed = getattr(table, "arith", "float32") != "float32"
    events = (q_spline_events if fixed else spline_events)(table,
                                                            late_stage_entry=late_stage_entry)
    advance = plant_stepper(problem, table, seed=seed, substeps=substeps)
    if fixed:
        F = table.frac_bits

        def to_input(x):
            q = np.clip(np.floor(x / table.x_lsb + 0.5), -(1 << F), (1 << F) - 1)
            return q.astype(host.ctl.dtype)

        def off(xq):     # the state measured again, one LSB off (no new latch)
            return np.clip(xq.astype(np.int64) + 1, -(1 << F), (1 << F) - 1).astype(xq.dtype)

        def to_command(U):
            return U * table.u_lsb
    else:
        def to_input(x):
            return x.astype(np.float32)

        def off(x32):    # the state measured again, slightly off (no new latch)
            return (x32 * np.float32(1.001) + np.float32(1e-3)).astype(np.float32)

        def to_command(U):
            return U.astype(float)
    x = np.array(problem.x0, dtype=float)
    u = np.asarray(table.u_hold).copy()                     # held until the first command
    rows: list[Record] = []
    last = 0
    for k in range(table.n_stages):
        for j in range(int(table.stage_start[k]), int(table.stage_start[k + 1])):
            ev = events.get(j, {})
            x32 = to_input(x)
            for probe in ev.get("probe", []):
                xp = x32.copy()
                for i, value in probe.items():
                    xp[i] = value
                rows.append(host.call(j, xp))
            if not ev.get("skip"):
                rows.append(host.call(j, x32))
                if ev.get("repeat"):
                    rows.append(host.call(j, off(x32)))
                u = rows[-1].u
                last = j
            x = advance(k, x, to_command(u))
    x32 = to_input(x)
    n_ticks = int(table.stage_start[-1])
    for tick in (n_ticks, n_ticks + 1000, last - 10, last):  # range, range, order, repeat
        rows.append(host.call(tick, x32))
    return rows


def saturating_limits(table, rows: list[Record], quantile: float = 0.9):
    """u_min/u_max that clamp the larger commands of `rows` (0 = u_hold stays inside); in Q
    units for a fixed-point table."""
    U = np.array([r.u for r in rows if r.status >= 0], dtype=float)
    hi = np.quantile(np.maximum(U, 0.0), quantile, axis=0)
    lo = np.quantile(np.maximum(-U, 0.0), quantile, axis=0)
    if getattr(table, "arith", "float32") != "float32":
        dtype = np.asarray(table.u_min).dtype
        return (-np.maximum(np.ceil(lo), 1.0)).astype(dtype), \
            np.maximum(np.ceil(hi), 1.0).astype(dtype)
    # round outwards to 1/64, at least 1/64, so the limits are short exact literals
    hi = np.maximum(np.ceil(hi * 64.0), 1.0) / 64.0
    lo = np.maximum(np.ceil(lo * 64.0), 1.0) / 64.0
    return (-lo).astype(np.float32), hi.astype(np.float32)


def render(table, runs: list[Run], *, seed: int, source: str) -> str:
    crc = table_crc32(table)
    arith = getattr(table, "arith", "float32")
    lit = c_f32 if arith == "float32" else c_int
    total = sum(len(r.records) for r in runs)
    lines = [
        "/* Generated by tools/arm/make_replay.py: host (cffi) build of firmware/src on "
        f"{source},\n * seed {seed}, table {table.name} crc32 0x{crc:08X}, {len(runs)} run(s), "
        f"{total} records. Do not edit; not committed. */",
    ]
    if arith == "float32":
        lines.append("#include <math.h>")
    lines += ['#include "replay_records.h"', "",
              f"const uint32_t replay_table_crc32 = 0x{crc:08X}u;", ""]
    for n, run in enumerate(runs):
        if run.limits:
            lo = ", ".join(lit(v) for v in run.table.u_min)
            hi = ", ".join(lit(v) for v in run.table.u_max)
            lines += [f"static const stsp_scalar_t run{n}_u_min[REPLAY_NU] = {{{lo}}};",
                      f"static const stsp_scalar_t run{n}_u_max[REPLAY_NU] = {{{hi}}};"]
        lines.append(f"static const replay_record_t run{n}_records[{len(run.records)}] = {{")
        for r in run.records:
            xs = ", ".join(lit(v) for v in r.x)
            us = ", ".join(lit(v) for v in r.u)
            lines.append(f"    {{{r.tick}u, {r.next_tick}u, {r.status}, {r.stage}u, "
                         f"{r.latched}u, {r.sat_mask}u, {{{xs}}}, {{{us}}}}},")
        lines += ["};", ""]
    lines.append(f"const uint32_t replay_run_count = {len(runs)}u;")
    lines.append(f"const replay_run_t replay_runs[{len(runs)}] = {{")
    for n, run in enumerate(runs):
        limits = f"run{n}_u_min, run{n}_u_max" if run.limits else "NULL, NULL"
        lines.append(f'    {{"{run.note}", {limits}, 0x{table_crc32(run.table):08X}u, '
                     f"{len(run.records)}u, run{n}_records}},")
    lines.append("};")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True, help="C file to write")
    ap.add_argument("--problem", type=Path, default=ROOT / "examples" / "robot_corridor.toml")
    ap.add_argument("--gains", type=Path, default=None,
                    help="committed tables the ARM image links (their CRC must match); default "
                         "gains/<name>.c, gains/<name>_<arith>.c, gains/<name>_spline.c or "
                         "gains/<name>_<arith>_spline.c of the problem's name")
    ap.add_argument("--arith", choices=["float32", "q15", "q31"], default="float32")
    ap.add_argument("--table", choices=["per-tick", "spline"], default="per-tick",
                    help="the table kind (spline: every call of two runs)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--substeps", type=int, default=4)
    ap.add_argument("--head", type=int, default=50, help="first ticks of each stage")
    ap.add_argument("--tail", type=int, default=50, help="last ticks of each stage")
    ap.add_argument("--stride", type=int, default=50, help="plus every stride-th tick")
    ap.add_argument("--perturb", type=int, metavar="RECORD", default=None,
                    help="test the test: move u[0] of this record (of the first run) up by one "
                         "ulp (one unit)")
    args = ap.parse_args(argv)
    spline = args.table == "spline"

    problem = load_problem(args.problem)
    designed = design_problem(problem, table="spline" if spline else None,
                              mode=problem.options.get("mode", "stagewise"))
    if args.arith == "float32":
        table = designed.table
    elif spline:
        table = fixed_point_spline(designed, args.arith)[0]
    else:
        table = fixed_point_table(designed, args.arith)
    if spline and getattr(table, "spline", None) is None:
        raise SystemExit("make_replay: the design gave no spline table")
    if args.gains is None:
        suffix = ("" if args.arith == "float32" else f"_{args.arith}") + \
            ("_spline" if spline else "")
        args.gains = ROOT / "gains" / f"{problem.name}{suffix}.c"
    want = committed_crc(args.gains, table.name)
    got = table_crc32(table)
    if want != got:
        raise SystemExit(f"make_replay: designed table crc32 0x{got:08X} differs from "
                         f"{args.gains} ({'none found' if want is None else f'0x{want:08X}'}): "
                         "regenerate the gains (stospline design) before replaying")

    if spline:
        first = simulate_calls(problem, table, seed=args.seed, substeps=args.substeps,
                               late_stage_entry=False)
        lo, hi = saturating_limits(table, first)
        limited = dataclasses.replace(table, u_min=lo, u_max=hi)
        second = simulate_calls(problem, limited, seed=args.seed + 1, substeps=args.substeps,
                                late_stage_entry=True)
        if not any(r.status == STATUS_SATURATED for r in second):
            raise SystemExit("make_replay: the limited run never saturated")
        runs = [Run(table, first, False, "committed table"),
                Run(limited, second, True, "with limits")]
    else:
        ticks = set(select_ticks(np.asarray(table.stage_start), args.head, args.tail,
                                 args.stride))
        missing = {int(s) for s in table.stage_start[:-1]} - ticks
        if missing:
            raise SystemExit(f"make_replay: latch ticks {sorted(missing)} not selected")
        rows = simulate(problem, table, ticks, seed=args.seed, substeps=args.substeps)
        runs = [Run(table, rows, False, "committed table")]

    if args.perturb is not None:
        rec = runs[0].records[args.perturb]
        u = rec.u.copy()
        if args.arith == "float32":
            u[0] = np.nextafter(u[0], np.float32(np.inf), dtype=np.float32)
        else:
            u[0] = u[0] + 1
        rec.u = u
        print(f"make_replay: PERTURBED record {args.perturb} (tick {rec.tick}) u[0] by +1 ulp",
              file=sys.stderr)

    text = render(table, runs, seed=args.seed, source=args.problem.name)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    if not args.out.exists() or args.out.read_text() != text:
        args.out.write_text(text)
        state = "written"
    else:
        state = "unchanged"
    for n, run in enumerate(runs):
        recs = run.records
        counts: dict[int, int] = {}
        for r in recs:
            counts[r.status] = counts.get(r.status, 0) + 1
        summary = ", ".join(f"{counts[s]} x {s}" for s in sorted(counts))
        print(f"make_replay: run {n} ({run.note}): {len(recs)} records, ticks "
              f"{min(r.tick for r in recs)}..{max(r.tick for r in recs if r.status >= 0)}, "
              f"statuses {summary}, crc32 0x{table_crc32(run.table):08X}")
    print(f"make_replay: -> {args.out} ({state})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
