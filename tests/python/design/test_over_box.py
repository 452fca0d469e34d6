"""Guarantees over the parameter box (`stospline.oracle.over_box`): the moments as exact affine
and quadratic forms of the parameters, every-tick regions designed to hold at every vertex
of the box (and refused, naming the region and the parameter, when the box is too wide),
and corridor exit bounds that cover every vertex. Each check compares with the oracle run
at the parameters themselves, and each has a case where the nominal alone would be wrong."""
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

from conftest import EXAMPLES
from stospline.design.sensitivity import source_designs
from stospline.design.tick_qp import design_tick_qp
from stospline.errors import DesignError
from stospline.oracle.evaluate import evaluate_table
from stospline.oracle.exit_bound import exit_bounds, exit_bounds_over_box
from stospline.oracle.over_box import band_margins, box_moments, vertices
from stospline.oracle.parametric import design_parametric, evaluate_at
from stospline.problem import parse_problem
from stospline.problem.parameters import problem_at
from stospline.table.parametric import parametric_table

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "problem"))
from test_parameters import base_doc  # noqa: E402

SEED = 20261128


def cart(upper: float):
    """The cart of test_parameters (six parameters: a constraint value, targets, both drifts
    and x0) with its position at most `upper` in expectation at every tick."""
    doc = base_doc()
    doc["regions"] = [{"t": [0.0, 2.0], "every": "tick", "C": [[1, 0]], "lower": [-10.0],
                       "upper": [upper]}]
    return parse_problem(doc)


def untightened(p):
    """The parametric table of the tick-grid design with its rows not tightened."""
    hz, stages = design_tick_qp(p).tick_gains()
    return parametric_table(p, hz, stages, source_designs(p, design_tick_qp))


def test_box_moments_are_the_oracles_at_random_parameters():
    p = cart(2.0)
    table = untightened(p)
    box = box_moments(p, table)
    rng = np.random.default_rng(SEED)
    lo, hi = (np.array([getattr(q, k) for q in p.parameters]) for k in ("lower", "upper"))
    for _ in range(3):
        theta = rng.uniform(lo, hi)
        m = evaluate_table(problem_at(p, theta), table.at(theta), path=True,
                           output=np.eye(p.n))
        mean, cov = box.at(theta)
        assert np.abs(mean - m.path_mean).max() <= 1e-9 * max(1, np.abs(m.path_mean).max())
        assert np.abs(cov - m.path_y_cov).max() <= 1e-9 * max(1, np.abs(m.path_y_cov).max())
    # Multiplicative noise: the covariance moves with the parameters (not only the mean).
    assert np.abs(box.G).max() > 1e-3 * np.abs(box.cov).max()


def test_region_holds_at_every_vertex_and_the_worst_case_is_exact():
    p = cart(2.0)
    plain = box_moments(p, untightened(p))
    (before,) = band_margins(p, plain)
    assert not before.holds and before.parameter == "mid"     # the nominal alone: violated
    # The predicted worst case is the oracle's at the worst vertex (exact for a box).
    worst = min(min(2.0 - (plain.at(v)[0][1:, 0])) for v in vertices(p.parameters))
    assert abs(worst - before.worst) <= 1e-9
    pd = design_parametric(p, mode="joint")
    assert all(m.holds for m in pd.margins), pd.margins
    for v in vertices(p.parameters):
        for quantize, tol in ((False, 1e-9), (True, 1e-5)):
            x = evaluate_at(p, pd.table, v, path=True, quantize=quantize).path_mean[1:, 0]
            assert x.max() <= 2.0 + tol, (v, quantize, x.max())


def test_a_box_too_wide_for_the_region_is_refused_naming_region_and_parameter():
    # The first knot fixes x(1) = 2 mid, up to 2 at mid = 1: a bound of 1.6 cannot hold.
    with pytest.raises(DesignError) as err:
        design_parametric(cart(1.6), mode="joint")
    assert err.value.field == "regions[0]"
    assert "mid" in err.value.reason and "\n" not in str(err.value)


def drone_doc():
    return tomllib.loads((EXAMPLES / "drone_gates.toml").read_text())


@pytest.fixture(scope="module")
def drone():
    p = parse_problem(drone_doc())
    return p, design_parametric(p, mode="joint")


def test_drone_altitude_band_holds_at_every_gate_vertex(drone):
    p, pd = drone
    (m,) = pd.margins
    assert m.holds and m.nominal > 0.1
    reg = p.tick_regions[0]
    for v in vertices(p.parameters):
        z = evaluate_at(p, pd.table, v, path=True).path_mean[reg.ticks(p.t0, p.tick_hz)] @ reg.C.T
        assert z.min() >= reg.lower[0] - 1e-9 and z.max() <= reg.upper[0] + 1e-9, v


def test_drone_table_and_columns_are_one_design(drone):
    from stospline import design_problem
    p, pd = drone
    table = design_problem(p, mode="joint").table
    q = pd.table.table.quantized()
    for key in ("K", "k0", "L", "Lambda", "lambda0"):
        assert np.array_equal(getattr(table, key), getattr(q, key)), key


def test_corridor_bound_over_the_box_covers_every_vertex(drone):
    p, pd = drone
    c = p.corridors[0]
    over = exit_bounds_over_box(c, pd.box, p.t0, p.tick_hz)
    nominal = exit_bounds(c, pd.box.mean @ c.C.T, c.C @ pd.box.cov @ c.C.T, p.t0, p.tick_hz)
    beyond_nominal = False
    for v in vertices(p.parameters):
        m = evaluate_table(problem_at(p, v), pd.table.at(v), path=True, output=c.C)
        at = exit_bounds(c, m.path_y_mean, m.path_y_cov, p.t0, p.tick_hz)["cantelli"]
        assert np.all(at.per_tick <= over["cantelli"].per_tick + 1e-12), v
        beyond_nominal |= bool(np.any(at.per_tick > nominal["cantelli"].per_tick + 1e-6))
    assert beyond_nominal        # the nominal's bound alone does not cover the box


def test_the_cli_refuses_a_gate_range_beyond_the_ceiling(tmp_path, capsys):
    from stospline.cli import main
    text = (EXAMPLES / "drone_gates.toml").read_text()
    assert text.count("range = [2.1, 3.1]") == 1
    path = tmp_path / "wide.toml"         # gate 2 up to 3.3 m, the ceiling at 3.2 m
    path.write_text(text.replace("range = [2.1, 3.1]", "range = [2.1, 3.3]"))
    out = tmp_path / "out"
    assert main(["design", str(path), "--out", str(out)]) == 2
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert len(err.splitlines()) == 1 and "regions[0]" in err and "gate2_z" in err, err
    assert not out.exists()
