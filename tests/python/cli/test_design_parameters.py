"""`stospline design --out` of a problem with [[parameters]] writes the sensitivity columns
``<name>_params.{h,c}`` with the tables, as one set, and its JSON summary lists the parameters
with their ranges; with ``--arith q15|q31`` the fixed-point parametric controller
``<name>_<arith>{,_params}.{h,c}``, with ``--table spline`` the spline one
``<name>[_<arith>]_spline{,_params}.{h,c}``; a table kind without columns is refused before
any work."""
import json

import numpy as np
import pytest

from conftest import EXAMPLES, GAINS

from stospline import design_problem, load_problem
from stospline.cli import main
from stospline.options import resolve_options
from stospline.oracle.fixed_point_margin import fixed_point_certificate
from stospline.oracle.parametric import fixed_parametric, fixed_spline_parametric
from stospline.pipeline import fixed_point_table
from stospline.refine.spline_params import certify_over_box, spline_parametric_of
from stospline.table.spline.fixed_point import q_spline_bytes
from stospline.table.spline.qparams import column_flash_bytes, spline_gain_table


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


def _design_as_shipped(tmp_path, capsys, stem: str, *extra: str):
    """``(summary, captured)`` of `design robot_goal.toml --out DIR --json` with `extra`,
    after checking that it wrote ``<stem>{,_params}.{c,h}`` byte for byte as gains/ ships
    them (tools/params_tables.py writes those with the same code) and ``<stem>.json``."""
    out = tmp_path / "out"
    assert main(["design", str(EXAMPLES / "robot_goal.toml"), *extra, "--out", str(out),
                 "--json"]) == 0
    captured = capsys.readouterr()
    assert sorted(p.name for p in out.iterdir()) == [
        f"{stem}.c", f"{stem}.h", f"{stem}.json", f"{stem}_params.c", f"{stem}_params.h"]
    for suffix in (".c", ".h", "_params.c", "_params.h"):
        assert (out / f"{stem}{suffix}").read_text() == (GAINS / f"{stem}{suffix}").read_text()
    summary = json.loads(captured.out)
    assert summary == json.loads((out / f"{stem}.json").read_text())
    return summary, captured


@pytest.mark.parametrize("arith", ["q15", "q31"])
def test_design_arith_writes_the_fixed_point_parametric_controller(tmp_path, capsys, arith):
    """`--arith q15|q31`: the gain table quantized with the columns and the columns, byte for
    byte the shipped gains/ (tools/params_tables.py --fixed, the same code), and a summary of
    the table written (its scales and its error bound over the box, not the plain Q table's)."""
    summary, captured = _design_as_shipped(tmp_path, capsys, f"robot_goal_{arith}",
                                           "--arith", arith)
    problem = load_problem(EXAMPLES / "robot_goal.toml")
    _, pf, pd = fixed_parametric(problem, options=resolve_options(problem, arith=arith))
    table = pf.gain_table()
    fixed = summary["fixed"]
    assert (fixed["x_exp"], fixed["u_exp"], fixed["v_exp"]) == (
        table.x_exp.tolist(), table.u_exp.tolist(), table.v_exp.tolist())
    assert fixed["u_error_bound_lsb"] == json.loads(json.dumps(table.written_bound_lsb()))
    plain = fixed_point_table(design_problem(problem), arith)
    assert fixed["u_error_bound_lsb"] != json.loads(json.dumps(plain.written_bound_lsb()))
    # what the table as flashed guarantees over the box (docs/theory/parameters.md)
    cert = fixed_point_certificate(problem, pd.table, pf)["corridors"][0]["cantelli"]
    assert fixed["over_box"]["corridors"][0]["over_box"]["cantelli"]["worst_tick"] == \
        pytest.approx(cert.worst_tick, rel=1e-9)
    assert fixed["over_box"]["bands"] == [] and "note" not in captured.err


@pytest.mark.parametrize("arith", ["q15", "q31"])
def test_design_arith_table_spline_writes_the_fixed_point_spline_parametric_controller(
        tmp_path, capsys, arith):
    """`--arith q15|q31 --table spline`: the Q spline gain table and its integer spline
    columns, byte for byte the shipped gains/ (tools/params_tables.py --fixed, the same code),
    and a summary of the table as flashed: its scales, its sizes and, under ``over_box``,
    `fixed_point_certificate` of the spline law over the box, not the per-tick Q table's."""
    summary, captured = _design_as_shipped(tmp_path, capsys, f"robot_goal_{arith}_spline",
                                           "--arith", arith, "--table", "spline")
    problem = load_problem(EXAMPLES / "robot_goal.toml")
    _, (pf, gains, cols), pd = fixed_spline_parametric(
        problem, options=resolve_options(problem, arith=arith))
    fixed = summary["fixed"]
    table = spline_gain_table(pf, gains, f"robot_goal_{arith}_spline")
    assert (fixed["x_exp"], fixed["u_exp"], fixed["v_exp"]) == (
        table.x_exp.tolist(), table.u_exp.tolist(), table.v_exp.tolist())
    assert fixed["u_error_bound_lsb"] == json.loads(json.dumps(table.written_bound_lsb()))
    assert fixed["spline"]["gain_bytes"] == q_spline_bytes(gains)
    assert fixed["spline"]["column_bytes"] == column_flash_bytes(pf, cols)
    cert = fixed_point_certificate(problem, pd.table, pf)["corridors"][0]
    got = fixed["over_box"]["corridors"][0]["over_box"]
    for tail in ("cantelli", "gaussian"):
        assert got[tail]["worst_tick"] == pytest.approx(cert[tail].worst_tick, rel=1e-9)
    if arith == "q15":      # the per-tick Q table's differs in the 4th digit
        _, tick_pf, tick_pd = fixed_parametric(problem, options=resolve_options(problem,
                                                                                arith=arith))
        per_tick = fixed_point_certificate(problem, tick_pd.table, tick_pf)["corridors"][0]
        assert got["cantelli"]["worst_tick"] != pytest.approx(
            per_tick["cantelli"].worst_tick, rel=1e-6)
    assert fixed["over_box"]["bands"] == [] and captured.err == ""


def test_a_band_row_the_fixed_point_table_does_not_certify_is_noted(capsys):
    """The drone's region touches its ceiling at a vertex of the box (designed so): the Q15
    error bound takes it beyond, so the summary says it does not hold and stderr says so."""
    assert main(["design", str(EXAMPLES / "drone_gates.toml"), "--arith", "q15", "--json"]) == 0
    captured = capsys.readouterr()
    band, = json.loads(captured.out)["fixed"]["over_box"]["bands"]
    assert band["field"] == "regions[0]" and not band["holds"] and band["worst_margin"] < -1e-3
    note, = captured.err.strip().splitlines()
    assert note.startswith("stospline: note: regions[0] row 0 is not certified for the Q15")


def test_fixed_point_columns_out_of_scale_are_refused_naming_the_range(tmp_path, capsys):
    doc = (EXAMPLES / "robot_goal.toml").read_text()
    bad = tmp_path / "wide.toml"
    bad.write_text(doc.replace("range = [-1.5, -0.5]", "range = [-1e30, 1e30]"))
    out = tmp_path / "out"
    assert main(["design", str(bad), "--arith", "q31", "--out", str(out)]) == 2
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert len(err.splitlines()) == 1 and "parameters[0].range: " in err, err
    assert captured.out == "" and not out.exists()


def test_design_table_spline_writes_the_spline_parametric_controller(tmp_path, capsys):
    """`--table spline`: the spline gain table and its spline columns, byte for byte the
    shipped gains/ (tools/params_tables.py --spline, the same code), and in the summary's
    ``table`` what the table as flashed guarantees over the box: `certify_over_box` of the
    spline parametric table made apart (`spline_parametric_of`, its own spline fit)."""
    summary, captured = _design_as_shipped(tmp_path, capsys, "robot_goal_spline",
                                           "--table", "spline")
    assert summary["parameters"][1]["name"] == "goal_y" and captured.err == ""
    problem = load_problem(EXAMPLES / "robot_goal.toml")
    want = certify_over_box(problem, spline_parametric_of(problem),
                            keys=("spline", "per_tick_float32"))
    got = summary["table"]["over_box"]
    assert np.ravel(got["column_error"]) == pytest.approx(np.ravel(want["column_error"]),
                                                          rel=1e-4)
    worst = got["corridors"][0]["worst_tick"]
    assert worst == pytest.approx(want["spline"]["corridors"][0]["worst_tick"], rel=1e-9)
    # the flashed table's, not the per-tick float32 table's (they differ in the 8th digit)
    assert worst != pytest.approx(want["per_tick_float32"]["corridors"][0]["worst_tick"],
                                  rel=1e-9)
    assert got["bands"] == [] and got["bands_hold"] is True


def test_a_table_without_columns_is_refused_in_one_line(tmp_path, capsys):
    """Refused before any work, naming the option given (else the file's field)."""
    out = tmp_path / "out"
    varying = tmp_path / "varying.toml"          # a time-varying rate: no spline columns
    varying.write_text((EXAMPLES / "investment.toml").read_text() + """
[[parameters]]
name = "goal"
sets = ["knots[1].constraint.value[0]", "knots[1].penalty.target[0]"]
range = [90.0, 110.0]
""")
    goal = str(EXAMPLES / "robot_goal.toml")
    for problem, extra, named in (
            (goal, ["--table", "spline", "--delay-ticks", "1"], "--delay-ticks: "),
            (goal, ["--arith", "q15", "--table", "spline", "--delay-ticks", "1"],
             "--delay-ticks: "),
            (str(varying), ["--table", "spline"], "stages[0]: "),
            (str(varying), ["--arith", "q31", "--table", "spline"], "stages[0]: ")):
        assert main(["design", problem, "--out", str(out), *extra]) == 2
        captured = capsys.readouterr()
        err = captured.err.strip()
        assert len(err.splitlines()) == 1 and named in err, err
        assert captured.out == "" and not out.exists()
    assert main(["design", str(varying), "--out", str(out)]) == 0      # per-tick columns


@pytest.mark.parametrize("extra, blocked", [
    ([], "robot_goal_params.c"), (["--arith", "q15"], "robot_goal_q15_params.h"),
    (["--table", "spline"], "robot_goal_spline_params.c"),
    (["--arith", "q15", "--table", "spline"], "robot_goal_q15_spline_params.c")])
def test_all_files_or_none(tmp_path, capsys, extra, blocked):
    """A parameter file's target that cannot be replaced: nothing written, status 2."""
    out = tmp_path / "out"
    out.mkdir()
    (out / blocked).mkdir()
    assert main(["design", str(EXAMPLES / "robot_goal.toml"), "--out", str(out), *extra]) == 2
    captured = capsys.readouterr()
    assert blocked in captured.err and captured.out == ""
    assert sorted(p.name for p in out.iterdir()) == [blocked]
