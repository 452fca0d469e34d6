"""Strict output: every JSON the tool prints or writes is strict JSON (no
NaN/Infinity), every generated table is finite, and a design whose numbers overflow float32 or
the fixed-point scales is refused with exit 2, one line naming the cause, and nothing written.
Numpy's RuntimeWarnings never reach the user."""
import json
import re
import subprocess
import sys

import numpy as np
import pytest

from conftest import REPO
from stospline.problem import ProblemError, parse_problem
from stospline.strict import check_table_finite, dumps, ratio_or_null


def minimal_file() -> str:
    """The docs' own minimal file (docs/guide/problem-file.md): a cart without noise."""
    text = (REPO / "docs" / "guide" / "problem-file.md").read_text()
    m = re.search(r"```toml\n(# complete file: the minimal file.*?)```", text, re.S)
    return m.group(1)


def variant(**subs) -> str:
    """The minimal file with some lines replaced: {old line start: new line}."""
    lines = minimal_file().splitlines()
    for old, new in subs.items():
        i = next(i for i, line in enumerate(lines) if line.startswith(old))
        lines[i] = new
    return "\n".join(lines) + "\n"


def run(*args):
    return subprocess.run([sys.executable, "-m", "stospline.cli", *args],
                          capture_output=True, text=True)


def strict_json(text: str):
    """json.loads that refuses NaN, Infinity and -Infinity, as strict parsers do."""
    def refuse(token):
        raise ValueError(f"non-standard JSON constant {token}")
    return json.loads(text, parse_constant=refuse)


def assert_refused(r, out, field, *words):
    assert r.returncode == 2, r.stdout + r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr                     # one line, no warnings, no traceback
    assert f": {field}: " in lines[0], lines[0]
    for w in words:
        assert w in lines[0], lines[0]
    assert not out.exists()


@pytest.mark.parametrize("subs, field, words", [
    # K, Lambda, ... of Q = 1e300 overflow float32: the .c held `inff` and the JSON NaN.
    ({"R = [[1]]": "R = [[1]]\nQ = [[1e300, 0], [0, 1]]"}, "cost.Q", ["overflow"]),
    ({"constraint = { C = [[1, 0]]": "constraint = { C = [[1, 0]], value = [1e308] }"},
     "knots[0].constraint.value", ["not finite"]),
    # The controller measures the state in float32.
    ({"x0 =": "x0 = [1e308, 0.0]"}, "x0[0]", ["float32"]),
])
def test_overflowing_design_is_refused_before_writing(tmp_path, subs, field, words):
    f = tmp_path / "p.toml"
    f.write_text(variant(**subs))
    out = tmp_path / "out"
    assert_refused(run("design", str(f), "--out", str(out)), out, field, *words)
    r = run("design", str(f), "--json")
    assert r.returncode == 2 and r.stdout == ""


def test_fixed_point_scale_overflow_is_refused(tmp_path):
    """Q = 1e30 fits float32 but no Q15 scale (exponent beyond STSP_Q_EXP_MAX): was a
    ValueError traceback."""
    f = tmp_path / "p.toml"
    f.write_text(variant(**{"R = [[1]]": "R = [[1]]\nQ = [[1e30, 0], [0, 1]]"}))
    out = tmp_path / "out"
    assert_refused(run("design", str(f), "--arith", "q15", "--out", str(out)), out, "cost.Q",
                   "STSP_Q_EXP_MAX")


def test_state_that_stays_zero_gets_a_fixed_point_scale(tmp_path):
    """A state never driven and without noise has predicted range 0: it takes the smallest
    scale instead of failing."""
    f = tmp_path / "p.toml"
    f.write_text(variant(**{
        "x0 =": "x0 = [0.0, 0.0, 0.0]", "A =": "A = [[0, 1, 0], [0, 0, 0], [0, 0, 0]]",
        "B =": "B = [[0], [1], [0]]",
        "constraint = { C = [[1, 0]]": "constraint = { C = [[1, 0, 0]], value = [1.0] }",
        "constraint = { C = [[1, 0], [0, 1]]":
            "constraint = { C = [[1, 0, 0], [0, 1, 0]], value = [0.0, 0.0] }"}))
    r = run("design", str(f), "--arith", "q15", "--json")
    assert r.returncode == 0 and r.stderr == "", r.stderr
    s = strict_json(r.stdout)
    assert s["fixed"]["x_exp"][2] == s["fixed"]["x_exp"][0] - 24


def test_noise_free_simulation_json_is_strict(tmp_path):
    """The minimal file has no noise: every path is the same, the standard errors are 0 and
    the z-scores undefined. They are null with a reason (not Infinity); nothing on stderr (no
    numpy RuntimeWarning)."""
    f = tmp_path / "cart.toml"
    f.write_text(minimal_file())
    r = run("simulate", str(f), "--paths", "50", "--json")
    assert r.returncode == 0, r.stderr
    assert r.stderr == ""
    s = strict_json(r.stdout)
    assert s["cost"]["z"] is None and "standard error is 0" in s["cost"]["z_undefined"]
    assert s["simulation_bias"]["cost_over_stderr"] is None
    assert "cost_over_stderr_undefined" in s["simulation_bias"]
    for kn in s["knots"]:
        assert kn["z"] == [None, None] and kn["z_undefined"]
    # The text report says n/a for them.
    r = run("simulate", str(f), "--paths", "50")
    assert r.returncode == 0 and r.stderr == "" and "z [n/a, n/a]" in r.stdout


def test_simulation_from_a_huge_start_is_finite_or_refused(tmp_path):
    """--x0=1e30,0 died in ZeroDivisionError; beyond float32 it is one line, exit 2."""
    f = tmp_path / "cart.toml"
    f.write_text(minimal_file())
    r = run("simulate", str(f), "--paths", "20", "--json", "--x0=1e30,0")
    assert r.returncode == 0 and r.stderr == "", r.stderr
    s = strict_json(r.stdout)
    assert s["cost"]["z"] is None and np.isfinite(s["cost"]["mc_mean"])
    r = run("simulate", str(f), "--paths", "20", "--json", "--x0=1e39,0")
    assert r.returncode == 2 and r.stdout == ""
    assert len(r.stderr.strip().splitlines()) == 1 and "float32" in r.stderr


def test_dumps_refuses_nan_so_no_regression_slips_through():
    assert dumps({"a": [1.0, None]}) == json.dumps({"a": [1.0, None]}, indent=2, sort_keys=True)
    for bad in (float("nan"), float("inf"), -float("inf")):
        with pytest.raises(ValueError):
            dumps({"a": bad})


def test_ratio_or_null():
    assert ratio_or_null(1.0, 2.0, "why") == (0.5, None)
    assert ratio_or_null(1.0, 0.0, "why") == (None, "why")
    assert ratio_or_null([1.0, 2.0], [0.0, 4.0], "why") == ([None, 0.5], "why")


def test_check_table_finite_names_the_entry(robot_zoh):
    """A table with one overflowing float32 gain is refused, the tick named."""
    K = robot_zoh.table.K.copy()
    K[7, 1, 2] = np.inf
    bad = robot_zoh.table.with_arrays(K=K)
    with pytest.raises(ProblemError, match="tick 7"):
        check_table_finite(robot_zoh.problem, bad)
    check_table_finite(robot_zoh.problem, robot_zoh.table)


def test_every_shipped_json_is_strict():
    for path in sorted((REPO / "gains").glob("*.json")):
        strict_json(path.read_text())


def test_minimal_file_parses():
    import tomllib
    assert parse_problem(tomllib.loads(minimal_file())).name == "cart"


def test_codegen_never_writes_a_non_finite_literal(robot_zoh):
    """Last line of defence behind the pipeline's check: `inff` never reaches a .c file."""
    from stospline.table.codegen import generate_c
    k0 = robot_zoh.table.k0.copy()
    k0[3, 0] = np.nan
    with pytest.raises(ValueError, match="finite"):
        generate_c(robot_zoh.table.with_arrays(k0=k0))
