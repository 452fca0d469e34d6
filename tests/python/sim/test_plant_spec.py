"""The plant step compiled for a problem (`stospline.harness.plant_spec`) computes the bits of
the generic step, runs for the stages it was compiled for, and leaves any other stage to the
generic step."""
from dataclasses import replace

import numpy as np
import pytest

from stospline.harness import controller as controller_module
from stospline.harness.controller import CorridorWatch, build_controller
from stospline.harness.montecarlo import _zoh, simulate
from stospline.pipeline import design_problem
from stospline.problem import load_problem

from conftest import EXAMPLES

PATHS = 256


# with a state cost (eps01), a drift and input noise (quadrotor)
@pytest.fixture(scope="module", params=["robot_corridor", "robot_corridor_eps01", "quadrotor"])
def modules(request):
    """The example, its table's module without a compiled plant and with one."""
    problem = load_problem(EXAMPLES / f"{request.param}.toml")
    table = design_problem(problem).table
    generic = build_controller(table)
    return problem, generic, generic.for_plant(problem)


def _states(problem, rng):
    """States and commands with exact zeros of both signs among them (the sums' signs of
    zero are where a dropped term could show)."""
    X = rng.standard_normal((PATHS, problem.n)) * 3.0
    X[:8] = 0.0
    X[8:16] = -0.0
    X[16:24, ::2] = 0.0
    U = rng.standard_normal((PATHS, problem.m)).astype(np.float32)
    U[:4] = 0.0
    U[4:12] = -0.0
    return X, U


def _run(ctl, plant, X, U, dZ, ticks=20):
    """The states and costs after every tick (a sign of zero may not last many ticks)."""
    X, cost, out = X.copy(), np.zeros(len(X)), []
    for j in range(ticks):
        ctl.plant_tick(plant, dZ[j], U, X, cost)
        out.append(X.copy())
    return np.stack(out), cost


@pytest.mark.parametrize("substeps", [1, 3])
def test_compiled_step_is_bit_identical(modules, substeps):
    problem, generic, compiled = modules
    assert compiled.plant_source is not None and generic.plant_source is None
    rng = np.random.default_rng(substeps)
    X, U = _states(problem, rng)
    for k, stage in enumerate(problem.stages):
        dt = 1.0 / generic.table.tick_hz / substeps
        dZ = rng.standard_normal((20, PATHS, substeps, stage.G.shape[2]))
        dZ[:, :4] = 0.0
        plants = [c.plant(stage, *_zoh(stage, dt), dt, substeps) for c in (generic, compiled)]
        assert generic.lib.harness_plant_compiled(plants[0].c) == 0
        assert compiled.lib.harness_plant_compiled(plants[1].c) == 1, f"stage {k}"
        (Xg, cg), (Xc, cc) = (_run(c, pl, X, U, dZ) for c, pl in zip((generic, compiled),
                                                                       plants))
        assert Xg.tobytes() == Xc.tobytes() and cg.tobytes() == cc.tobytes(), f"stage {k}"


def test_other_data_run_the_generic_step(modules):
    """A stage with other coefficients and a noise entry the compiled step does not have is
    not run by it, and still gets the generic step's bits."""
    problem, generic, compiled = modules
    stage = problem.stages[0]
    rng = np.random.default_rng(7)
    G = stage.G.copy()
    G[tuple(np.argwhere(G == 0)[0])] = 0.5
    other = replace(stage, A=stage.A + 0.25 * rng.standard_normal(stage.A.shape),
                    R=stage.R * 1.5, G=G)
    dt = 1.0 / generic.table.tick_hz
    X, U = _states(problem, rng)
    dZ = rng.standard_normal((20, PATHS, 1, stage.G.shape[2]))
    plants = [c.plant(other, *_zoh(other, dt), dt, 1) for c in (generic, compiled)]
    assert compiled.lib.harness_plant_compiled(plants[1].c) == 0
    (Xg, cg), (Xc, cc) = (_run(c, pl, X, U, dZ) for c, pl in zip((generic, compiled), plants))
    assert Xg.tobytes() == Xc.tobytes() and cg.tobytes() == cc.tobytes()


@pytest.mark.parametrize("example", ["robot_corridor", "robot_corridor_eps01"])
def test_simulate_numbers_do_not_depend_on_the_compiled_step(example, monkeypatch):
    """The whole fused run (controller, plant, corridor watch, statistics) with the compiled
    step and corridor equals the run with the generic ones, exits included."""
    problem = load_problem(EXAMPLES / f"{example}.toml")
    generic = build_controller(design_problem(problem).table)
    compiled = generic.for_plant(problem)
    watch = CorridorWatch.of(problem.corridors, 1, problem.t0, generic.table.tick_hz)
    for ctl, expected in ((compiled, 1), (generic, 0)):
        cors, _ = watch.c_structs(ctl.ffi)
        for k in range(len(problem.corridors)):
            assert ctl.lib.harness_corridor_compiled(cors + k, k, problem.n) == expected
    runs = [simulate(problem, generic, paths=1000, seed=3, substeps=2, workers=1,
                     per_path=True)]
    monkeypatch.setattr(controller_module, "plant_source", lambda *args: None)
    runs.append(simulate(problem, generic, paths=1000, seed=3, substeps=2, workers=1,
                         per_path=True))
    a, b = runs
    assert np.count_nonzero(a.exit_tick >= 0) > 0        # exits to compare
    assert a.cost.tobytes() == b.cost.tobytes()
    assert all(x.tobytes() == y.tobytes() for x, y in zip(a.knot_states, b.knot_states))
    assert a.exit_tick.tobytes() == b.exit_tick.tobytes()
    assert a.exit_wall.tobytes() == b.exit_wall.tobytes()


@pytest.mark.parametrize("noise", [True, False])
def test_compiled_module_builds_without_warnings(noise, tmp_path, monkeypatch):
    """The module with the compiled step and corridors builds under the harness's flags plus
    -Werror, for a noisy plant and for a noise-free one (no increments to read)."""
    from stospline.harness import build as build_module
    text = (EXAMPLES / "robot_corridor.toml").read_text()
    if not noise:
        start = text.index("noise = [")
        text = text[:start] + text[text.index("]\n", text.index("state = 3")) + 2:]
    src = tmp_path / "p.toml"
    src.write_text(text)
    problem = load_problem(src)
    assert bool(np.any(problem.stages[0].G)) == noise
    monkeypatch.setattr(build_module, "HARNESS_CFLAGS", build_module.HARNESS_CFLAGS + ["-Werror"])
    table = design_problem(problem).table
    ctl = build_controller(table, build_dir=tmp_path / "build", plant=problem)
    assert ctl.plant_source is not None
