"""The fault table of a [plant] problem runs on the model: on the linear model written in C
every row is the linear harness's row of the same linear problem, seed and faults, to rounding
(the model's run is the harness's paths); the row the model cannot take (the plant's B scaled)
is left out with its reason, and every level of the standard sweep is a row or left out."""
import pytest

from stospline.harness.controller import build_controller
from stospline.harness.fault_sweep import SWEEP_ROWS, fault_table
from stospline.nonlinear.fault_sweep import model_fault_table
from stospline.nonlinear.iterate import fit_plant
from stospline.pipeline import design_problem
from stospline.problem.reader import parse_problem
from support.plant_sources import LINEAR, linear_doc, the_same_linear_doc

PATHS, SUBSTEPS, SEED = 600, 2, 11      # two blocks of paths, the last one short
RTOL = 1e-9                             # the same paths: sums in another order


@pytest.fixture(scope="module")
def tables(tmp_path_factory):
    """The fault tables of the double integrator as a [plant] in C (on the model) and as a
    linear problem (on the linear harness)."""
    where = tmp_path_factory.mktemp("plant")
    (where / "model.c").write_text(LINEAR)
    problem, fit = fit_plant(linear_doc(), where)
    on_model = model_fault_table(design_problem(problem), fit.model, paths=PATHS, seed=SEED,
                                 substeps=SUBSTEPS)
    dl = design_problem(parse_problem(the_same_linear_doc()))
    linear = fault_table(dl.problem, build_controller(dl.table), paths=PATHS, seed=SEED,
                         substeps=SUBSTEPS, workers=1)
    return on_model, linear


def test_every_level_is_a_row_or_left_out_with_its_reason(tables):
    (rows, left_out), linear = tables
    assert len(rows) + len(left_out) == SWEEP_ROWS == len(linear)
    assert [(r.fault, r.level) for r in left_out] == [("model mismatch", "B x 0.9")]
    assert left_out[0].reason.startswith("plant_B_scale does not apply to a [plant] model")
    assert [(r.fault, r.level) for r in rows] == [
        (r.fault, r.level) for r in linear if r.faults.plant_B_scale == 1.0]


def test_the_model_rows_are_the_linear_harness_rows(tables):
    (rows, _), linear = tables
    by_name = {(r.fault, r.level): r for r in linear}
    for r in rows:
        h = by_name[(r.fault, r.level)]
        assert r.faults.as_dict() == h.faults.as_dict()
        assert r.mc_cost == pytest.approx(h.mc_cost, rel=RTOL)
        assert r.mc_cost_hw95 == pytest.approx(h.mc_cost_hw95, rel=1e-6)
        assert r.mc_knot_variance == pytest.approx(h.mc_knot_variance, rel=RTOL)
        assert r.mc_constraint_bias == pytest.approx(h.mc_constraint_bias, rel=1e-6, abs=1e-12)
        assert r.saturation == h.saturation and r.paths == h.paths == PATHS
        for mine, theirs in ((r.oracle_cost, h.oracle_cost),
                             (r.oracle_knot_variance, h.oracle_knot_variance)):
            assert (mine is None) == (theirs is None)
            assert mine is None or mine == pytest.approx(theirs, rel=1e-9)
    # The faults change the numbers: the rows are not the fault-free run repeated.
    assert len({round(r.mc_cost, 9) for r in rows}) > len(rows) // 2
