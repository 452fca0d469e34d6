"""Design options are resolved once (override, then the file's [design], then the default),
and the names of the written files come from one function."""
from dataclasses import replace
from pathlib import Path

import pytest

from stospline.errors import ProblemError
from stospline.options import DesignOptions, resolve_options
from stospline.output_names import corridor_design_files, table_files, table_stem
from stospline.pipeline import design_files, design_problem, fixed_point_table
from stospline.problem.reader import load_problem

ROBOT = Path(__file__).resolve().parents[3] / "examples" / "robot_corridor.toml"


@pytest.fixture(scope="module")
def robot():
    return load_problem(ROBOT)


FILE = {"mode": "joint", "discretization": "continuous", "delay_ticks": 1, "table": "spline",
        "spline_tolerance": 1e-4, "arith": "q15"}
OVERRIDE = {"mode": "stagewise", "discretization": "exact-zoh", "delay_ticks": 0,
            "table": "per-tick", "spline_tolerance": 2e-4, "arith": "q31"}


def test_defaults_without_file_options(robot):
    assert resolve_options(replace(robot, options={})) == DesignOptions()


@pytest.mark.parametrize("key", sorted(FILE))
def test_the_file_beats_the_default_and_an_override_beats_the_file(robot, key):
    problem = replace(robot, options={key: FILE[key]})
    assert getattr(resolve_options(problem), key) == FILE[key]
    assert getattr(resolve_options(problem, **{key: OVERRIDE[key]}), key) == OVERRIDE[key]


def test_a_bad_tolerance_names_where_it_came_from(robot):
    with pytest.raises(ProblemError) as err:
        resolve_options(robot, spline_tolerance=0.5, tolerance_field="--spline-tolerance")
    assert err.value.field == "--spline-tolerance"
    with pytest.raises(ValueError, match="table must be one of"):
        resolve_options(robot, table="lookup")


def test_the_design_keeps_its_resolved_options(robot):
    d = design_problem(replace(robot, options={"spline_tolerance": 3e-5}))
    assert d.options.spline_tolerance == 3e-5 and d.options.table == "per-tick"


@pytest.mark.parametrize("arith,spline", [("float32", False), ("q15", False),
                                          ("float32", True)])
def test_file_names_are_the_table_names(robot, arith, spline):
    """The stem is the C prefix the table code gives the table (symbols of several designs
    link into one image), and the pipeline writes exactly the named files."""
    d = design_problem(robot, table="spline" if spline else None)
    table = d.table if arith == "float32" else fixed_point_table(d, arith)
    assert table_stem(robot.name, arith, spline) == table.name
    files, _ = design_files(d, ROBOT.name, arith)
    assert list(files) == table_files(robot.name, arith, spline)


def test_corridor_design_files():
    assert corridor_design_files("r") == ["r.toml", "r.c", "r.h", "r.json", "r_corridor.json"]
