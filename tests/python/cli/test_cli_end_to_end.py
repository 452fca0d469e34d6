"""The CLI end to end, as a user runs it."""
import json
import subprocess
import sys

import pytest

from conftest import EXAMPLES

ROBOT = str(EXAMPLES / "robot_corridor.toml")


def run(*args):
    return subprocess.run([sys.executable, "-m", "stospline.cli", *args],
                          capture_output=True, text=True)


def test_design_json_summary(robot_zoh):
    r = run("design", ROBOT, "--json")
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    assert s["design"] == "stagewise-exact-zoh"
    assert s["J0"] == pytest.approx(robot_zoh.design.J0, rel=1e-11)
    assert s["oracle_J_design"] == pytest.approx(s["J0"], rel=1e-10)
    assert len(s["knots"]) == 2
    for k, kn in enumerate(s["knots"]):
        assert len(kn["mean"]) == 4 and len(kn["cov"]) == 4
        assert max(abs(v) for v in kn["constraint"]["design_violation"]) < 1e-9


def test_simulate_json_reports_ci_and_bias():
    r = run("simulate", ROBOT, "--paths", "300", "--seed", "3", "--json")
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    lo, hi = s["cost"]["ci95"]
    assert lo < s["cost"]["mc_mean"] < hi
    assert s["worst_status"] == 0 and s["paths"] == 300
    assert abs(s["simulation_bias"]["cost_over_stderr"]) < 0.05
    assert len(s["knots"][1]["mc_cov"]) == 4


def test_plot_writes_png(tmp_path):
    out = tmp_path / "fig.png"
    r = run("plot", ROBOT, "--out", str(out), "--paths", "20")
    assert r.returncode == 0, r.stderr
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_missing_file_exits_2(tmp_path):
    r = run("design", str(tmp_path / "nope.toml"), "--out", str(tmp_path / "o"))
    assert r.returncode == 2
    assert not (tmp_path / "o").exists()
