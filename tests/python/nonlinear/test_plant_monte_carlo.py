"""Monte Carlo of the compiled controller on a [plant] model: on a linear model given in C the
plant agrees with the oracle of the same linear problem, knot means, variances and cost, within
joint 99% intervals (fixed seed); the command line's JSON is strict."""
import json

import numpy as np
import pytest

from stospline.cli import main
from stospline.nonlinear.iterate import fit_plant
from stospline.nonlinear.simulate import plant_simulation
from stospline.pipeline import design_problem
from support.plant_sources import LINEAR, LINEAR_TOML, linear_doc


@pytest.fixture(scope="module")
def linear_plant(tmp_path_factory):
    where = tmp_path_factory.mktemp("plant")
    (where / "model.c").write_text(LINEAR)
    problem, fit = fit_plant(linear_doc(), where)
    return where, design_problem(problem), fit.model


def test_a_linear_model_in_c_meets_its_oracle(linear_plant):
    _, d, model = linear_plant
    s = plant_simulation(d, model, paths=4000, seed=35, substeps=8)
    assert s["verdict"]["agree"], s
    # The intervals are not vacuous: narrower than 15 % of the oracle's knot-1 variances, so
    # a noise 10 % too weak (variances 19 % too small) is seen, and the scheme's bias on the
    # cost is below its statistical interval.
    v = np.array(s["knots"][1]["oracle_variance"])
    assert np.all(np.array(s["knots"][1]["variance_halfwidth"]) < 0.15 * v)
    assert s["cost"]["scheme_bias"] < s["cost"]["halfwidth"]


def test_simulate_prints_strict_json(linear_plant, capsys):
    where, _, _ = linear_plant
    import tomllib
    assert tomllib.loads(LINEAR_TOML) == linear_doc()
    (where / "p.toml").write_text(LINEAR_TOML)
    assert main(["simulate", str(where / "p.toml"), "--paths", "50", "--json"]) == 0
    out = capsys.readouterr().out

    def refuse(name):
        raise ValueError(name)
    s = json.loads(out, parse_constant=refuse)
    assert s["plant"]["paths"] == 50 and len(s["knots"]) == 2


def test_workers_that_do_not_apply_to_the_model_are_noted(linear_plant, capsys):
    """The model's run is one process: --workers is said not to spread it (one line on
    stderr), and the numbers are those of the run without it."""
    where, _, _ = linear_plant
    (where / "p.toml").write_text(LINEAR_TOML)
    args = ["simulate", str(where / "p.toml"), "--paths", "50", "--json"]
    assert main(args) == 0
    alone = capsys.readouterr()
    assert main(args + ["--workers", "2"]) == 0
    spread = capsys.readouterr()
    assert spread.out == alone.out
    notes = [ln for ln in spread.err.splitlines() if "[plant] model" in ln]
    assert len(notes) == 1 and "--workers do not spread it" in notes[0], spread.err
    assert "[plant] model" not in alone.err
