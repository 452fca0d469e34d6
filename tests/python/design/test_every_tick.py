"""[[regions]] with every = "tick": the band holds at every controller tick of the implemented
law, met by constraint generation while few rows are active and by the
sparse QP on the tick grid beyond (`stospline.refine.every_tick`, `stospline.design.tick_qp`)."""
import copy
import os
import tomllib

import numpy as np
import pytest

from conftest import EXAMPLES
from stospline.cli import main
from stospline.design.bands import design_bands
from stospline.errors import DesignError
from stospline.pipeline import design_problem, design_summary
from stospline.problem import ProblemError, load_problem, parse_problem
from stospline.problem.model import Constraint
from stospline.problem.regions import with_bands
from stospline.refine.every_tick import active_ticks, between_ticks, design_every_tick
from stospline.oracle.evaluate import evaluate_table
from stospline.table.format import table_of

MONOTONE = EXAMPLES / "robot_monotone.toml"
ROBOT = EXAMPLES / "robot_corridor.toml"


def robot_doc(hz: int, regions: list) -> dict:
    doc = tomllib.loads(ROBOT.read_text())
    doc.pop("corridors")
    doc.update(tick_hz=hz, design={"mode": "joint"}, regions=regions)
    return doc


def velocities(prob, table):
    """E{xdot}, E{ydot} at every tick of [t0 + 1 tick, 6] from the oracle."""
    return evaluate_table(prob, table, path=True).path_mean[1:, [1, 3]]


@pytest.fixture(scope="module")
def monotone():
    return design_problem(load_problem(MONOTONE), mode="joint")


def test_region_holds_at_every_tick_on_the_oracle(monotone):
    d = monotone
    assert d.every_tick.iterations > 1 and len(d.every_tick.working_set) > 0
    exact = velocities(d.problem, table_of(d.design, quantize=False))
    assert exact.min() >= -1e-9 * 10            # tolerance 1e-9 of the bounds' scale (10)
    assert velocities(d.problem, d.table).min() >= -1e-6      # float32 gains
    # The region binds: without it the expected x overshoots and comes back.
    doc = tomllib.loads(MONOTONE.read_text())
    doc.pop("regions")
    free = design_problem(parse_problem(doc), mode="joint")
    assert velocities(free.problem, free.table).min() < -0.02
    assert d.design.J0 > free.design.J0
    # The summary says the same (negative: inside).
    reg = design_summary(d)["every_tick"]["regions"][0]
    assert reg["ticks"] == 600 and reg["worst_at_ticks_design"] <= 1e-8


def test_agrees_with_the_dense_design_over_all_ticks():
    """At 20 Hz the band at every tick of the region can be posed densely (one band knot per
    tick, as `every` = one tick would): the same optimum and the same active ticks."""
    p = parse_problem(robot_doc(20, [{"t": [0.0, 5.5], "every": "tick", "C": [[0, 1, 0, 0]],
                                      "lower": [0.0], "upper": [10.0]}]))
    et = design_every_tick(p)
    reg = p.tick_regions[0]
    dense_p = with_bands(p, {int(j): Constraint(reg.C, None, reg.lower, reg.upper)
                             for j in reg.ticks(p.t0, p.tick_hz)})
    dense = design_bands(dense_p)
    assert len(dense_p.knots) == 111 and len(et.problem.knots) < 12
    assert et.design.J0 == pytest.approx(dense.J0, rel=1e-12, abs=0)
    assert active_ticks(et.problem, et.design) == active_ticks(dense_p, dense)
    assert len(active_ticks(dense_p, dense)) >= 5          # an arc of contacts, not one tick
    assert np.linalg.cond(et.design.base.stages[0].W0) < np.linalg.cond(dense.base.stages[0].W0)


def test_a_grid_misses_what_every_tick_catches():
    """The same region on a 0.1 s grid: met at the grid points, violated between them."""
    doc = tomllib.loads(MONOTONE.read_text())
    grid = copy.deepcopy(doc)
    grid["regions"][0]["every"] = 0.1
    g = design_problem(parse_problem(grid), mode="joint")
    v = velocities(g.problem, table_of(g.design, quantize=False))
    on_grid = np.arange(10, 600, 10) - 1                  # ticks 10, 20, ... (row j = tick j+1)
    assert v[on_grid].min() >= -1e-9
    assert v.min() < -1e-4
    e = design_problem(parse_problem(doc), mode="joint")
    assert velocities(e.problem, table_of(e.design, quantize=False)).min() >= -1e-8
    assert e.design.J0 > g.design.J0


def narrow_corridor_at_every_tick():
    doc = tomllib.loads((EXAMPLES / "robot_narrow_corridor.toml").read_text())
    doc["knots"][0]["constraint"] = {"C": [[1, 0, 1, 0]], "value": [0.0]}
    for r in doc["regions"]:
        r["every"] = "tick"
    return doc


def no_overshoot():
    """E{x} <= -1 at every tick: the contact is at zero speed, so the mean bulges out
    between the ticks it touches."""
    return robot_doc(20, [{"t": [0.0, 6.0], "every": "tick", "C": [[1, 0, 0, 0]],
                           "lower": [-6.0], "upper": [-1.0]}])


@pytest.mark.parametrize("make, bulge", [(narrow_corridor_at_every_tick, False),
                                         (no_overshoot, True)])
def test_between_ticks_finds_the_exact_extremum(make, bulge):
    """Positions of a double integrator are quadratic over a tick: the worst over the
    interval from the polynomial's ends and extrema equals a brute-force search on 2001 points
    per tick, and is never below it."""
    d = design_problem(parse_problem(make()), mode="joint")
    p = d.problem
    m = evaluate_table(p, table_of(d.design, quantize=False), path=True)
    got = between_ticks(p, m.path_mean, m.path_u_mean)
    A, B = p.stages[0].A, p.stages[0].B
    h = 1.0 / p.tick_hz
    s = np.linspace(0, h, 2001)
    for reg, g in zip(p.tick_regions, got):
        assert g["exact"]
        worst = -np.inf
        for j in range(int(round(reg.t[0] * p.tick_hz)), int(round(reg.t[1] * p.tick_hz))):
            x, u = m.path_mean[j], m.path_u_mean[j]
            # x(s) = x + s A x + s^2/2 A^2 x + s B u + s^2/2 A B u (A^3 = 0 here)
            xs = (x + np.outer(s, A @ x) + np.outer(s ** 2 / 2, A @ A @ x)
                  + np.outer(s, B @ u) + np.outer(s ** 2 / 2, A @ B @ u))
            y = xs @ reg.C.T
            worst = max(worst, float(np.maximum(y - reg.upper, reg.lower - y).max()))
        assert g["worst"] >= worst - 1e-15 and g["worst"] == pytest.approx(worst, abs=1e-12)
        at_ticks = float(design_summary(d)["every_tick"]["regions"][0]["worst_at_ticks_design"])
        if bulge:     # beyond the band only between ticks (O(h^2), tiny here)
            assert at_ticks <= 6e-9 < 1e-8 < g["worst"] < 1e-6
            assert abs(g["t"] * p.tick_hz - round(g["t"] * p.tick_hz)) > 1e-3


def test_iteration_cap_names_the_region():
    p = load_problem(MONOTONE)
    with pytest.raises(DesignError) as err:
        design_every_tick(p, max_iterations=2)
    assert err.value.field == "regions[0]" and "2 rounds" in str(err.value)


def test_written_back_as_a_tick_region():
    p = load_problem(MONOTONE)
    q = parse_problem(tomllib.loads(p.to_toml()))
    assert len(q.tick_regions) == 1 and len(q.knots) == 2
    a, b = p.tick_regions[0], q.tick_regions[0]
    assert a.t == b.t and np.array_equal(a.C, b.C) and np.array_equal(a.lower, b.lower)
    assert 'every = "tick"' in p.to_toml()


@pytest.mark.parametrize("edit, field, reason", [
    (lambda doc: doc["regions"][0].update(every="tock"), "regions[0].every", '"tick"'),
    (lambda doc: doc["regions"][0].update(every=[1]), "regions[0].every", "number"),
    (lambda doc: doc["regions"][0].update(t=[0.0, 7.0]), "regions[0].t", "last knot"),
    (lambda doc: doc["regions"][0].update(lower=[0.0, 11.0]), "regions[0].lower", "empty"),
    (lambda doc: doc["regions"][0].update(t=[0.005, 6.0]), "regions[0].t", "whole number"),
    (lambda doc: doc["design"].update(mode="stagewise"), "regions[0].every", "mode joint"),
    (lambda doc: doc["regions"][0].update(C=[[0, 1, 0, 0], [0, 0, 0, 0]]), "regions[0].C",
     "row 1 is zero"),
    # E{xdot} <= -1 at every tick, yet at rest at t = 6: contradicts the knot there.
    (lambda doc: doc["regions"][0].update(lower=[-10.0, 0.0], upper=[-1.0, 10.0]),
     "regions[0]", "cannot all be met"),
    # A third state the input cannot move, kept in a band it starts outside of.
    (lambda doc: doc.update(x0=[-5.0, 0.0, 1.0, 0.0, 0.0],
                            dynamics={**{k: [r + [0] for r in v] + [[0] * 5]
                                         for k, v in doc["dynamics"].items() if k == "A"},
                                      "B": doc["dynamics"]["B"] + [[0, 0]]},
                            knots=[{**kn, **{key: {**kn[key], "C": [r + [0] for r in
                                                                     kn[key]["C"]]}
                                             for key in ("penalty", "constraint")}}
                                   for kn in doc["knots"]],
                            regions=[{"t": [0.0, 6.0], "every": "tick", "C": [[0, 0, 0, 0, 1]],
                                      "lower": [1.0], "upper": [2.0]}]),
     "regions[0]", "the design fails"),
])
def test_bad_input_exits_2_naming_the_field_and_writes_nothing(tmp_path, capsys, edit, field,
                                                               reason):
    doc = tomllib.loads(MONOTONE.read_text())
    edit(doc)
    src = tmp_path / "in"
    src.mkdir()
    f = src / "bad.toml"
    f.write_text(_dump(doc))
    out = tmp_path / "out"
    out.mkdir()
    code = main(["design", str(f), "--out", str(out)])
    stdout, err = capsys.readouterr()
    assert code == 2, err
    assert stdout == "" and err.count("\n") == 1, err
    assert f"{field}: " in err and reason in err, err
    assert os.listdir(out) == []


def test_a_spline_table_of_a_band_dual_is_refused():
    """Constraint generation's table (a band dual of at most 8 rows) re-plans its working set
    only: no spline table, naming design.table. (The tick-grid QP's tables latch the state and
    have one: tests/python/sim/test_spline_restore.py.)"""
    problem = parse_problem(narrow_corridor_at_every_tick())
    assert design_problem(problem, mode="joint").every_tick.method == "constraint-generation"
    with pytest.raises(DesignError) as err:
        design_problem(problem, mode="joint", table="spline")
    assert err.value.field == "design.table"


def test_a_delay_is_refused():
    with pytest.raises(DesignError) as err:
        design_problem(load_problem(MONOTONE), mode="joint", delay_ticks=1)
    assert err.value.field == "design.delay_ticks"


def test_continuous_discretization_is_refused():
    with pytest.raises(DesignError) as err:
        design_problem(load_problem(MONOTONE), mode="joint", discretization="continuous")
    assert err.value.field == "regions[0].every"


def _dump(doc: dict) -> str:
    """A problem file from a decoded one (the dicts here are plain TOML values)."""
    import json

    def val(v):
        if isinstance(v, dict):
            return "{ " + ", ".join(f"{k} = {val(x)}" for k, x in v.items()) + " }"
        if isinstance(v, list):
            return "[" + ", ".join(val(x) for x in v) + "]"
        return json.dumps(v)
    lines = [f"{k} = {val(v)}" for k, v in doc.items() if not isinstance(v, (dict, list))
             or (isinstance(v, list) and v and not isinstance(v[0], dict))]
    for k, v in doc.items():
        if isinstance(v, dict):
            lines += [f"[{k}]"] + [f"{kk} = {val(x)}" for kk, x in v.items()]
        elif isinstance(v, list) and v and isinstance(v[0], dict):
            for item in v:
                lines += [f"[[{k}]]"] + [f"{kk} = {val(x)}" for kk, x in item.items()]
    return "\n".join(lines) + "\n"


def test_monte_carlo_through_the_compiled_controller_agrees(monotone):
    """The tables of the every-tick design run in the harness like any band table: Monte Carlo
    through the compiled C controller agrees with the oracle (fixed seed)."""
    from stospline.pipeline import simulate_problem, simulation_summary
    mc = simulate_problem(monotone, paths=2000, seed=20261125)
    s = simulation_summary(monotone, mc, seed=20261125)
    assert s["verdict"]["agree"], s["verdict"]
    # 90 active rows: the tick-grid QP's table, the file's 2 stages, the state latched at t0.
    assert monotone.every_tick.method == "tick-qp"
    assert len(monotone.table.stage_start) - 1 == 2
    assert list(monotone.table.stage_n_latch) == [4, 0]


def test_tick_grid_qp_equals_constraint_generation():
    """The same optimum two independent ways at 100 Hz: the sparse primal QP on the tick grid
    and constraint generation on the dual (90 band knots, W(t0) of 90 rows)."""
    p = load_problem(MONOTONE)
    cg = design_every_tick(p, band_rows=None)
    qp = design_every_tick(p)
    assert cg.method == "constraint-generation" and qp.method == "tick-qp"
    assert len(cg.problem.knots) == 92 and len(qp.problem.knots) == 2
    assert qp.design.J0 == pytest.approx(cg.design.J0, rel=1e-12, abs=0)
    assert active_ticks(qp.problem, qp.design) == active_ticks(cg.problem, cg.design)
    # And both laws give the same commands' means at every tick (the oracle, double).
    a = evaluate_table(cg.problem, table_of(cg.design, quantize=False), path=True)
    b = evaluate_table(qp.problem, table_of(qp.design, quantize=False), path=True)
    assert np.abs(a.path_mean - b.path_mean).max() < 1e-9
    assert b.J == pytest.approx(qp.design.J0, rel=1e-12)


def test_completing_the_square_gives_the_joint_design():
    """Without regions the tick-grid QP is the joint exact-ZOH design: J = V0(x0) + sum d'H d
    with d the offset that the knots' equalities force (no inequality rows)."""
    from stospline.design.tick_qp import design_tick_qp
    from stospline.design.zoh import design_zoh
    p = load_problem(ROBOT)
    qp = design_tick_qp(p)
    zoh = design_zoh(p, mode="joint")
    assert qp.J0 == pytest.approx(zoh.J0, rel=1e-12)
    _, st_qp = qp.tick_gains()
    _, st_z = zoh.tick_gains()
    assert np.abs(np.concatenate([s[0] for s in st_qp]) -
                  np.concatenate([s[0] for s in st_z])).max() < 1e-9     # the same K


def test_one_khz_arc_of_contact_is_met_at_every_tick(tmp_path):
    """At 1 kHz robot_monotone's arcs of contact hold 1 029 rows at 1 029 ticks (constraint
    generation would need a stage per tick: 1 031 > 256). The tick-grid QP meets every tick on
    the oracle, the float32 table to rounding, and costs less than at 100 Hz (a faster
    controller tracks the bound more closely)."""
    doc = tomllib.loads(MONOTONE.read_text())
    doc["tick_hz"] = 1000
    p = parse_problem(doc)
    with pytest.raises(DesignError) as err:
        design_every_tick(p, band_rows=None)
    assert err.value.field == "regions[0]" and "STSP_MAX_STAGES" in str(err.value)
    d = design_problem(p, mode="joint")
    assert d.every_tick.method == "tick-qp" and len(d.every_tick.working_set) > 1000
    exact = velocities(d.problem, table_of(d.design, quantize=False))
    assert exact.min() >= -1e-9 * 10
    assert velocities(d.problem, d.table).min() >= -1e-6
    assert d.design.J0 < design_problem(load_problem(MONOTONE), mode="joint").design.J0
    assert d.law.J == pytest.approx(d.design.J0, rel=1e-10)
    assert d.table.n_stages == 2


def test_region_ends_are_ticks_of_the_region():
    """[a, b] includes its ends: the narrow corridor's only contact is the corner t = 3, the
    end of the first leg, which a grid (ends excluded) never checks."""
    d = design_problem(parse_problem(narrow_corridor_at_every_tick()), mode="joint")
    assert d.every_tick.working_set == [(60, 0, 0)]          # E{y} >= 0.55 at tick 60 = 3 s
    m = evaluate_table(d.problem, table_of(d.design, quantize=False), path=True)
    assert m.path_mean[60, 2] >= 0.55 - 1e-12


def test_contacts_at_neighbouring_ticks_at_100_hz():
    """E{x} <= -1 at 100 Hz: the working set's dual has nearly dependent rows (contacts at
    neighbouring ticks), where OSQP's active set alone misses a row by ~2e-6; settled by KKT
    steps, every tick holds to the tolerance."""
    doc = no_overshoot()
    doc["tick_hz"] = 100
    et = design_every_tick(parse_problem(doc))
    m = evaluate_table(et.problem, table_of(et.design, quantize=False), path=True)
    assert m.path_mean[1:, 0].max() <= -1 + 6e-9
    assert et.iterations >= 5 and len(et.working_set) + et.dropped >= 5


def test_rows_the_optimum_leaves_slack_are_dropped():
    """Rows cut in an early round and overtaken later are dropped at the end: the same J0,
    fewer stages, and here few enough rows (7 <= 8) for the table to carry the band dual."""
    p = parse_problem(no_overshoot())
    et = design_every_tick(p)
    assert et.dropped > 0 and len(et.working_set) == 2
    assert len(et.problem.knots) == len(p.knots) + 2
    assert et.history[-1]["added"] == -et.dropped
    assert et.history[-1]["J0"] == pytest.approx(et.history[-2]["J0"], rel=1e-12)
    d = design_problem(p, mode="joint")
    assert d.table.band_qp is not None and d.table.band_qp.q == 7


def _no_overshoot_between(hz: int, between: bool) -> dict:
    doc = no_overshoot()
    doc["tick_hz"] = hz
    doc["regions"][0]["between_ticks"] = between
    return doc


def test_between_ticks_holds_over_the_whole_interval():
    """E{x} <= -1 on [0, 6] at 20 Hz: at the ticks only, the mean bulges 7.5e-8 beyond the
    band between ticks 104 and 105 (a tangential contact); with between_ticks = true the
    Bernstein rows keep the exact polynomial mean inside at every time, for a cost 1e-10
    relative higher."""
    ticks_only = design_problem(parse_problem(_no_overshoot_between(20, False)), mode="joint")
    d = design_problem(parse_problem(_no_overshoot_between(20, True)), mode="joint")
    assert d.every_tick.method == "tick-qp"
    gap0 = design_summary(ticks_only)["every_tick"]["regions"][0]
    gap = design_summary(d)["every_tick"]["regions"][0]
    assert gap0["over_interval_exact"] and gap["over_interval_exact"]
    assert gap0["worst_over_interval"] > 5e-8                 # the bulge the ticks miss
    assert gap["worst_over_interval"] <= 1e-9 * 6             # TOLERANCE x the bounds' scale
    assert gap["worst_at_ticks_implemented"] <= 1e-7          # float32 gains
    assert ticks_only.design.J0 < d.design.J0 < ticks_only.design.J0 * (1 + 1e-8)
    # Monte-Carlo-free independent check: the mean sampled between ticks by the oracle's own
    # matrix exponential (not the polynomial the rows were built from).
    m = evaluate_table(d.problem, table_of(d.design, quantize=False), path=True)
    worst = between_ticks(d.problem, m.path_mean, m.path_u_mean, points=16)
    assert worst[0]["worst"] <= 1e-9 * 6


def test_between_ticks_needs_a_polynomial_mean(tmp_path, capsys):
    """Between ticks is enforced only where the mean is a polynomial over a tick (A
    nilpotent): a damped robot is refused, naming the key; nothing is written."""
    doc = _no_overshoot_between(20, True)
    doc["dynamics"]["A"][1][1] = -0.5                    # x velocity damped: not nilpotent
    f = tmp_path / "damped.toml"
    f.write_text(_dump(doc))
    out = tmp_path / "out"
    out.mkdir()
    code = main(["design", str(f), "--out", str(out)])
    stdout, err = capsys.readouterr()
    assert code == 2 and stdout == "" and err.count("\n") == 1, err
    assert "regions[0].between_ticks: " in err and "nilpotent" in err, err
    assert os.listdir(out) == []


@pytest.mark.parametrize("value, every, reason", [
    (1, "tick", "must be true or false"),
    (True, 0.1, 'needs every = "tick"'),
])
def test_between_ticks_bad_values(value, every, reason):
    doc = _no_overshoot_between(20, True)
    doc["regions"][0]["between_ticks"] = value
    doc["regions"][0]["every"] = every
    with pytest.raises(ProblemError) as err:
        parse_problem(doc)
    assert err.value.field == "regions[0].between_ticks" and reason in str(err.value)


def test_between_ticks_is_written_back():
    p = parse_problem(_no_overshoot_between(20, True))
    again = parse_problem(tomllib.loads(p.to_toml()))
    assert again.tick_regions[0].between and not load_problem(MONOTONE).tick_regions[0].between


def test_between_ticks_where_a_waypoint_touches_the_band():
    """The quadrotor (gravity as the affine drift, no delay) at 100 Hz under z <= 2 on [0, 4],
    whose waypoints z = 2 at t = 2 and 4 lie on the band: between ticks the climb rate must
    then vanish at the waypoints, an equality the bands imply and no point satisfies
    strictly. The exact corrections do not settle on such degenerate rows; the interior
    point's own iterate is the design, feasible (the oracle finds every tick and every time
    between inside) and optimal to its reported duality gap."""
    doc = tomllib.loads((EXAMPLES / "quadrotor.toml").read_text())
    doc.update(tick_hz=100, design={"mode": "joint"})
    doc["regions"] = [{"t": [0.0, 4.0], "every": "tick", "C": [[1, 0]], "lower": [0.0],
                       "upper": [2.0], "between_ticks": True},
                      {"t": [0.0, 6.0], "every": "tick", "C": [[0, 1]], "lower": [-1.0],
                       "upper": [2.0], "between_ticks": True}]
    d = design_problem(parse_problem(doc), mode="joint")
    for gap in design_summary(d)["every_tick"]["regions"]:
        assert gap["worst_over_interval"] <= 1e-9 * 2 and gap["over_interval_exact"]
    assert 0 < d.design.optimality_gap <= 1e-6 * d.design.J0       # the interior point's
    assert d.law.J == pytest.approx(d.design.J0, rel=1e-12)
    for r in doc["regions"]:
        r["between_ticks"] = False
    ticks_only = design_problem(parse_problem(doc), mode="joint")
    assert ticks_only.design.J0 <= d.design.J0 + d.design.optimality_gap
    assert design_summary(ticks_only)["every_tick"]["regions"][0]["worst_over_interval"] > 1e-7


@pytest.mark.parametrize("rows", [2, 3])
def test_dependent_knot_rows_are_refused_before_the_tick_grid_qp(rows):
    """Identical equality rows make the QP's equality block singular: refused, naming the
    knot's rows, as the other designs refuse them (not SuperLU's "exactly singular")."""
    from stospline.design.tick_qp import design_tick_qp
    from stospline.errors import DesignError
    p = parse_problem({
        "name": "cart", "x0": [0.0, 0.0], "tick_hz": 100,
        "dynamics": {"A": [[0, 1], [0, 0]], "B": [[0], [1]]}, "cost": {"R": [[1]]},
        "design": {"mode": "joint"},
        "knots": [{"t": 1.0, "constraint": {"C": [[1, 0]], "value": [1.0]}},
                  {"t": 2.0, "constraint": {"C": [[1.0, 0.0]] * rows, "value": [0.0] * rows}}],
        "regions": [{"t": [0.0, 2.0], "every": "tick", "C": [[1.0, 0.0]], "lower": [-1000.0],
                     "upper": [1000.0], "between_ticks": True}]})
    with pytest.raises(DesignError, match=r"linearly dependent") as exc:
        design_tick_qp(p)
    assert exc.value.field == "knots[1].constraint.C"
