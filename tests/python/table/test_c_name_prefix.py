"""The problem name as a C prefix: names whose generated identifiers, macros
or files collide with the firmware's, the harness's, the C library's or each other are refused
at parse time, in one line naming `name`."""
import re
import subprocess
import sys

import pytest

from conftest import EXAMPLES
from stospline.problem.names import MAX_NAME_LENGTH
from stospline.table.codegen import generate_c
from stospline.pipeline import fixed_point_table
from stospline.problem import ProblemError, parse_problem


def _doc(name) -> dict:
    return {"name": name, "x0": [0.0, 0.0], "tick_hz": 10,
            "dynamics": {"A": [[0, 1], [0, 0]], "B": [[0], [1]]}, "cost": {"R": [[1]]},
            "knots": [{"t": 1.0, "constraint": {"C": [[1, 0]], "value": [1.0]}}]}


@pytest.mark.parametrize("name, words", [
    ("harness", "harness_"),          # harness_table: simulate failed to compile
    ("harness_x", "harness_"),
    ("stsp_max", "STSP_"),            # STSP_MAX_NX redefined the firmware's macro
    ("stsp_fixed", "STSP_"),          # STSP_FIXED_NX switched the firmware's build variant
    ("STSP", "STSP_"),
    ("Stsp_gains", "STSP_"),
    ("robot_q15", "fixed-point"),     # = the Q15 tables of a design named robot
    ("robot_Q31", "fixed-point"),
    ("math", "<math.h>"),             # math.h on the include path shadows <math.h>
    ("string", "<string.h>"),
    ("Python", "<Python.h>"),         # shadows cffi's <Python.h>
    ("con", "Windows"),
    ("_robot", "underscore"),
    ("a__b", "underscore"),
    ("robot_", "underscore"),
    ("a" * (MAX_NAME_LENGTH + 1), "characters"),
    ("a" * 250, "characters"),        # was an OSError (file name too long)
])
def test_colliding_names_are_refused(name, words):
    with pytest.raises(ProblemError) as exc:
        parse_problem(_doc(name))
    assert exc.value.field == "name" and words in exc.value.reason
    assert "\n" not in str(exc.value) and len(str(exc.value)) < 400


@pytest.mark.parametrize("name", ["robot", "stspline", "harnessed", "my_stsp", "Robot2",
                                  "q15", "mathx", "a" * MAX_NAME_LENGTH])
def test_ordinary_names_are_accepted(name):
    assert parse_problem(_doc(name)).name == name


def test_harness_name_is_one_line_exit_2(tmp_path):
    """`name = "harness"` made `simulate` fail in the C compiler with a traceback."""
    f = tmp_path / "h.toml"
    text = (EXAMPLES / "robot_corridor.toml").read_text()
    f.write_text(text.replace('name = "robot_corridor"', 'name = "harness"'))
    r = subprocess.run([sys.executable, "-m", "stospline.cli", "simulate", str(f),
                        "--paths", "10"], capture_output=True, text=True)
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.count("\n") == 1 and ": name: " in r.stderr


def test_longest_name_keeps_generated_identifiers_within_c99(robot_zoh):
    """With a name of MAX_NAME_LENGTH characters every generated identifier and macro (float32
    and Q31 tables) has at most the 63 significant characters C99 guarantees, so they stay
    distinct on every conforming compiler."""
    name = "n" * MAX_NAME_LENGTH
    texts = list(generate_c(robot_zoh.table, prefix=name))
    q31 = fixed_point_table(robot_zoh, "q31")
    texts += generate_c(q31, prefix=f"{name}_q31")
    idents = {w for t in texts for w in re.findall(r"\b[A-Za-z_]\w*\b", t)
              if w.lower().startswith(name)}
    assert any(w.endswith("_Q31_PROBLEM_SHA256") for w in idents)
    assert max(len(w) for w in idents) <= 63
