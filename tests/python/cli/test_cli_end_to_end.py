"""The CLI end to end, as a user runs it."""
import json
import subprocess
import sys
from statistics import NormalDist

import numpy as np
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


def test_simulate_agrees_with_the_oracle_of_the_table(robot_zoh):
    """`simulate` runs the compiled C controller in Monte Carlo. Its mean cost and knot means
    must match the exact oracle of the same float32 table, computed here through the library
    (not read back from the JSON), within 99.9 % jointly (Bonferroni over the cost and the 8
    knot-mean components) at a fixed seed: the cost against the sample's standard error, each
    knot mean against the oracle's own covariance over the number of paths."""
    paths = 2000
    r = run("simulate", ROBOT, "--paths", str(paths), "--seed", "3", "--json")
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    assert s["worst_status"] == 0 and s["paths"] == paths
    oracle = robot_zoh.implemented
    z = NormalDist().inv_cdf(1 - 0.001 / 2 / (1 + 2 * 4))
    assert abs(s["cost"]["mc_mean"] - oracle.J) <= z * s["cost"]["mc_stderr"], (s["cost"], oracle.J)
    for k, kn in enumerate(s["knots"]):
        stderr = np.sqrt(np.diag(oracle.knot_cov[k]) / paths)
        assert np.all(np.abs(np.array(kn["mc_mean"]) - oracle.knot_mean[k]) <= z * stderr), \
            (k, kn["mc_mean"], oracle.knot_mean[k], stderr)
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


def test_simulate_check_exit_status(tmp_path):
    """`--check`: status 0 when the run agrees with the oracle, 3 when it cannot (here the
    actuators saturate, so the oracle does not predict the run); the verdict line either way."""
    r = run("simulate", ROBOT, "--paths", "300", "--seed", "2", "--check")
    assert r.returncode == 0, r.stdout + r.stderr
    assert "verdict: agree" in r.stdout
    limited = tmp_path / "limited.toml"
    limited.write_text(open(ROBOT).read().replace("tick_hz", "u_max = 0.3\ntick_hz", 1))
    r = run("simulate", str(limited), "--paths", "300", "--seed", "2", "--check")
    assert r.returncode == 3, r.stdout + r.stderr
    assert "verdict: DISAGREE" in r.stdout and "saturated" in r.stdout
    r = run("simulate", str(limited), "--paths", "300", "--seed", "2")
    assert r.returncode == 0, r.stderr            # without --check: the numbers, status 0
    s = json.loads(run("simulate", ROBOT, "--paths", "300", "--json").stdout)
    assert s["verdict"]["agree"] is True and s["simulation_bias"]["substeps_chosen"] == "auto"


ONE_STATE = """
name = "growth"
t0 = 0.0
x0 = [1.0]
tick_hz = 100
[dynamics]
A = [[0.05]]
B = [[1.0]]
noise = [{ state = 0, G = [[0.2]] }]
[cost]
Q = [[0.0]]
R = [[1.0]]
[[knots]]
t = 1.0
constraint = { C = [[1.0]], value = [1.5] }
"""


@pytest.mark.parametrize("text", [
    ONE_STATE,                                                      # by default, n = 1
    open(ROBOT).read().replace("axes = [0, 2]", "axes = [2]", 1),   # one chosen state
], ids=["one state", "axes = [2]"])
def test_plot_one_state_against_time(tmp_path, text):
    """A problem with a single state (e.g. wealth under geometric noise) plots that state
    against time instead of failing on the default phase-plane axes; so does `axes = [i]`."""
    f = tmp_path / "p.toml"
    f.write_text(text)
    out = tmp_path / "p.png"
    r = run("plot", str(f), "--out", str(out), "--paths", "20")
    assert r.returncode == 0, r.stderr
    assert out.stat().st_size > 10_000 and out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_plot_axes_must_be_one_or_two_states(tmp_path):
    f = tmp_path / "p.toml"
    f.write_text(ONE_STATE + "[plot]\naxes = [0, 1]\n")
    r = run("plot", str(f), "--out", str(tmp_path / "p.png"))
    assert r.returncode == 2 and "plot.axes" in r.stderr and "one or two" in r.stderr
    assert not (tmp_path / "p.png").exists()


def test_simulate_on_a_local_dask_cluster_gives_the_same_numbers():
    """`--scheduler local`: the blocks on a local Dask cluster; the summary is the one of the
    run without it."""
    args = ["simulate", ROBOT, "--paths", "1500", "--seed", "5", "--substeps", "1", "--json"]
    plain = json.loads(run(*args).stdout)
    r = run(*args, "--scheduler", "local", "--workers", "2")
    assert r.returncode == 0, r.stderr
    dask = json.loads(r.stdout)
    assert dask["cost"] == plain["cost"] and dask["knots"] == plain["knots"]
