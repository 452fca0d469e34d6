"""A linear model given in C is the linear problem it writes: its linearisation is the linear
file's data (time-invariant, no drift term), so the design is the same to rounding; and its
Monte Carlo on the model with the same seed runs the linear harness's paths (the same normal
numbers in the same blocks, a step that on a linear model is the harness's exponential
Euler-Maruyama step), so every path's knot states, cost and corridor exit agree to rounding,
with and without faults."""
import numpy as np
import pytest

from stospline.harness.controller import build_controller
from stospline.harness.montecarlo import BLOCK_PATHS, simulate
from stospline.harness.user_plant import simulate_model
from stospline.nonlinear.iterate import fit_plant
from stospline.pipeline import design_problem
from stospline.problem.faults import parse_faults
from stospline.problem.reader import parse_problem
from support.plant_sources import LINEAR, linear_doc, the_same_linear_doc

# Rounding: the design's numbers are the same operations on the same data; the paths' differ
# at most by the order of a cost's sums.
RTOL = 1e-12
PATHS, SUBSTEPS, SEED = 2 * BLOCK_PATHS + 100, 4, 35     # three blocks, the last one short
# x <= 1.02 while the mean passes 1 at t = 1: some paths leave.
CORRIDOR = {"t": [0.5, 1.5], "C": [[1, 0]],
            "polygons": [{"A": [[1], [-1]], "b": [1.02, 1.0]}]}


@pytest.fixture(scope="module")
def both(tmp_path_factory):
    """The double integrator with a corridor: as a [plant] in C, fitted and designed, and as
    a linear problem, designed."""
    where = tmp_path_factory.mktemp("plant")
    (where / "model.c").write_text(LINEAR)
    plant_doc, linear = linear_doc(), the_same_linear_doc()
    plant_doc["corridors"] = linear["corridors"] = [CORRIDOR]
    problem, fit = fit_plant(plant_doc, where)
    return design_problem(problem), fit.model, design_problem(parse_problem(linear))


def _relative(a, b) -> float:
    return float(np.max(np.abs(np.asarray(a) - b)) / np.max(np.abs(b)))


def test_the_linearisation_is_the_linear_problem(both):
    dp, _, dl = both
    for sp, sl in zip(dp.problem.stages, dl.problem.stages):
        assert sp.varying is None and sp.f is None
        for name in ("A", "B", "G"):
            assert _relative(getattr(sp, name), getattr(sl, name)) <= RTOL, name
    assert abs(dp.design.J0 / dl.design.J0 - 1) <= RTOL
    assert abs(dp.implemented.J / dl.implemented.J - 1) <= RTOL
    gp, gl = dp.gains(quantized=False), dl.gains(quantized=False)
    for name in ("K", "k0", "L"):
        assert _relative(getattr(gp, name), getattr(gl, name)) <= RTOL, name


@pytest.mark.parametrize("raw", [{}, {"sensor_noise": 0.05, "actuator_noise": 0.5,
                                      "delay_ticks": 1},
                                 {"miss_probability": 0.3, "sensor_quantum": 0.1}],
                         ids=["no_faults", "linear_faults", "nonlinear_faults"])
def test_the_model_runs_the_linear_harness_paths(both, raw):
    dp, model, dl = both
    faults = parse_faults(raw, 2, 1)
    run = simulate_model(dp.problem, build_controller(dp.table), model, paths=PATHS,
                         seed=SEED, substeps=SUBSTEPS, faults=faults)
    mc = simulate(dl.problem, build_controller(dl.table), paths=PATHS, seed=SEED,
                  substeps=SUBSTEPS, faults=faults, workers=1, per_path=True)
    for k, X in enumerate(run.knots):
        np.testing.assert_allclose(X, mc.knot_states[k], rtol=RTOL, atol=RTOL)
        assert _relative(X.mean(axis=0), mc.knot_moments[k].mean) <= 1e-9
        assert _relative(np.cov(X.T), mc.knot_cov(k)) <= 1e-9
    np.testing.assert_allclose(run.cost, mc.cost, rtol=RTOL)
    assert abs(run.cost.mean() / mc.cost_mean_ci()[0] - 1) <= 1e-9
    np.testing.assert_array_equal(run.exits, mc.exit_tick)
    assert 0 < mc.exit_count(0) < PATHS
    assert int(np.sum(run.exits[0] >= 0)) == mc.exit_count(0)
    # What the figures draw: the mean path, path 0 and (without faults, when the command
    # path 0's controller computes is the one applied) its commands.
    np.testing.assert_allclose(run.mean_x, mc.mean_x, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(run.sample_x, mc.sample_x, rtol=RTOL, atol=RTOL)
    np.testing.assert_allclose(run.sample_t, mc.sample_t, rtol=RTOL)
    if not faults.any:
        np.testing.assert_allclose(run.sample_u, mc.sample_u, rtol=1e-6)
        np.testing.assert_allclose(run.u_low, mc.u_low, rtol=1e-6)
        np.testing.assert_allclose(run.u_high, mc.u_high, rtol=1e-6)
