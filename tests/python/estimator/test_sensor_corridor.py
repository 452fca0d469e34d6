"""Corridors and every-tick regions with the estimator in the loop: the mean path of
the sensor loop is the full-state one at every tick (so every-tick regions hold), the corridor's
exit bounds come from the true state's exact spread under the sensor loop (larger than the
full-state one), the C harness of the sensor loop counts the true state's exits, and
corridor-design screens and certifies on that loop."""
import copy
import json

import numpy as np
import pytest

from stospline.cli import main
from stospline.corridor_search import _outputs
from stospline.estimator.ctable import estimator_table
from stospline.estimator.oracle import evaluate_estimator
from stospline.harness.estimator_loop import build_estimator_controller, simulate_estimator
from stospline import load_problem
from stospline.harness.estimator_run import (count_sensor_exits, sensor_outputs,
                                              sensor_path_mean)
from stospline.harness.exit_stats import clopper_pearson_lower
from stospline.oracle.evaluate import evaluate_table
from stospline.oracle.exit_bound import exit_bounds
from stospline.options import DesignOptions
from stospline.pipeline import design_problem
from stospline.problem.reader import parse_problem
from stospline.refine.every_tick import every_tick_check
from stospline.report.design_summary import design_summary
from stospline.table.format import table_of

from conftest import EXAMPLES, GAINS
from test_estimator_oracle import DOC

# A 1-D corridor on the position of the small sensed loop (2 s at 20 Hz; the mean runs 0.5 ->
# 1 -> 0, its spread 0.1 -> 0.3), narrow enough that a few per cent of the paths leave it.
UP, LO = 1.45, -0.8
CORRIDOR = {"t": [0.0, 2.0], "C": [[1, 0]], "polygons": [{"A": [[1], [-1]], "b": [UP, -LO]}]}
REGION = {"t": [0.2, 1.6], "every": "tick", "C": [[0, 1]], "lower": [-0.6], "upper": [0.9]}


def _problem(**more):
    doc = copy.deepcopy(DOC)
    doc.update(copy.deepcopy(more))
    return parse_problem({k: v for k, v in doc.items() if v is not None})


@pytest.fixture(scope="module")
def corridor_case():
    problem = _problem(corridors=[CORRIDOR])
    d = design_problem(problem)
    et = estimator_table(problem, d.table)
    # the build cache's copy: the same tables as count_sensor_exits and the CLI runs build
    ctl = build_estimator_controller(problem, d.table, et)
    return problem, d, et, ctl


def test_every_tick_region_holds_for_the_sensor_loop():
    """The filter is unbiased, so the sensor loop's mean path is the full-state loop's at every
    tick: the every-tick region (active: the design sits on its bound) holds for the loop on
    the estimate, to float32 precision with the flashed filter, exactly with the designed one."""
    problem = _problem(regions=[REGION])
    d = design_problem(problem, options=DesignOptions(mode="joint"))
    law = table_of(d.design, quantize=False)
    full = evaluate_table(d.problem, law, path=True).path_mean
    designed = evaluate_estimator(d.problem, law, path=True).moments.path_mean
    np.testing.assert_allclose(designed, full, rtol=0, atol=1e-12)
    flashed = sensor_path_mean(d.problem, d.table)
    scale = 4 * np.finfo(np.float32).eps * max(1.0, np.abs(full).max())
    assert 0 < np.abs(flashed - evaluate_table(d.problem, d.table, path=True).path_mean).max() \
        < scale
    (reg,) = every_tick_check(d, sensor_path=flashed)["regions"]
    assert abs(reg["worst_at_ticks_design"]) < 1e-9          # active
    assert reg["worst_at_ticks_sensor_loop"] < scale
    (shown,) = design_summary(d)["every_tick"]["regions"]     # what `design --json` prints
    assert shown["worst_at_ticks_sensor_loop"] == pytest.approx(
        reg["worst_at_ticks_sensor_loop"], rel=1e-2)            # printed to a few digits
    # without a sensor the entry is absent
    bare = design_problem(_problem(regions=[REGION], measurement=None),
                          options=DesignOptions(mode="joint"))
    assert sensor_path_mean(bare.problem, bare.table) is None
    assert "worst_at_ticks_sensor_loop" not in every_tick_check(bare)["regions"][0]


def test_sensor_outputs_are_the_true_states_with_a_larger_spread(corridor_case):
    """The corridor's output moments of the sensor loop: the full-state mean, the start's
    spread at tick 0, a spread at least the full-state one at every tick (strictly larger
    somewhere), hence a larger Cantelli bound; the corridor search routes to them."""
    problem, d, et, _ = corridor_case
    c = problem.corridors[0]
    J, ym, yc = sensor_outputs(problem, d.table, c.C)
    full = evaluate_table(problem, d.table, path=False, output=c.C)
    np.testing.assert_allclose(ym, full.path_y_mean, rtol=0, atol=1e-6)
    assert yc[0, 0, 0] == pytest.approx(0.01)                  # x0_cov's position variance
    gap = yc[:, 0, 0] - full.path_y_cov[:, 0, 0]
    assert gap.min() > -1e-12 and gap.max() > 0.1 * full.path_y_cov[:, 0, 0].max()
    # the tick-by-tick variance equals the knot's variance of the estimator oracle
    loop = evaluate_estimator(problem, d.table, gains=et.per_tick()[0],
                              predictor=et.per_tick()[1], path=True)
    k1 = int(d.table.stage_start[1])
    assert yc[k1, 0, 0] == pytest.approx(loop.moments.knot_cov[0][0, 0], rel=1e-12)
    assert loop.moments.path_var[0, 0] == pytest.approx(0.01)
    sensor = exit_bounds(c, ym, yc, problem.t0, problem.tick_hz)["cantelli"].per_tick
    state = exit_bounds(c, full.path_y_mean, full.path_y_cov, problem.t0,
                        problem.tick_hz)["cantelli"].per_tick
    assert np.all(sensor >= state - 1e-12) and sensor.sum() > state.sum()
    assert _outputs(problem, d.table, 0)[0] == J


def test_a_spline_designs_consumers_use_its_flashed_spline_filter():
    """robot_position_sensor with ``table = "spline"``: its filter as flashed is the gain
    spline, and the corridor's output moments (`sensor_outputs`, which the corridor search
    reads) and the every-tick path mean (`sensor_path_mean`) are the oracle's with those gains,
    not with the per-sample ones: they differ from the latter's by about the shipped
    certificate's changes (gains/robot_position_sensor_spline.json)."""
    problem = load_problem(EXAMPLES / "robot_position_sensor.toml")
    d = design_problem(problem, table="spline")
    cert = json.loads((GAINS / "robot_position_sensor_spline.json").read_text())
    cert = cert["estimator"]["gain_spline"]
    assert d.table.spline_tolerance == cert["spline_tolerance"]
    loop = evaluate_estimator(problem, d.table)
    spline = estimator_table(problem, d.table, loop, spline_tolerance=cert["spline_tolerance"])
    assert spline.gain_spline.spans() == cert["spans"]
    gains, pred = spline.per_tick()
    C = problem.corridors[0].C
    J, ym, yc = sensor_outputs(problem, d.table, C)
    ref = evaluate_estimator(problem, d.table, gains=gains, predictor=pred, output=C,
                             path=True).moments
    assert J == pytest.approx(ref.J, rel=1e-14)
    np.testing.assert_allclose(yc, ref.path_y_cov, rtol=1e-13, atol=0)
    np.testing.assert_array_equal(sensor_path_mean(problem, d.table), ref.path_mean)
    # the per-sample filter of the same law: the certificate's relative changes
    per = estimator_table(problem, d.table, loop)
    Jp, _, ycp = sensor_outputs(problem, d.table, C, (per, *per.per_tick()))
    assert abs((J - Jp) / Jp - cert["J_change"]) <= 0.5e-10        # printed to 1e-10
    change = (np.linalg.norm(yc - ycp, axis=(1, 2)) / np.linalg.norm(ycp, axis=(1, 2)))[1:]
    assert cert["knot_cov_change"] / 10 < change.max() < 10 * cert["knot_cov_change"]


def test_the_harness_counts_the_true_states_exits_within_the_bound(corridor_case):
    """The C run of the sensor loop watches the corridor: its exit count is the count of
    recorded true paths that leave (recounted here from the states), it is not zero, and its
    one-sided 99 % lower bound is below the Cantelli certificate. A watch on the estimate
    instead of the state (mutation) counts differently."""
    problem, d, et, ctl = corridor_case
    paths = 3000
    mc, rec = simulate_estimator(problem, ctl, paths=paths, seed=20261128, substeps=1,
                                 record=paths)
    c = problem.corridors[0]
    x = rec["x"][:, :, 0]                                        # (ticks + 1, paths)
    left = (x > UP) | (x < LO)
    assert mc.exit_count(0) == int(left.any(axis=0).sum())
    assert 0.01 * paths < mc.exit_count(0) < 0.2 * paths
    first = np.where(left.any(axis=0), left.argmax(axis=0), -1)
    assert np.array_equal(np.flatnonzero(mc.exits.by_tick[0]),
                          np.unique(first[first >= 0]))
    xh = rec["xhat"][:, :, 0].astype(float)
    assert int(((xh > UP) | (xh < LO)).any(axis=0).sum()) != mc.exit_count(0)
    _, ym, yc = sensor_outputs(problem, d.table, c.C)
    bound = exit_bounds(c, ym, yc, problem.t0, problem.tick_hz)["cantelli"].total
    assert clopper_pearson_lower(mc.exit_count(0), paths) <= bound
    # in one block of `paths`, corridor-design's count is this run's (block 0: the seed's stream)
    assert count_sensor_exits(problem, d.table, 0, paths=paths, seed=20261128,
                              block_paths=paths) == mc.exit_count(0)


def test_corridor_design_screens_and_certifies_on_the_sensor_loop(tmp_path, capsys):
    """One grid point, few paths: the certificate's counts are the sensor loop's (the same
    seeds through `count_sensor_exits`), not the full-state loop's."""
    problem_file = tmp_path / "sensed.toml"
    doc = copy.deepcopy(DOC)
    doc["corridors"] = [{**CORRIDOR, "epsilon": 0.3}]
    problem = parse_problem(copy.deepcopy(doc))
    problem_file.write_text(problem.to_toml())
    code = main(["corridor-design", str(problem_file), "--search", "400", "--certify", "500",
                 "--strip", "0", "--rate", "0", "--json"])
    assert code == 0
    cert = json.loads(capsys.readouterr().out)
    chosen = cert["chosen"]
    d = design_problem(problem)
    assert chosen["screening"]["exits"] == count_sensor_exits(
        problem, d.table, 0, paths=400, seed=chosen["screening"]["seed"]) > 0
    assert chosen["certification"]["exits"] == count_sensor_exits(
        problem, d.table, 0, paths=500, seed=chosen["certification"]["seed"])
    assert chosen["J"] == pytest.approx(sensor_outputs(problem, d.table,
                                                       problem.corridors[0].C)[0], rel=1e-12)


def test_corridor_design_refuses_faults_with_a_sensor(tmp_path, capsys):
    doc = copy.deepcopy(DOC)
    doc["corridors"] = [{**CORRIDOR, "epsilon": 0.3}]
    doc["faults"] = {"miss_probability": 0.01}
    path = tmp_path / "faulty.toml"
    path.write_text(parse_problem(doc).to_toml())
    assert main(["corridor-design", str(path), "--search", "100", "--certify", "100"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "faults" in err[0] and "[measurement]" in err[0]
    assert list(tmp_path.iterdir()) == [path]


def test_simulate_reports_the_sensor_loops_exits_beside_its_bounds(tmp_path, capsys):
    """`stospline simulate` of a [measurement] problem with a corridor: the exits are the
    sensor loop's (the same seed through `count_sensor_exits`), the bounds its own."""
    doc = copy.deepcopy(DOC)
    doc["corridors"] = [CORRIDOR]
    problem = parse_problem(copy.deepcopy(doc))
    path = tmp_path / "sensed.toml"
    path.write_text(problem.to_toml())
    assert main(["simulate", str(path), "--paths", "1000", "--seed", "7", "--substeps", "1",
                 "--json"]) == 0
    (c,) = json.loads(capsys.readouterr().out)["corridors"]
    d = design_problem(problem)
    assert c["mc"]["exits"] == count_sensor_exits(problem, d.table, 0, paths=1000, seed=7) > 0
    _, ym, yc = sensor_outputs(problem, d.table, problem.corridors[0].C)
    want = exit_bounds(problem.corridors[0], ym, yc, problem.t0, problem.tick_hz)
    assert c["bound"]["gaussian"]["total"] == pytest.approx(want["gaussian"].total, rel=1e-3)
    assert "true state" in c["bound"]["loop"]
