"""gains/<name>_params.{c,h} of every example with [[parameters]] are regenerated
byte-for-byte (tools/params_tables.py, run by tools/regen_gains.sh), and so are the Q15/Q31
parametric controllers of tools/params_tables.py --fixed (per tick and spline) and the spline
ones of --spline."""
import sys

import pytest

from conftest import EXAMPLES, GAINS, REPO

from stospline.oracle.parametric import parametric_c_files
from stospline.problem import load_problem

WITH_PARAMETERS = sorted(p.stem for p in EXAMPLES.glob("*.toml")
                         if load_problem(p).parameters)


def test_an_example_has_parameters():
    assert "robot_goal" in WITH_PARAMETERS


@pytest.mark.parametrize("example", WITH_PARAMETERS)
def test_regenerating_parameter_columns_changes_no_byte(example):
    files = parametric_c_files(load_problem(EXAMPLES / f"{example}.toml"),
                               source_name=f"{example}.toml")
    assert sorted(files) == [f"{example}_params.c", f"{example}_params.h"]
    for name, text in files.items():
        assert (GAINS / name).read_text() == text, \
            f"gains/{name} differs (regenerate with tools/regen_gains.sh)"


def test_regenerating_fixed_point_parametric_tables_changes_no_byte():
    """gains/robot_goal_<arith>.{c,h} and _params.{c,h}, and the spline ones
    gains/robot_goal_<arith>_spline.{c,h} and _spline_params.{c,h} (tools/params_tables.py
    --fixed)."""
    sys.path.insert(0, str(REPO / "tools"))
    from params_tables import FIXED, fixed_point_files, fixed_spline_files
    for example in FIXED:
        for kind, made in (("", fixed_point_files(example)),
                           ("_spline", fixed_spline_files(example))):
            for arith, (files, _) in made.items():
                assert sorted(files) == sorted(f"{example}_{arith}{kind}{s}" for s in
                                               (".c", ".h", "_params.c", "_params.h"))
                for name, text in files.items():
                    assert (GAINS / name).read_text() == text, \
                        f"gains/{name} differs (regenerate with tools/regen_gains.sh)"


def test_regenerating_spline_parametric_tables_changes_no_byte():
    """gains/robot_goal_spline.{c,h} and _spline_params.{c,h} (tools/params_tables.py
    --spline)."""
    sys.path.insert(0, str(REPO / "tools"))
    from params_tables import SPLINE, spline_files
    for example in SPLINE:
        files, _ = spline_files(load_problem(EXAMPLES / f"{example}.toml"), f"{example}.toml")
        assert sorted(files) == sorted(f"{example}_spline{s}" for s in
                                       (".c", ".h", "_params.c", "_params.h"))
        for name, text in files.items():
            assert (GAINS / name).read_text() == text, \
                f"gains/{name} differs (regenerate with tools/regen_gains.sh)"
