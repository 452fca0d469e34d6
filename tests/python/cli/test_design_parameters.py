"""`stospline design --out` of a problem with [[parameters]] writes the sensitivity columns
``<name>_params.{h,c}`` with the tables, as one set, and its JSON summary lists the parameters
with their ranges; a table kind without columns is refused before any work."""
import json

from conftest import EXAMPLES, GAINS

from stospline.cli import main


def test_design_writes_the_parameter_files_and_lists_them(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["design", str(EXAMPLES / "robot_goal.toml"), "--out", str(out), "--json"]) == 0
    captured = capsys.readouterr()
    assert sorted(p.name for p in out.iterdir()) == [
        "robot_goal.c", "robot_goal.h", "robot_goal.json", "robot_goal_params.c",
        "robot_goal_params.h"]
    for name in ("robot_goal_params.c", "robot_goal_params.h", "robot_goal.c"):
        assert (out / name).read_text() == (GAINS / name).read_text(), name
    summary = json.loads(captured.out)
    assert summary == json.loads((out / "robot_goal.json").read_text())
    assert summary["parameters"] == [
        {"name": "goal_x", "nominal": -1.0, "lower": -1.5, "upper": -0.5},
        {"name": "goal_y", "nominal": 5.0, "lower": 4.5, "upper": 5.5}]


def test_a_problem_without_parameters_writes_no_columns(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["design", str(EXAMPLES / "population.toml"), "--out", str(out), "--json"]) == 0
    assert "parameters" not in json.loads(capsys.readouterr().out)
    assert not list(out.glob("*_params.*"))


def test_a_table_without_columns_is_refused_in_one_line(tmp_path, capsys):
    out = tmp_path / "out"
    for extra, named in ((["--arith", "q15"], "--arith: "), (["--table", "spline"], "--table: ")):
        assert main(["design", str(EXAMPLES / "robot_goal.toml"), "--out", str(out),
                     *extra]) == 2
        captured = capsys.readouterr()
        err = captured.err.strip()
        assert len(err.splitlines()) == 1 and named in err, err
        assert captured.out == "" and not out.exists()


def test_all_files_or_none(tmp_path, capsys):
    """A parameter file's target that cannot be replaced: nothing written, status 2."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "robot_goal_params.c").mkdir()
    assert main(["design", str(EXAMPLES / "robot_goal.toml"), "--out", str(out)]) == 2
    captured = capsys.readouterr()
    assert "robot_goal_params.c" in captured.err and captured.out == ""
    assert sorted(p.name for p in out.iterdir()) == ["robot_goal_params.c"]
