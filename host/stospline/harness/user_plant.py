"""Monte Carlo of the compiled controller against a ``[plant]`` model itself
(`stospline.problem.plant_c.PlantModel`), not its linearisation.

Each tick the controller (the firmware built with the table, `CompiledController`) computes
the commands of every path from its state; the model is then integrated over the tick by
Euler–Maruyama with `substeps` steps, the command held:

    x+ = x + f(t, x, u) dt + g(t, x, u) dZ,      dZ ~ N(0, dt I).

Alongside, the same paths are integrated with twice the substeps on the same Brownian path (a
coarse increment is the sum of two fine ones), each with its own controllers: the difference of
the two runs' knot means estimates the scheme's error (order 1 in dt for the means), which the
verdict reports beside the statistical error. The running cost is the left-point rule per
substep; knot penalties are added at the knots; corridor exits are watched after every tick.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stospline.harness.controller import STATUS, CorridorWatch

__all__ = ["PlantRun", "simulate_model"]


@dataclass
class PlantRun:
    """Per path: ``knots[k]`` the state at knot k (paths, n), ``cost`` the realised cost
    (paths,); ``fine_knot_means[k]`` the knot means with twice the substeps (same Brownian
    path); ``exits`` (corridors, paths) the first state tick outside each corridor (-1:
    none); ``worst_status`` the lowest controller status; ``saturated`` commands clipped."""
    paths: int
    seed: int
    substeps: int
    knots: list
    cost: np.ndarray
    fine_knot_means: list
    exits: np.ndarray
    worst_status: int
    saturated: int


def _running_cost(stage, X: np.ndarray, U: np.ndarray) -> np.ndarray:
    c = np.einsum("pi,ij,pj->p", U, stage.R, U) + 2 * U @ stage.r + stage.rho
    if np.any(stage.Q) or np.any(stage.S) or np.any(stage.q):
        c += np.einsum("pi,ij,pj->p", X, stage.Q, X) + 2 * np.einsum(
            "pi,ij,pj->p", X, stage.S, U) + 2 * X @ stage.q
    return c


def _penalty(knot, X: np.ndarray) -> np.ndarray:
    if knot.penalty is None:
        return np.zeros(X.shape[0])
    r = X @ knot.penalty.C.T - knot.penalty.target
    return knot.penalty.weight * np.sum(r * r, axis=1)


def _em(model, t: float, X: np.ndarray, U: np.ndarray, dt: float, dZ: np.ndarray):
    f = model.drift(t, X, U)
    g = model.diffusion(t, X, U)
    return X + f * dt + np.einsum("pij,pj->pi", g, dZ)


def simulate_model(problem, controller, model, *, paths: int, seed: int,
                   substeps: int) -> PlantRun:
    """Run `paths` paths of `controller` (built for `problem`'s table) on `model` from x0 with
    the generator seeded by `seed` (`numpy.random.default_rng`)."""
    rng = np.random.default_rng(seed)
    n, h = problem.n, 1.0 / problem.tick_hz
    coarse_step, fine_step = controller.real_stepper(paths), controller.real_stepper(paths)
    X = np.tile(problem.x0, (paths, 1)).astype(float)
    Xf = X.copy()
    cost = np.zeros(paths)
    watch = CorridorWatch.of(problem.corridors, paths, problem.t0, problem.tick_hz)
    watch.check(0, X)
    knot_ticks = np.cumsum(problem.ticks_per_stage)
    knots, fine, worst, saturated = [], [], 0, 0
    dt = h / substeps
    j = 0
    for k, (stage, ticks) in enumerate(zip(problem.stages, problem.ticks_per_stage)):
        for _ in range(ticks):
            t = problem.t0 + j * h
            U, status = coarse_step(j, X)
            U = np.asarray(U, dtype=float)
            Uf = np.asarray(fine_step(j, Xf)[0], dtype=float)
            worst = min(worst, int(status.min()))
            saturated += int(np.sum(status == STATUS["WARN_SATURATED"]))
            cost_stage = stage.at(t + h / 2)
            for s in range(substeps):
                dz = rng.standard_normal((2, paths, model.mz)) * np.sqrt(dt / 2)
                ts = t + s * dt
                cost += _running_cost(cost_stage, X, U) * dt
                X = _em(model, ts, X, U, dt, dz[0] + dz[1])
                Xf = _em(model, ts, Xf, Uf, dt / 2, dz[0])
                Xf = _em(model, ts + dt / 2, Xf, Uf, dt / 2, dz[1])
            j += 1
            watch.check(j, X)
        assert j == knot_ticks[k]
        knots.append(X.copy())
        fine.append(Xf.mean(axis=0))
        cost += _penalty(problem.knots[k], X)
    return PlantRun(paths, seed, substeps, knots, cost, fine, watch.exit_tick, worst,
                    saturated)
