"""``stospline report`` of a [plant] problem: the page shows the Monte Carlo on the model
itself (the numbers of `plant_simulation` with the same paths and seed) beside the
linearisation's, and the fault table on the model with the row it cannot run named; a fault
the model cannot take is refused before any run."""
import re

import pytest

from stospline.cli import main
from stospline.harness.fault_sweep import SWEEP_ROWS
from stospline.nonlinear.iterate import fit_plant
from stospline.nonlinear.simulate import plant_simulation
from stospline.pipeline import design_problem
from stospline.problem.toml_writer import document_to_toml
from support.plant_sources import LINEAR, linear_doc


@pytest.fixture
def plant_file(tmp_path):
    (tmp_path / "model.c").write_text(LINEAR)
    (tmp_path / "p.toml").write_text(document_to_toml(linear_doc()))
    return tmp_path


def test_the_report_shows_the_model_run(plant_file):
    page = plant_file / "r.html"
    assert main(["report", str(plant_file / "p.toml"), "--paths", "300", "--seed", "7",
                 "--substeps", "4", "--fault-paths", "100",
                 "--out", str(page)]) == 0
    text = page.read_text()
    assert 'id="plant-table"' in text and "runs against the model itself" in text
    problem, fit = fit_plant(linear_doc(), plant_file)
    s = plant_simulation(design_problem(problem), fit.model, paths=300, seed=7, substeps=4)
    shown = float(re.search(r'id="plant-cost">([^<]+)<', text).group(1))
    assert shown == pytest.approx(s["cost"]["mc"], rel=1e-5)
    # A linear model in C: the model agrees with its linearisation's oracle.
    assert s["verdict"]["agree"] and 'id="plant-verdict">On the model: the Monte Carlo agrees' \
        in text
    # The fault table on the model: every level of the sweep but the one it cannot run.
    assert 'id="fault-table-model"' in text and 'id="no-fault-table"' not in text
    table = re.search(r'<table id="fault-table">(.*?)</table>', text, flags=re.S).group(1)
    assert len(re.findall(r"<tr>", table)) == 1 + SWEEP_ROWS - 1
    assert "Left out: model mismatch (B x 0.9): plant_B_scale does not apply" in text


def test_a_linear_only_fault_is_refused_before_any_run(plant_file, capsys):
    doc = linear_doc()
    doc["faults"] = {"plant_B_scale": 0.9}
    (plant_file / "p.toml").write_text(document_to_toml(doc))
    rc = main(["report", str(plant_file / "p.toml"), "--paths", "300",
               "--out", str(plant_file / "r.html")])
    err = capsys.readouterr().err
    assert rc == 2 and ": faults.plant_B_scale:" in err and len(err.strip().splitlines()) == 1
    assert not (plant_file / "r.html").exists()
