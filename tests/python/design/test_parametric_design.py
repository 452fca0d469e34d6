"""Runtime parameters: the parametric table at random parameters in the range equals a fresh
design at those values.

The sensitivity columns come from designs whose only source is one parameter
(`stospline.design.sensitivity`); the reference here is independent of that route: the file
with the values substituted (`apply_to_doc`), read again and designed from scratch. Compared:
the gains K, L, Lambda (unchanged), k0 and lambda0, the oracle's cost of the parametric table
at theta against the fresh design's own J0 (exact ZOH) or the oracle's cost of the fresh
table (continuous, whose J0 is the continuous law's), and the oracle's knot means. On shipped
examples (the robot, the quadrotor with gravity as a parameter and a one-tick delay, the
investment with time-varying interest), on random problems with stage overrides,
time-varying data and a drift, and on the offsets of tracking paths.
"""
import tomllib

import numpy as np
import pytest

from conftest import EXAMPLES
from support.problems import tracked_cart_doc
from test_random_problems import random_doc
from test_time_varying_data import tv_doc

from stospline.design.continuous import design_continuous
from stospline.design.zoh import design_zoh
from stospline.oracle.evaluate import evaluate_table
from stospline.oracle.parametric import cost_quadratic, design_parametric, evaluate_at
from stospline.problem import parse_problem
from stospline.problem.parameters import apply_to_doc
from stospline.table.format import table_of

# Relative agreement: exact ZOH is the same recursion on the same gains (rounding only); the
# continuous design integrates the gains and linear terms together with adaptive steps, so a
# fresh design's steps differ and the agreement is the integrator's (rtol 1e-12).
TOL = {"exact-zoh": 1e-11, "continuous": 1e-10}


def _rel(a, b):
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.abs(a - b).max() / max(1.0, np.abs(b).max())) if b.size else 0.0


def _fresh(doc, p, theta, discretization, mode, delay):
    q = parse_problem(apply_to_doc(doc, p.parameters, theta))
    if discretization == "exact-zoh":
        d = design_zoh(q, mode=mode, delay_ticks=delay)
    else:
        d = design_continuous(q, mode=mode)
    return q, d


def check_against_fresh(doc, *, mode="stagewise", discretization="exact-zoh", delay=0,
                        draws=3, seed=0):
    """The worst relative differences over `draws` random theta (and the range's upper
    corner) of the parametric table against fresh designs; asserts them within TOL."""
    p = parse_problem(doc)
    pd = design_parametric(p, mode=mode, discretization=discretization, delay_ticks=delay)
    rng = np.random.default_rng(seed)
    lo = np.array([q.lower for q in p.parameters])
    hi = np.array([q.upper for q in p.parameters])
    thetas = [rng.uniform(lo, hi) for _ in range(draws)] + [hi]
    worst = dict.fromkeys(("gains", "k0", "lambda0", "J", "mean"), 0.0)
    for theta in thetas:
        q, fd = _fresh(doc, p, theta, discretization, mode, delay)
        ft = table_of(fd, quantize=False)
        pt = pd.table.at(theta)
        worst["gains"] = max(worst["gains"], _rel(pt.K, ft.K), _rel(pt.L, ft.L),
                             _rel(pt.Lambda, ft.Lambda))
        worst["k0"] = max(worst["k0"], _rel(pt.k0, ft.k0))
        worst["lambda0"] = max(worst["lambda0"], _rel(pt.lambda0, ft.lambda0))
        mom = evaluate_at(p, pd.table, theta)
        ref = evaluate_table(q, ft, path=False)
        J_ref = fd.J0 if discretization == "exact-zoh" else ref.J
        worst["J"] = max(worst["J"], abs(mom.J - J_ref) / abs(J_ref))
        worst["mean"] = max(worst["mean"], _rel(mom.knot_mean, ref.knot_mean))
        if discretization == "exact-zoh":       # the constraints at theta hold by the table
            for k, kn in enumerate(q.knots):
                if kn.constraint is not None:
                    assert _rel(mom.knot_constraint[k], kn.constraint.value) < 1e-9
    print(f"\n{p.name} {mode} {discretization} delay={delay}: "
          + " ".join(f"{k}={v:.2g}" for k, v in worst.items()))
    tol = TOL[discretization]
    assert worst["gains"] <= tol
    for key in ("k0", "lambda0", "J", "mean"):
        assert worst[key] <= tol, (key, worst[key])
    return p, pd


def _example(name, **over):
    doc = tomllib.loads((EXAMPLES / f"{name}.toml").read_text())
    doc.update(over)
    return doc


def robot_goal_doc(tick_hz=100):
    """The robot with its goal (x, y) and its start x as parameters."""
    doc = _example("robot_corridor", tick_hz=tick_hz)
    doc["parameters"] = [
        {"name": "goal_x", "sets": ["knots[1].constraint.value[0]",
                                    "knots[1].penalty.target[0]"], "range": [-1.5, -0.5]},
        {"name": "goal_y", "sets": ["knots[1].constraint.value[2]",
                                    "knots[1].penalty.target[2]"], "range": [4.5, 5.5]},
        {"name": "start_x", "sets": ["x0[0]"], "range": [-5.5, -4.5]},
        {"name": "bend_x", "sets": ["knots[0].penalty.target[0]"], "range": [-1.3, -0.7]}]
    return doc


@pytest.mark.parametrize("mode", ["stagewise", "joint"])
@pytest.mark.parametrize("discretization", ["exact-zoh", "continuous"])
def test_robot_goal(mode, discretization):
    check_against_fresh(robot_goal_doc(), mode=mode, discretization=discretization)


def test_shipped_robot_goal():
    check_against_fresh(tomllib.loads((EXAMPLES / "robot_goal.toml").read_text()), draws=2)


def test_robot_goal_at_its_own_rate():
    check_against_fresh(robot_goal_doc(1000), draws=2)


def test_quadrotor_gravity_and_waypoint_with_delay():
    doc = _example("quadrotor", tick_hz=100)
    doc["parameters"] = [
        {"name": "gravity", "sets": ["dynamics.f[1]"], "range": [-10.3, -9.3]},
        {"name": "hover", "sets": ["knots[0].constraint.value[0]", "knots[0].penalty.target[0]",
                                   "knots[1].constraint.value[0]", "knots[1].penalty.target[0]"],
         "range": [1.5, 2.5]},
        {"name": "top", "sets": ["knots[2].constraint.value[0]", "knots[2].penalty.target[0]"],
         "range": [4.5, 5.5]}]
    for mode in ("stagewise", "joint"):
        check_against_fresh(doc, mode=mode, delay=1)


def test_investment_time_varying_rate():
    doc = _example("investment")
    doc["parameters"] = [
        {"name": "wealth_mid", "sets": ["knots[0].constraint.value[0]",
                                        "knots[0].penalty.target[0]"], "range": [50.0, 70.0]},
        {"name": "wealth_end", "sets": ["knots[1].constraint.value[0]",
                                        "knots[1].penalty.target[0]"], "range": [90.0, 110.0]}]
    for disc in ("exact-zoh", "continuous"):
        check_against_fresh(doc, discretization=disc)


def _with_parameters(doc, rng):
    """Parameters on every kind of value of a random problem: a drift on every stage (top
    level, and in each [[stages]] entry that overrides dynamics), the first constraint value
    and penalty target of each knot, x0[0]; one parameter setting two values at once."""
    n = len(doc["x0"])
    doc["dynamics"]["f"] = rng.normal(size=n).round(3).tolist()
    over = [k for k, st in enumerate(doc.get("stages", [])) if "dynamics" in st]
    pars = ([{"name": "f0", "sets": ["dynamics.f[0]"]}]
            if len(over) < len(doc["knots"]) else [])
    for k in over:
        doc["stages"][k]["dynamics"]["f"] = rng.normal(size=n).round(3).tolist()
        pars.append({"name": f"f_s{k}", "sets": [f"stages[{k}].dynamics.f[{n - 1}]"]})
    for k, kn in enumerate(doc["knots"]):
        if "constraint" in kn and "penalty" in kn:   # one parameter, two values
            kn["penalty"]["target"][0] = kn["constraint"]["value"][0]
            pars.append({"name": f"both{k}", "sets": [f"knots[{k}].constraint.value[0]",
                                                      f"knots[{k}].penalty.target[0]"]})
        elif "constraint" in kn:
            pars.append({"name": f"value{k}", "sets": [f"knots[{k}].constraint.value[0]"]})
        elif "penalty" in kn:
            pars.append({"name": f"target{k}", "sets": [f"knots[{k}].penalty.target[0]"]})
    pars.append({"name": "start0", "sets": ["x0[0]"]})
    pd = parse_problem({**doc, "parameters": [{**q, "range": [-1e3, 1e3]} for q in pars]})
    for q, par in zip(pars, pd.parameters):
        q["range"] = [par.nominal - 1.0, par.nominal + 0.5]
    doc["parameters"] = pars
    return doc


@pytest.mark.parametrize("seed", range(6))
def test_random_problems(seed):
    """Seeds 2..5 have [[stages]] entries that override the dynamics (and their drift)."""
    rng = np.random.default_rng(100 + seed)
    n, m, mz, stages = (int(rng.integers(1, 5)), int(rng.integers(1, 3)),
                        int(rng.integers(1, 3)), int(rng.integers(2, 4)))
    doc = _with_parameters(random_doc(seed, n, m, mz, stages, per_stage=seed != 0), rng)
    for mode in ("stagewise", "joint"):
        check_against_fresh(doc, mode=mode, seed=seed)
    check_against_fresh(doc, mode="stagewise", discretization="continuous", seed=seed,
                        draws=1)


@pytest.mark.parametrize("mode", ["stagewise", "joint"])
@pytest.mark.parametrize("discretization", ["exact-zoh", "continuous"])
def test_time_varying_data_with_tracking(mode, discretization):
    doc = tv_doc("linear")
    doc["dynamics"]["f"] = [0.1, -0.3]
    doc["parameters"] = [
        {"name": "mid", "sets": ["knots[0].constraint.value[0]"], "range": [0.0, 1.0]},
        {"name": "rest", "sets": ["knots[1].constraint.value[0]",
                                  "knots[1].penalty.target[0]"], "range": [-0.5, 0.5]},
        {"name": "push", "sets": ["dynamics.f[1]"], "range": [-1.0, 0.0]},
        {"name": "start", "sets": ["x0[0]"], "range": [0.5, 1.5]}]
    check_against_fresh(doc, mode=mode, discretization=discretization)


@pytest.mark.parametrize("mode", ["stagewise", "joint"])
@pytest.mark.parametrize("discretization", ["exact-zoh", "continuous"])
def test_tracking_path_offsets(mode, discretization):
    """Offsets of two tracking paths (the top-level one on two stages, a stage's own), with a
    knot value, the drift and the start as parameters."""
    check_against_fresh(tracked_cart_doc(), mode=mode, discretization=discretization,
                        draws=3 if discretization == "exact-zoh" else 1)


def test_cost_is_the_quadratic_in_theta():
    """`cost_quadratic` fitted from oracle runs inside the range predicts fresh designs'
    J0 at other parameters."""
    doc = robot_goal_doc(50)
    p = parse_problem(doc)
    pd = design_parametric(p)
    J0, g, H = cost_quadratic(p, pd.table)
    nom = np.array([q.nominal for q in p.parameters])
    rng = np.random.default_rng(7)
    for _ in range(3):
        theta = rng.uniform([q.lower for q in p.parameters], [q.upper for q in p.parameters])
        d = theta - nom
        _, fd = _fresh(doc, p, theta, "exact-zoh", "stagewise", 0)
        assert abs(J0 + 2 * g @ d + d @ H @ d - fd.J0) <= 1e-9 * fd.J0


def test_sensitivity_columns_are_not_differences():
    """The goal's column of k0 is the source design alone: doubling the nominal goal leaves
    it unchanged while the nominal k0 changes (a difference of designs would not)."""
    doc = robot_goal_doc(20)
    a = design_parametric(parse_problem(doc)).table
    doc["knots"][1]["constraint"]["value"][0] = doc["knots"][1]["penalty"]["target"][0] = -1.2
    b = design_parametric(parse_problem(doc)).table
    assert np.array_equal(a.S_k0, b.S_k0) and np.array_equal(a.S_lambda0, b.S_lambda0)
    assert not np.array_equal(a.table.k0, b.table.k0)
    assert np.abs(a.S_k0[..., 0]).max() > 0 and not a.S_k0[..., 2].any()   # x0: no column


def test_columns_only_for_per_tick_tables():
    """A spline table has no per-tick columns (its spline columns come from
    `stospline.pipeline.spline_parametric_files`); a Q15 per-tick table has them, scaled with
    its gains (`fixed_parametric`: the gain table and the columns)."""
    from stospline.errors import DesignError
    from stospline.oracle.parametric import parametric_c_files
    doc = robot_goal_doc(20)
    doc["design"] = {"table": "spline"}
    with pytest.raises(DesignError) as err:
        parametric_c_files(parse_problem(doc))
    assert err.value.field == "design.table"
    doc["design"] = {"arith": "q15"}
    p = parse_problem(doc)
    assert sorted(parametric_c_files(p)) == sorted(
        f"{p.name}_q15{s}" for s in (".c", ".h", "_params.c", "_params.h"))


def test_a_knot_band_built_in_python_holds_at_every_vertex_of_the_box():
    """A band at a knot (a problem assembled in Python) with parameters: the design keeps the
    band for every parameter vector of the box, checked by the oracle at every vertex; a band
    narrower than the parameters move the row over is refused, naming the knot and the
    parameter that moves it most."""
    from dataclasses import replace
    from stospline.errors import DesignError
    from stospline.oracle.over_box import vertices
    from stospline.problem.model import Constraint
    p = parse_problem(robot_goal_doc(20))
    kn = p.knots[0]

    def banded(half):
        band = Constraint(kn.constraint.C, None, kn.constraint.value - half,
                          kn.constraint.value + half)
        return replace(p, knots=(replace(kn, constraint=band),) + p.knots[1:])
    q = banded(0.5)
    pd = design_parametric(q, mode="joint")
    assert pd.margins and all(m.holds for m in pd.margins), pd.margins
    for v in vertices(q.parameters):
        y = evaluate_at(q, pd.table, v).knot_constraint[0]
        assert np.all(y >= -0.5 - 1e-9) and np.all(y <= 0.5 + 1e-9), (v, y)
    # The goal and the bend target move the row over 0.67 at the knot: a band 0.4 wide cannot
    # hold over the box.
    with pytest.raises(DesignError) as err:
        design_parametric(banded(0.2), mode="joint")
    assert err.value.field == "knots[0].constraint" and "bend_x" in err.value.reason


def test_float32_table_at_theta_costs_what_a_fresh_float32_table_costs():
    """As flashed: the parametric table at theta rounded to float32 against a fresh design's
    float32 table, both through the exact oracle (float32 rounding of k0 and lambda0 only)."""
    doc = tomllib.loads((EXAMPLES / "robot_goal.toml").read_text())
    p = parse_problem(doc)
    pd = design_parametric(p)
    theta = [-0.6, 5.4]
    q, fd = _fresh(doc, p, theta, "exact-zoh", "stagewise", 0)
    mine = evaluate_at(p, pd.table, theta, quantize=True)
    ref = evaluate_table(q, table_of(fd))
    assert abs(mine.J - ref.J) <= 1e-7 * ref.J
    assert _rel(mine.knot_mean, ref.knot_mean) <= 1e-6
