#!/usr/bin/env python3
"""Expected values for tests/c/test_params_spline.c from the float32 specification of the
parametric law on a spline table (stospline.table.spline.params.ParamSplineSpec) on the
shipped gains/robot_goal_spline* tables (tools/params_tables.py --spline): the three runs of
tests/c/params_reference.py (THETA_A from tick 0; the nominal, then THETA_B at the stage-1
start; THETA_A, then THETA_B at tick MID inside stage 0) with its states, their commands
hashed, run A's commands kept at some ticks, and the nominal run's hash (which must be
stsp_step()'s on the spline table). Prints tests/c/params_spline_expected.h
(tests/python/firmware/test_params_spline_c.py checks that the file is this output):
    PYTHONPATH=host .venv/bin/python tests/c/params_spline_reference.py \\
        > tests/c/params_spline_expected.h
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from params_reference import MID, THETA_A, THETA_B, header, params_state  # noqa: E402


def spline_parametric():
    """The shipped robot_goal spline parametric table (tools/params_tables.py --spline)."""
    from stospline.problem import load_problem
    from stospline.refine.spline_params import spline_parametric_of
    return spline_parametric_of(load_problem(ROOT / "examples" / "robot_goal.toml"))


def runs(sp=None):
    """The commands (n_ticks, nu) of runs A, B, C and of the nominal."""
    from stospline.table.spline.params import ParamSplineSpec
    sp = sp or spline_parametric()
    table = sp.table
    nominal = [q.nominal for q in sp.per_tick.parameters]
    stage1 = int(table.stage_start[1])
    out = []
    for changes in ({0: THETA_A}, {stage1: THETA_B}, {0: THETA_A, MID: THETA_B}, {}):
        spec = ParamSplineSpec(table, sp.columns, nominal)
        us = []
        for j in range(table.n_ticks):
            if j in changes:
                spec.set(changes[j])
            us.append(spec.step(j, params_state(j, table.dims[0]))[0])
        out.append(np.array(us))
    return out


def expected(sp=None) -> str:
    A, B, C, N = runs(sp)
    return header("PSP", [" * command's bits (a zero as +0) of the float32 specification on",
                          " * gains/robot_goal_spline* for runs A, B, C and the nominal (see "
                          "the script),",
                          " * and run A's commands at PSP_CHECKED ticks. */"],
                  {"A": A, "B": B, "C": C, "NOMINAL": N}, "tests/c/params_spline_reference.py")


if __name__ == "__main__":
    print(expected(), end="")
