"""Corridor exits: the oracle's bounds on a problem whose exit probability is known in closed
form, the C harness's exit counting against a numpy recount of the same states, and runs
without corridors unchanged.

The scalar problem: ``dx = u dt + sigma dZ`` (the additive noise written as noise on a constant
state x1 = 1) with nothing to steer for, so the optimal law is u = 0 and x(t) = sigma W(t) is
exactly Gaussian: ``P(x(t) > b) = Phi(-b / (sigma sqrt t))``.
"""
import numpy as np
import pytest
from scipy.stats import norm

from stospline.pipeline import design_problem
from stospline.problem import parse_problem
from stospline.harness.controller import CorridorWatch, TickStats, build_controller
from stospline.oracle.exit_bound import corridor_outputs, exit_bounds
from stospline.harness.exit_stats import clopper_pearson_lower, clopper_pearson_upper
from stospline.harness.montecarlo import _zoh, simulate

SIGMA, B, HZ = 0.5, 0.6, 100


def scalar(corridor_t=(0.0, 1.0), polygons=None):
    polygons = polygons or [{"A": [[1.0]], "b": [B]}]
    return parse_problem({
        "name": "walk", "x0": [0.0, 1.0], "tick_hz": HZ,
        "dynamics": {"A": [[0, 0], [0, 0]], "B": [[1], [0]],
                     "noise": [{"state": 1, "G": [[SIGMA], [0.0]]}]},
        "cost": {"R": [[1]]},
        "knots": [{"t": 1.0}],
        "corridors": [{"t": list(corridor_t), "C": [[1, 0]], "polygons": polygons}],
    })


@pytest.fixture(scope="module")
def walk():
    p = scalar()
    d = design_problem(p)
    assert np.abs(d.table.K).max() == 0 and np.abs(d.table.k0).max() == 0   # u = 0
    return p, d


def test_bounds_match_the_closed_form(walk):
    p, d = walk
    (c,) = p.corridors
    ((ym, yc),) = corridor_outputs(p, d.table)
    t = np.arange(HZ + 1) / HZ
    np.testing.assert_allclose(yc[:, 0, 0], SIGMA ** 2 * t, rtol=1e-12, atol=1e-15)
    b = exit_bounds(c, ym, yc, p.t0, p.tick_hz)
    var = SIGMA ** 2 * t
    np.testing.assert_allclose(b["gaussian"].per_tick, norm.sf(B / np.sqrt(np.maximum(var, 1e-300))),
                               rtol=1e-10, atol=1e-300)
    np.testing.assert_allclose(b["cantelli"].per_tick, var / (var + B ** 2), rtol=1e-10)
    assert b["gaussian"].per_tick[0] == 0 and b["cantelli"].per_tick[0] == 0   # x0 = 0 < b
    # Two walls |x| <= b in one polygon: the union bound over rows doubles each tick's term.
    two = scalar(polygons=[{"A": [[1.0], [-1.0]], "b": [B, B]}])
    b2 = exit_bounds(two.corridors[0], ym, yc, p.t0, p.tick_hz)
    np.testing.assert_allclose(b2["gaussian"].per_tick, 2 * b["gaussian"].per_tick, rtol=1e-12)
    np.testing.assert_allclose(b2["gaussian"].per_wall, [b["gaussian"].per_tick.sum()] * 2)
    # Two polygons (x <= b, or x >= b + 1): per tick the smaller polygon bound.
    union = scalar(polygons=[{"A": [[1.0]], "b": [B]}, {"A": [[-1.0]], "b": [-(B + 1)]}])
    bu = exit_bounds(union.corridors[0], ym, yc, p.t0, p.tick_hz)
    np.testing.assert_array_equal(bu["gaussian"].per_tick, b["gaussian"].per_tick)


def test_monte_carlo_exits_at_one_tick_match_the_gaussian_probability(walk):
    """A corridor of the last tick only: the exits count P(x(1) > b) = Phi(-b / sigma) (the
    plant's scheme is exact for additive noise); the count is within its 99.9 % interval."""
    p = scalar(corridor_t=(1.0, 1.0))
    _, d = walk
    mc = simulate(p, build_controller(d.table), paths=20000, seed=11, substeps=1, workers=1)
    k = mc.exit_count(0)
    exact = norm.sf(B / SIGMA)
    assert clopper_pearson_lower(k, 20000, 0.9995) <= exact <= clopper_pearson_upper(k, 20000,
                                                                                   0.9995)
    assert set(np.flatnonzero(mc.exits.by_tick[0])) == {HZ}


def test_cantelli_bound_holds_over_the_interval(walk):
    """Over the whole interval the exits are the discretely monitored first passage; the
    Cantelli union bound must not fall below the Monte Carlo lower confidence bound."""
    p, d = walk
    mc = simulate(p, build_controller(d.table), paths=20000, seed=12, substeps=1, workers=1)
    k = mc.exit_count(0)
    ((ym, yc),) = corridor_outputs(p, d.table)
    b = exit_bounds(p.corridors[0], ym, yc, p.t0, p.tick_hz)
    assert b["cantelli"].total >= clopper_pearson_lower(k, 20000)
    # Reflection principle: continuous monitoring gives 2 Phi(-b/sigma); the ticks see fewer.
    assert k / 20000 <= 2 * norm.sf(B / SIGMA)
    assert clopper_pearson_upper(k, 20000) >= norm.sf(B / SIGMA)


def test_c_exit_counting_equals_a_numpy_recount(robot_problem, robot_zoh):
    """The harness's C check (first exit tick and wall per path) against `CorridorWatch.check`
    (numpy) on the same double states after every tick, on the robot with a corridor narrowed
    so that many paths leave, through several walls."""
    p = robot_problem
    ctl = build_controller(robot_zoh.table)
    (c,) = p.corridors
    narrow = type(c)(c.t, c.C, tuple((A, b - 0.3 * (b > 0)) for A, b in c.polygons))
    paths, h = 256, 1.0 / p.tick_hz
    X = np.ascontiguousarray(np.tile(p.x0, (paths, 1)))
    rng = np.random.default_rng(5)
    watch_c = CorridorWatch.of((narrow,), paths, p.t0, p.tick_hz)
    watch_np = CorridorWatch.of((narrow,), paths, p.t0, p.tick_hz)
    step = ctl.stepper(paths)
    stats = TickStats.zeros(paths, p.n, p.m)
    cost = np.zeros(paths)
    table = robot_zoh.table
    for k in range(table.n_stages):
        st = p.stages[k]
        plant = ctl.plant(st, *_zoh(st, h), h, 1)
        dZ = np.empty((paths, 1, st.G.shape[2]))
        tick = ctl.ticker(step.instances, paths, dZ, X, cost, stats, None, watch_c)
        for j in range(int(table.stage_start[k]), int(table.stage_start[k + 1])):
            dZ[:] = rng.standard_normal(dZ.shape)
            assert tick(j, plant) == 0
            watch_np.check(j + 1, X)
    out = watch_np.exit_tick[0] >= 0
    assert 20 < out.sum() < paths and len(set(watch_np.exit_wall[0][out])) >= 3
    np.testing.assert_array_equal(watch_c.exit_tick, watch_np.exit_tick)
    np.testing.assert_array_equal(watch_c.exit_wall, watch_np.exit_wall)


def test_corridors_change_nothing_else_and_not_the_worker_count(robot_problem, robot_zoh):
    from dataclasses import replace
    ctl = build_controller(robot_zoh.table)
    bare = replace(robot_problem, corridors=())
    runs = [simulate(prob, ctl, paths=1100, seed=3, substeps=1, workers=w, per_path=True)
            for prob, w in ((bare, 1), (robot_problem, 1), (robot_problem, 2))]
    for mc in runs[1:]:
        np.testing.assert_array_equal(mc.cost, runs[0].cost)
        np.testing.assert_array_equal(mc.mean_x, runs[0].mean_x)
        for a, b in zip(mc.knot_states, runs[0].knot_states):
            np.testing.assert_array_equal(a, b)
    assert runs[0].exit_tick is None
    np.testing.assert_array_equal(runs[1].exit_tick, runs[2].exit_tick)
    np.testing.assert_array_equal(runs[1].exit_wall, runs[2].exit_wall)
    assert (runs[1].exit_tick >= 0).any()


def test_simulate_json_reports_the_corridor(tmp_path, capsys):
    """`stospline simulate --json`: the exits with their upper bound, the bounds, by time and
    wall, strict JSON (no NaN/Infinity); the text output has one line per corridor."""
    import json
    from stospline.cli import main
    f = tmp_path / "walk.toml"
    f.write_text(scalar(polygons=[{"A": [[1.0], [-1.0]], "b": [B, B]}]).to_toml()
                 .replace("[[corridors]]", "[[corridors]]\nepsilon = 0.5"))
    assert main(["simulate", str(f), "--paths", "3000", "--seed", "2", "--substeps", "1",
                 "--workers", "1", "--json", "--quiet"]) == 0
    s = json.loads(capsys.readouterr().out, parse_constant=lambda c: pytest.fail(c))
    (c,) = s["corridors"]
    m = c["mc"]
    assert m["paths"] == 3000 and 0 < m["exits"] < 3000
    assert m["estimate"] <= m["upper99"] <= 1 and m["meets_epsilon"] == (m["upper99"] <= 0.5)
    assert sum(b["exits"] for b in m["by_bin"]) == m["exits"]
    assert sum(w["exits"] for w in m["by_wall"]) == m["exits"]
    assert c["bound"]["cantelli"]["total"] == 1.0 and c["bound"]["gaussian"]["sum"] > 0
    assert main(["simulate", str(f), "--paths", "300", "--seed", "2", "--substeps", "1",
                 "--workers", "1", "--quiet"]) == 0
    assert "corridor 0 (t = [0, 1], epsilon 0.5): left by" in capsys.readouterr().out


def test_a_table_designed_for_a_delay_has_exits_without_bounds(tmp_path, capsys):
    """The oracle records no output moments for a delayed table: the Monte Carlo exits are
    reported, the bounds are null, and the report page says so."""
    import json
    from stospline.cli import main
    f = tmp_path / "walk.toml"
    f.write_text(scalar().to_toml())
    assert main(["simulate", str(f), "--paths", "600", "--seed", "2", "--substeps", "1",
                 "--workers", "1", "--json", "--quiet", "--delay-ticks", "1"]) == 0
    (c,) = json.loads(capsys.readouterr().out)["corridors"]
    assert c["bound"] is None and c["mc"]["exits"] > 0
    page = tmp_path / "r.html"
    assert main(["report", str(f), "--out", str(page), "--paths", "600", "--seed", "2",
                 "--substeps", "1", "--workers", "1", "--quiet", "--delay-ticks", "1"]) == 0
    assert "No oracle bounds: the table is designed for a delay." in page.read_text()


def test_corridors_with_faults_change_nothing_else(robot_problem, robot_zoh):
    """The fault tick with a corridor watch (harness_tick_watch with faults) runs the same
    loop as without the watch, and its exits match a numpy recount of its recorded paths
    wherever the float32 record is not within rounding of a wall."""
    from dataclasses import replace
    from stospline.problem.faults import parse_faults
    ctl = build_controller(robot_zoh.table)
    faults = parse_faults({"sensor_noise": 0.02, "actuator_noise": 0.1}, 4, 2)
    bare = replace(robot_problem, corridors=())
    a = simulate(bare, ctl, paths=300, seed=9, substeps=1, workers=1, faults=faults,
                 per_path=True)
    b = simulate(robot_problem, ctl, paths=300, seed=9, substeps=1, workers=1, faults=faults,
                 record=300, per_path=True)
    np.testing.assert_array_equal(a.cost, b.cost)
    np.testing.assert_array_equal(a.knot_states[1], b.knot_states[1])
    (c,) = robot_problem.corridors
    Y = b.record_x.astype(float) @ c.C.T                       # ticks x paths x 2
    walls = np.stack([c.exit_wall(Y[j]) for j in range(Y.shape[0])])
    first = np.where((walls >= 0).any(axis=0), np.argmax(walls >= 0, axis=0), -1)
    assert (b.exit_tick[0] >= 0).sum() > 5
    A, off = c.unit_walls()
    near = np.abs(Y @ A.T - off).min(axis=2).min(axis=0) < 1e-5   # paths grazing a wall
    np.testing.assert_array_equal(first[~near], b.exit_tick[0][~near])
