"""``stospline corridor-design`` on a [plant] model (the unicycle at 200 Hz, one grid point,
few paths): the certificate counts the exits of the compiled controller on the C model itself,
the written problem file and model copy reproduce the written tables, and a corridor too
narrow for the plant's spread is not certified."""
import copy
import json
import tomllib

import numpy as np
import pytest

from stospline.cli import main
from stospline.harness.controller import build_controller
from stospline.harness.user_plant import simulate_model
from stospline.nonlinear.iterate import load_plant_problem
from stospline.pipeline import design_problem
from stospline.problem.toml_writer import document_to_toml

from conftest import EXAMPLES

SEARCH = ["--epsilon", "0.4", "--search", "30", "--certify", "30", "--strip", "0",
          "--rate", "0"]


def _unicycle(where, narrow: bool = False):
    doc = tomllib.loads((EXAMPLES / "nonlinear" / "robot_unicycle.toml").read_text())
    doc["tick_hz"] = 200
    if narrow:        # 0.3 either side of the legs' centre lines: the spread is ~0.3 there
        doc["corridors"][0]["polygons"] = [
            {"A": [[0, -1], [0, 1], [1, 0]], "b": [-0.7, 1.3, 0]},
            {"A": [[-1, 0], [1, 0], [0, -1]], "b": [1.3, -0.7, 0]}]
    (where / "unicycle.c").write_bytes((EXAMPLES / "nonlinear" / "unicycle.c").read_bytes())
    path = where / "u.toml"
    path.write_text(document_to_toml(doc))
    return path


@pytest.fixture(scope="module")
def certified(tmp_path_factory):
    where = tmp_path_factory.mktemp("corridor")
    path = _unicycle(where)
    assert main(["corridor-design", str(path), *SEARCH, "--out", str(where / "out"),
                 "--json"]) == 0
    return where / "out", json.loads((where / "out" / "robot_unicycle_corridor.json")
                                     .read_text())


def test_the_certificate_counts_exits_on_the_model(certified):
    out, cert = certified
    c = cert["chosen"]
    assert cert["meets_epsilon"] and c["certification"]["upper99"] <= 0.4
    assert cert["plant"]["source"] == "robot_unicycle_plant.c"
    assert "against the [plant] model" in cert["method"]
    # The written file (with its model copy) is what the tables were designed from ...
    problem, fit = load_plant_problem(out / "robot_unicycle.toml")
    assert problem.source_sha256 == c["problem_sha256"]
    d = design_problem(problem)
    # ... and the certification's count is the model's: the same paths again.
    run = simulate_model(problem, build_controller(d.table), fit.model, paths=30,
                         seed=c["certification"]["seed"], substeps=1)
    assert int(np.sum(run.exits[0] >= 0)) == c["certification"]["exits"]


def test_the_written_tables_are_those_of_the_written_file(certified, tmp_path):
    out, _ = certified
    assert main(["design", str(out / "robot_unicycle.toml"), "--out", str(tmp_path)]) == 0
    for suffix in (".c", ".h"):
        assert (tmp_path / f"robot_unicycle{suffix}").read_bytes() == \
            (out / f"robot_unicycle{suffix}").read_bytes()


def test_a_corridor_too_narrow_for_the_plant_is_not_certified(tmp_path, capsys):
    path = _unicycle(tmp_path, narrow=True)
    rc = main(["corridor-design", str(path), *SEARCH, "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert rc == 2 and "corridors[0].epsilon" in err, err
    assert not (tmp_path / "out").exists()
