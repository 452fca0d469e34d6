#!/usr/bin/env python3
"""Expected values for tests/c/test_params.c from the float32 specification of the parametric
law (stospline.table.params_spec) on the shipped robot_goal tables: three runs over every tick
with the states of params_state() (the same formula in the C test), their commands hashed and
some ticks' commands kept. Run A sets THETA_A before tick 0; run B starts at the nominal and
sets THETA_B just before the first tick of stage 1; run C sets THETA_A, then THETA_B just
before tick MID (inside stage 0: the new k0 with the multipliers latched at tick 0).
Prints tests/c/params_expected.h (tests/python/firmware/test_params_c.py checks that the file
is this output):
    PYTHONPATH=host .venv/bin/python tests/c/params_reference.py > tests/c/params_expected.h
With ``--example drone_gates``: the same three runs of the drone through gates (its six gate
coordinates; run B changes them at the stage-1 start, tick 100, run C at tick 150), for
tools/arm/count_params.py --example drone_gates:
    PYTHONPATH=host .venv/bin/python tests/c/params_reference.py --example drone_gates \
        > tests/c/params_drone_expected.h
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
THETA_A = (-0.7, 5.3)
THETA_B = (-1.4, 4.6)
MID = 150
CHECKED = (0, 1, 150, 299, 300, 301, 599)
# Per example: (theta A, theta B, MID, CHECKED, the header the output is kept in).
RUNS = {"robot_goal": (THETA_A, THETA_B, MID, CHECKED, "params_expected.h"),
        "drone_gates": ((0.3, 2.2, 1.2, 2.9, -0.2, 1.4), (-0.4, 1.6, 0.6, 2.2, 0.4, 2.0),
                        150, (0, 1, 150, 199, 200, 201, 399), "params_drone_expected.h")}
f32 = np.float32


def fnv1a(words, h: int = 0x811C9DC5) -> int:
    """FNV-1a over 32-bit words, byte by byte, little-endian."""
    for w in words:
        for b in int(w).to_bytes(4, "little"):
            h = ((h ^ b) * 0x01000193) & 0xFFFFFFFF
    return h


def bits(a) -> np.ndarray:
    """binary32 bit patterns, a zero as +0 (the C's sign of zero may differ)."""
    return (np.asarray(a, f32) + f32(0)).view(np.uint32)


def params_state(j: int, nx: int) -> np.ndarray:
    """The state of tick j: ((7 j + 13 c) mod 41) 0.05 - 1 in binary32 (as the C test)."""
    return np.array([[f32((7 * j + 13 * c) % 41) * f32(0.05) - f32(1.0) for c in range(nx)]],
                    f32)


def tables(example: str = "robot_goal"):
    """The example's float32 table and parametric table, designed with its file's options."""
    from stospline import design_problem, load_problem
    from stospline.oracle.parametric import check_parametric_options, design_parametric
    problem = load_problem(ROOT / "examples" / f"{example}.toml")
    opts = check_parametric_options(problem)
    return (design_problem(problem, options=opts).table,
            design_parametric(problem, mode=opts.mode, discretization=opts.discretization,
                              delay_ticks=opts.delay_ticks).table)


def runs(example: str = "robot_goal", designed=None):
    """The tables and the commands (n_ticks, nu) of runs A, B, C (`designed`: the example's
    `tables`, when the caller has them)."""
    from stospline.table.params_spec import ParamSpec
    from stospline.table.parametric_c import flash_columns
    table, pt = designed or tables(example)
    cols = flash_columns(pt)
    theta_a, theta_b, mid, _, _ = RUNS[example]
    stage1 = int(table.stage_start[1])
    out = []
    for changes in ({0: theta_a}, {stage1: theta_b}, {0: theta_a, mid: theta_b}):
        spec = ParamSpec(table, cols, 1)
        us = []
        for j in range(table.n_ticks):
            if j in changes:
                spec.set(changes[j])
            us.append(spec.step(j, params_state(j, table.dims[0]))[0])
        out.append(np.array(us))
    return table, cols, out


def expected(example: str = "robot_goal", designed=None) -> str:
    """The header of `example`'s runs (tests/c/<RUNS[example][4]>)."""
    _, _, (A, B, C) = runs(example, designed)
    opt = "" if example == "robot_goal" else f" --example {example}"
    return header("PAR", [" * command's bits (a zero as +0) of the float32 specification on "
                          f"gains/{example}*",
                          " * for runs A, B, C (see the script), and run A's commands at "
                          "PAR_CHECKED ticks. */"],
                  {"A": A, "B": B, "C": C}, f"tests/c/params_reference.py{opt}",
                  RUNS[example][:4])


def header(prefix: str, comment: list[str], runs_: dict, script: str,
           run=RUNS["robot_goal"][:4]) -> str:
    """The expected-values header: `comment` after the first line, THETA_A/B, MID of `run`
    (``(theta A, theta B, MID, CHECKED)``), the hash of each run in `runs_` (``{name:
    commands}``, "A" first: its commands at CHECKED ticks kept), the names prefixed by `prefix`
    (lower case for the arrays)."""
    theta_a, theta_b, mid, checked = run
    low = prefix.lower()
    lines = [f"/* Generated by {script}: do not edit. FNV-1a over every", *comment,
             f"#define {prefix}_THETA_A {{{', '.join(f'{v}f' for v in theta_a)}}}",
             f"#define {prefix}_THETA_B {{{', '.join(f'{v}f' for v in theta_b)}}}",
             f"#define {prefix}_MID {mid}u"]
    lines += [f"#define {prefix}_HASH_{k} 0x{fnv1a(bits(v).ravel()):08X}u"
              for k, v in runs_.items()]
    lines += [f"#define {prefix}_N_CHECKED {len(checked)}u",
              f"static const uint32_t {low}_checked[{prefix}_N_CHECKED] = {{"
              + ", ".join(f"{j}u" for j in checked) + "};",
              f"static const uint32_t {low}_checked_u[{prefix}_N_CHECKED][{runs_['A'].shape[1]}]"
              " = {"]
    lines += ["    {" + ", ".join(f"0x{w:08X}u" for w in row) + "},"
              for row in bits(runs_["A"][list(checked)])]
    lines += ["};"]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    import argparse
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--example", choices=sorted(RUNS), default="robot_goal")
    print(expected(ap.parse_args().example), end="")
