"""The C text of a parametric table's sensitivity columns (`stospline.table.parametric_c`):
it compiles with the firmware's strict flags beside the table's own C, its arrays are the
columns in float32, and a C program that applies them at a parameter vector gets the
parametric table's k0 and lambda0 at that vector to float32 rounding."""
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from stospline.oracle.parametric import design_parametric
from stospline.problem import parse_problem
from stospline.table.codegen import generate_c
from stospline.table.parametric_c import generate_parametric_c

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "design"))
from test_parametric_design import robot_goal_doc  # noqa: E402

REPO = Path(__file__).resolve().parents[3]
FLAGS = ["-std=c99", "-Wall", "-Wextra", "-Wpedantic", "-Wconversion", "-Wshadow", "-Werror"]
CC = shutil.which("cc") or shutil.which("gcc")

MAIN = r"""
#include <stdio.h>
#include "robot_corridor_params.h"
/* k0 and lambda0 at theta, as a setter would compute them, printed one per line. */
int main(void) {
    static const float theta[ROBOT_CORRIDOR_N_PARAMS] = { THETA };
    const stsp_table_t *t = &robot_corridor_table;
    unsigned j, i, p;
    for (j = 0; j < t->n_ticks * t->nu; ++j) {
        float v = t->k0[j];
        for (p = 0; p < ROBOT_CORRIDOR_N_PARAMS; ++p)
            v += robot_corridor_S_k0[j * ROBOT_CORRIDOR_N_PARAMS + p]
                 * (theta[p] - robot_corridor_param_nominal[p]);
        printf("%.9g\n", (double)v);
    }
    for (i = 0; i < (unsigned)t->n_stages * t->n_latch; ++i) {
        float v = t->lambda0[i];
        for (p = 0; p < ROBOT_CORRIDOR_N_PARAMS; ++p)
            v += robot_corridor_S_lambda0[i * ROBOT_CORRIDOR_N_PARAMS + p]
                 * (theta[p] - robot_corridor_param_nominal[p]);
        printf("%.9g\n", (double)v);
    }
    return 0;
}
"""


@pytest.fixture(scope="module")
def robot():
    p = parse_problem(robot_goal_doc(20))
    return p, design_parametric(p).table


def test_arrays_are_the_columns_in_float32(robot):
    _, pt = robot
    header, source = generate_parametric_c(pt)
    assert "#define ROBOT_CORRIDOR_PARAM_GOAL_X 0u" in header
    assert "#define ROBOT_CORRIDOR_N_PARAMS 4u" in header

    def array(name):
        body = source.split(f"{name}[")[1].split("{")[1].split("}")[0]
        return np.array([float(v.rstrip("f")) for v in body.replace("\n", " ").split(",")
                         if v.strip()], dtype=np.float32)

    assert np.array_equal(array("robot_corridor_S_k0"), pt.S_k0.astype(np.float32).ravel())
    assert np.array_equal(array("robot_corridor_param_upper"),
                          np.float32([q.upper for q in pt.parameters]))


@pytest.mark.skipif(CC is None, reason="no C compiler")
def test_c_applies_the_columns(robot, tmp_path):
    p, pt = robot
    theta = np.array([-1.3, 4.6, -5.2, -0.8])
    h, c = generate_c(pt.table.quantized())
    (tmp_path / "robot_corridor.h").write_text(h)
    (tmp_path / "robot_corridor.c").write_text(c)
    h, c = generate_parametric_c(pt)
    (tmp_path / "robot_corridor_params.h").write_text(h)
    (tmp_path / "robot_corridor_params.c").write_text(c)
    (tmp_path / "main.c").write_text(
        MAIN.replace("THETA", ", ".join(f"{float(v)!r}f" for v in theta)))
    exe = tmp_path / "apply"
    subprocess.run([CC, *FLAGS, "-I", str(REPO / "firmware" / "include"), "-I", str(tmp_path),
                    "-o", str(exe), *(str(tmp_path / f) for f in
                                      ("main.c", "robot_corridor.c", "robot_corridor_params.c"))],
                   check=True)
    got = np.array(subprocess.run([str(exe)], check=True, capture_output=True, text=True)
                   .stdout.split(), dtype=float)
    want = pt.at(theta)
    ref = np.concatenate([want.k0.ravel(), want.lambda0.ravel()])
    assert got.shape == ref.shape
    # float32 storage and arithmetic: a few units of 2^-24 of the values and the terms
    scale = np.abs(np.concatenate([pt.table.k0.ravel(), pt.table.lambda0.ravel()])) + np.abs(
        np.concatenate([pt.S_k0.reshape(-1, 4), pt.S_lambda0.reshape(-1, 4)])) @ np.abs(
        theta - pt.nominal)
    err = np.abs(got - ref) / np.maximum(scale, 1e-30)
    print(f"\nC k0/lambda0 at theta vs the parametric table: max rel {err.max():.2g}")
    assert err.max() < 8 * 2.0 ** -24
