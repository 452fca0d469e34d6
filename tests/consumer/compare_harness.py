"""Compare a consumer run (tests/consumer/main.c) with the cffi harness, bit for bit.

    .venv/bin/python tests/consumer/compare_harness.py OUTPUT

OUTPUT holds main.c's lines ``tick status x0 x1 x2 x3 u0 u1`` (each float as the 8 hex
digits of its bits). The harness
(`stospline.harness.controller.build_controller`) compiles the firmware with the robot's table as the
designer makes it today, after checking that this is byte for byte the gains/robot_corridor.c
the consumer linked; it then steps one instance with the same ticks and states. Every status
and every command must be identical (float32 bit patterns, the sign of zero included), the run
must start at the problem's x0 and cover every tick of the plan. Exit status 0 on a match, 1
with the first difference otherwise."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]


def read_run(path: Path):
    ticks, status, x, u = [], [], [], []
    for line in path.read_text().splitlines():
        fields = line.split()
        if len(fields) != 8:
            raise SystemExit(f"compare_harness: {path}: not a main.c line: {line!r}")
        ticks.append(int(fields[0]))
        status.append(int(fields[1]))
        if not all(len(f) == 8 for f in fields[2:]):
            raise SystemExit(f"compare_harness: {path}: not 8 hex digits per float: {line!r}")
        x.append([int(f, 16) for f in fields[2:6]])
        u.append([int(f, 16) for f in fields[6:8]])
    return (np.array(ticks), np.array(status), np.array(x, dtype=np.uint32).view(np.float32),
            np.array(u, dtype=np.uint32).view(np.float32))


def main(argv: list[str]) -> int:
    from stospline.table.codegen import generate_c
    from stospline.harness.controller import build_controller
    from stospline.pipeline import design_problem
    from stospline.problem import load_problem

    ticks, status, x, u = read_run(Path(argv[1]))
    problem = load_problem(REPO / "examples" / "robot_corridor.toml")
    table = design_problem(problem).table
    if generate_c(table, source_name="robot_corridor.toml")[1] != (REPO / "gains" / "robot_corridor.c").read_text():
        print("compare_harness: gains/robot_corridor.c is not the designer's table "
              "(tools/regen_gains.sh)")
        return 1
    n_ticks = table.n_ticks
    if not np.array_equal(ticks, np.arange(n_ticks)):
        print(f"compare_harness: expected ticks 0..{n_ticks - 1}, got {len(ticks)} lines")
        return 1
    if not np.array_equal(x[0], np.asarray(problem.x0, dtype=np.float32)):
        print(f"compare_harness: first state {x[0]} is not the problem's x0 {problem.x0}")
        return 1
    step = build_controller(table).stepper(1)
    for k, tick in enumerate(ticks):
        U, S = step(int(tick), x[k][None, :])
        if S[0] != status[k] or not np.array_equal(U[0].view(np.uint32), u[k].view(np.uint32)):
            print(f"compare_harness: tick {tick}: consumer status {status[k]} u {u[k]!r}, "
                  f"harness status {S[0]} u {U[0]!r}")
            return 1
    print(f"compare_harness: {len(ticks)} ticks, every status and command identical "
          f"(last u {[v.hex() for v in u[-1].astype(float)]})")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
