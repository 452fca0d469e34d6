#!/usr/bin/env python3
"""Record a closed-loop run of the host build of the firmware for the QEMU replay test.

The robot example is designed (``design_problem(...).table``), compiled with the firmware
sources through the cffi harness, and run in closed loop on a seeded exponential
Euler-Maruyama simulation of the noisy plant. For a subset of ticks (the first and last ticks
of every stage, which include both latch ticks, plus every ``--stride``-th tick) the float32
state given to ``stsp_step`` and the float32 command it returned are written as exact
hexadecimal float literals into a C file that ``tests/arm/replay_main.c`` links against.
With ``--arith q15|q31`` the fixed-point tables (``stospline.pipeline.fixed_point_table``, the same
as the committed ``gains/robot_corridor_<arith>.c``) are used instead: the plant state is
converted to the Q format (round half up, saturated) before each step, the integer command is
scaled back for the plant, and the records hold the integers.

The output is deterministic (no time stamps) and is only rewritten when its content changes,
so an unchanged ARM build is not relinked. It belongs in the build directory, not in git.

    .venv/bin/python tools/arm/make_replay.py --out build/arm-m4f/replay_records.c
"""
from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

import numpy as np

from stospline.design.discretize import zoh
from stospline.sim.controller import build_controller
from stospline.pipeline import design_problem, fixed_point_table
from stospline.problem import load_problem
from stospline.table.format import table_crc32

ROOT = Path(__file__).resolve().parents[2]


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
    """Exact C99 hexadecimal literal of a finite binary32 value."""
    v = float(value)
    if not np.isfinite(v):
        raise ValueError(f"non-finite value {v} in a record")
    mant, exp = float.hex(v).split("p")
    if "." in mant:
        mant = mant.rstrip("0").rstrip(".")
    return f"{mant}p{exp}f"


def simulate(problem, table, ticks: set[int], *, seed: int, substeps: int):
    """Closed loop of the host C controller on the plant; the records of `ticks`."""
    ctl = build_controller(table)
    if ctl.arith == "float32":
        to_input, to_command = (lambda x: x.astype(np.float32)), (lambda U: U.astype(float))
    else:
        F = table.frac_bits

        def to_input(x):
            q = np.clip(np.floor(x / table.x_lsb + 0.5), -(1 << F), (1 << F) - 1)
            return q.astype(ctl.dtype)

        def to_command(U):
            return U * table.u_lsb
    step = ctl.stepper(1)
    rng = np.random.default_rng(seed)
    dt = 1.0 / table.tick_hz / substeps
    x = np.array(problem.x0, dtype=float)
    rows = []
    for k in range(table.n_stages):
        st = problem.stages[k]
        Ad, Bd = zoh(st.A, st.B, dt)
        G = st.G                                   # G[i] (n x mz) multiplies x_i
        for j in range(int(table.stage_start[k]), int(table.stage_start[k + 1])):
            x32 = to_input(x)                      # exactly what the controller sees
            U, status = step(j, x32[None, :])
            if int(status[0]) != 0:
                raise RuntimeError(f"host stsp_step at tick {j}: {ctl.status_str(int(status[0]))}")
            u32 = U[0].copy()                      # the stepper reuses its buffers
            if j in ticks:
                rows.append((j, x32.copy(), u32))
            u = to_command(u32)                    # zero-order hold over the tick
            for _ in range(substeps):
                dZ = rng.standard_normal(G.shape[2]) * np.sqrt(dt)
                x = Ad @ x + Bd @ u + np.einsum("i,iak,k->a", x, G, dZ)
    return rows


def c_int(value) -> str:
    """C literal of a Q15/Q31 integer (-2^31 has no literal of its own)."""
    v = int(value)
    return "(-2147483647 - 1)" if v == -(1 << 31) else str(v)


def render(table, rows, *, seed: int, source: str) -> str:
    crc = table_crc32(table)
    lit = c_f32 if getattr(table, "arith", "float32") == "float32" else c_int
    lines = [
        "/* Generated by tools/arm/make_replay.py: host (cffi) build of firmware/src on "
        f"{source},\n * seed {seed}, table crc32 0x{crc:08X}, {len(rows)} records. "
        "Do not edit; not committed. */",
        '#include "replay_records.h"',
        "",
        f"const uint32_t replay_table_crc32 = 0x{crc:08X}u;",
        f"const uint32_t replay_record_count = {len(rows)}u;",
        f"const replay_record_t replay_records[{len(rows)}] = {{",
    ]
    for tick, x, u in rows:
        xs = ", ".join(lit(v) for v in x)
        us = ", ".join(lit(v) for v in u)
        lines.append(f"    {{{tick}u, {{{xs}}}, {{{us}}}}},")
    lines.append("};")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True, help="C file to write")
    ap.add_argument("--problem", type=Path, default=ROOT / "examples" / "robot_corridor.toml")
    ap.add_argument("--gains", type=Path, default=None,
                    help="committed tables the ARM image links (their CRC must match); default "
                         "gains/robot_corridor.c, or gains/robot_corridor_<arith>.c")
    ap.add_argument("--arith", choices=["float32", "q15", "q31"], default="float32")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--substeps", type=int, default=4)
    ap.add_argument("--head", type=int, default=50, help="first ticks of each stage")
    ap.add_argument("--tail", type=int, default=50, help="last ticks of each stage")
    ap.add_argument("--stride", type=int, default=50, help="plus every stride-th tick")
    ap.add_argument("--perturb", type=int, metavar="RECORD", default=None,
                    help="test the test: move u[0] of this record up by one ulp (one unit)")
    args = ap.parse_args(argv)

    problem = load_problem(args.problem)
    designed = design_problem(problem)
    table = designed.table if args.arith == "float32" else fixed_point_table(designed, args.arith)
    if args.gains is None:
        suffix = "" if args.arith == "float32" else f"_{args.arith}"
        args.gains = ROOT / "gains" / f"robot_corridor{suffix}.c"
    ticks = set(select_ticks(np.asarray(table.stage_start), args.head, args.tail, args.stride))
    missing = {int(s) for s in table.stage_start[:-1]} - ticks
    if missing:
        raise SystemExit(f"make_replay: latch ticks {sorted(missing)} not selected")
    rows = simulate(problem, table, ticks, seed=args.seed, substeps=args.substeps)

    want = committed_crc(args.gains, table.name)
    got = table_crc32(table)
    if want != got:
        raise SystemExit(f"make_replay: designed table crc32 0x{got:08X} differs from "
                         f"{args.gains} ({'none found' if want is None else f'0x{want:08X}'}): "
                         "regenerate the gains (stospline design) before replaying")
    if args.perturb is not None:
        tick, x, u = rows[args.perturb]
        u = u.copy()
        if args.arith == "float32":
            u[0] = np.nextafter(u[0], np.float32(np.inf), dtype=np.float32)
        else:
            u[0] = u[0] + 1
        rows[args.perturb] = (tick, x, u)
        print(f"make_replay: PERTURBED record {args.perturb} (tick {tick}) u[0] by +1 ulp",
              file=sys.stderr)

    text = render(table, rows, seed=args.seed, source=args.problem.name)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    if not args.out.exists() or args.out.read_text() != text:
        args.out.write_text(text)
        state = "written"
    else:
        state = "unchanged"
    print(f"make_replay: {len(rows)} records (ticks {rows[0][0]}..{rows[-1][0]}, "
          f"crc32 0x{got:08X}) -> {args.out} ({state})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
