"""Faults around a [plant] model: on the linear model written in C, the model's run with faults
gives the linear harness's numbers with the same faults (knot means and cost, within joint 99 %
Monte Carlo intervals widened by each scheme's bias; fixed seeds), and the fault-free harness
run is told apart by the same comparison; the verdict compares with the fault oracle of the
linearisation; faults a model cannot take, and bad fault values, are refused in one line with
exit 2 before any run; the unicycle runs with sensor noise and shows the fault oracle."""
import json

import numpy as np
import pytest
from conftest import EXAMPLES

from stospline.cli import main
from stospline.harness.montecarlo import z_value
from stospline.harness.plant_scheme import scheme_moments
from stospline.nonlinear.iterate import fit_plant
from stospline.nonlinear.simulate import plant_simulation, plant_simulation_text
from stospline.pipeline import design_problem, simulate_problem
from stospline.problem.faults import Faults, parse_faults
from stospline.problem.reader import parse_problem
from stospline.problem.toml_writer import document_to_toml
from stospline.report.simulation_summary import loop_moments
from support.plant_sources import LINEAR, linear_doc, the_same_linear_doc

PATHS, SUBSTEPS = 4000, 16
EXACT = {"sensor_noise": 0.05, "actuator_noise": 0.5, "delay_ticks": 1}
NOT_EXACT = {"miss_probability": 0.3, "sensor_quantum": 0.1, "actuator_noise": 0.5}


@pytest.fixture(scope="module")
def both(tmp_path_factory):
    """The double integrator as a [plant] in C (designed on its linearisation) and as a linear
    problem (designed as such)."""
    where = tmp_path_factory.mktemp("plant")
    (where / "model.c").write_text(LINEAR)
    problem, fit = fit_plant(linear_doc(), where)
    return (where, design_problem(problem), fit.model,
            design_problem(parse_problem(the_same_linear_doc())))


def _linear_run(d, faults: Faults, seed: int) -> dict:
    """The linear harness's knot means and cost with their standard errors and the exact
    bias of its plant scheme."""
    mc = simulate_problem(d, paths=PATHS, seed=seed, substeps=SUBSTEPS, faults=faults,
                          workers=1)
    scheme = scheme_moments(d.problem, d.table, SUBSTEPS, faults)
    exact = loop_moments(d, faults)
    mean, hw = mc.cost_mean_ci(0.95)
    out = {"cost": (mean, hw / z_value(0.95), abs(scheme.J - exact.J)), "knots": []}
    for k in range(len(d.problem.knots)):
        m, se = mc.knot_mean_se(k)
        out["knots"].append((m, se, np.abs(scheme.knot_mean[k] - exact.knot_mean[k])))
    return out


def _alike(plant: dict, linear: dict) -> bool:
    """Whether the model's run and the harness's agree on every knot mean component and the
    cost: jointly at 99 % (Bonferroni), each difference within its interval widened by both
    schemes' biases."""
    n, K = len(plant["knots"][0]["mean"]), len(plant["knots"])
    z_plant = z_value(0.99, 2 * n * K + 1)         # the plant summary's half-widths
    z = z_value(0.99, n * K + 1)
    c = plant["cost"]
    m, se, bias = linear["cost"]
    ok = abs(c["mc"] - m) <= z * np.hypot(c["halfwidth"] / z_plant, se) + c["scheme_bias"] + bias
    for kn, (m, se, bias) in zip(plant["knots"], linear["knots"]):
        se_p = np.array(kn["mean_halfwidth"]) / z_plant
        ok &= bool(np.all(np.abs(np.array(kn["mean"]) - m)
                          <= z * np.hypot(se_p, se) + np.array(kn["scheme_bias"]) + bias))
    return bool(ok)


@pytest.mark.parametrize("raw", [EXACT, NOT_EXACT], ids=["linear_faults", "nonlinear_faults"])
def test_the_model_with_faults_is_the_linear_harness_with_them(both, raw):
    _, dp, model, dl = both
    faults = parse_faults(raw, 2, 1)
    s = plant_simulation(dp, model, paths=PATHS, seed=35, substeps=SUBSTEPS, faults=faults)
    assert s["faults"]["levels"] == faults.as_dict()
    assert _alike(s, _linear_run(dl, faults, seed=36)), s
    # The comparison sees the faults: the harness without them is told apart.
    assert not _alike(s, _linear_run(dl, Faults(), seed=36))
    if faults.exact:
        # The verdict is against the fault oracle, which is not the fault-free one.
        assert s["verdict"]["agree"], s
        assert s["cost"]["oracle"] == s["faults"]["oracle_cost"]
        assert abs(s["faults"]["oracle_cost"] - s["faults"]["nominal_cost"]) \
            > 5 * s["cost"]["halfwidth"]
    else:
        assert not s["verdict"]["agree"] and "not comparable" in s["verdict"]["reason"]


def _refusal(capsys, argv) -> str:
    rc = main(argv)
    err = capsys.readouterr().err
    assert rc == 2 and len(err.strip().splitlines()) == 1, err
    return err


@pytest.mark.parametrize("faults, option, field", [
    ({}, ["--fault", "sensor_noise=-1"], "--fault sensor_noise:"),
    ({"actuator_noise": [0.1, 0.2]}, [], "faults.actuator_noise:"),
    ({}, ["--fault", "plant_A_scale=1.1"], "--fault plant_A_scale:"),
    ({"plant_B_scale": 0.9}, [], "faults.plant_B_scale:"),
    ({"plant_B_scale": 0.9}, ["--fault", "sensor_noise=0.1"], "faults.plant_B_scale:"),
])
def test_bad_or_linear_only_faults_are_refused_before_any_run(both, capsys, faults, option,
                                                              field):
    where = both[0]
    doc = linear_doc()
    if faults:
        doc["faults"] = faults
    (where / "f.toml").write_text(document_to_toml(doc))
    err = _refusal(capsys, ["simulate", str(where / "f.toml"), "--paths", "50", *option])
    assert field in err
    out = where / "r.html"
    err = _refusal(capsys, ["report", str(where / "f.toml"), "--paths", "50", "--out", str(out),
                            *option])
    assert field in err and not out.exists()


def test_the_report_shows_the_faults_around_the_model(both, capsys):
    where = both[0]
    doc = linear_doc()
    doc["faults"] = {"sensor_noise": 0.05}
    (where / "g.toml").write_text(document_to_toml(doc))
    page = where / "g.html"
    assert main(["report", str(where / "g.toml"), "--paths", "200", "--substeps", "4",
                 "--fault-paths", "0", "--out", str(page)]) == 0
    text = page.read_text()
    assert 'id="plant-faults"' in text and "fault oracle of the linearisation" in text


def test_the_unicycle_with_sensor_noise_shows_the_fault_oracle(capsys):
    argv = ["simulate", str(EXAMPLES / "nonlinear" / "robot_unicycle.toml"), "--paths", "40",
            "--substeps", "auto", "--fault", "sensor_noise=0.01"]
    assert main(argv + ["--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    f = s["faults"]
    assert f["levels"] == {"sensor_noise": [0.01] * 4} and f["exact_oracle"]
    assert s["cost"]["oracle"] == f["oracle_cost"] != f["nominal_cost"]
    text = plant_simulation_text(s)
    assert "sensor_noise=" in text and "fault oracle of the linearisation" in text
    # The substeps were decided on the model: the first count whose bias bound met the target.
    p = s["plant"]
    assert p["substeps_chosen"] == "auto" and p["substeps"] == p["tried"][-1]["substeps"]
    assert p["tried"][-1]["bias_over_stderr"] <= p["tolerance"]
    assert all(e["bias_over_stderr"] > p["tolerance"] for e in p["tried"][:-1])
