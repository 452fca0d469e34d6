"""Monte Carlo of the compiled controller against a ``[plant]`` model itself
(`stospline.problem.plant_c.PlantModel`), not its linearisation.

Each tick the controller (the firmware built with the table, `CompiledController`) computes
the commands of every path from its state; the model is then integrated over the tick by
Euler–Maruyama with `substeps` steps, the command held:

    x+ = x + f(t, x, u) dt + g(t, x, u) dZ,      dZ ~ N(0, dt I).

Alongside, the same paths are integrated with twice the substeps on the same Brownian path (a
coarse increment is the sum of two fine ones), each with its own controllers: for a scheme of
weak order 1, twice the difference of the two runs estimates the coarse run's bias, which the
verdict reports beside the statistical error. The running cost is the left-point rule per
substep; knot penalties are added at the knots; corridor exits are watched after every tick.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stospline.errors import ProblemError
from stospline.harness.controller import STATUS, CorridorWatch

__all__ = ["PlantRun", "simulate_model"]


@dataclass
class PlantRun:
    """Per path: ``knots[k]`` the state at knot k (paths, n), ``cost`` the realised cost
    (paths,); ``fine_knots``, ``fine_cost`` the same with twice the substeps (same Brownian
    path); ``exits`` (corridors, paths) the first state tick outside each corridor (-1:
    none); ``worst_status`` the lowest controller status; ``saturated`` commands clipped."""
    paths: int
    seed: int
    substeps: int
    knots: list
    cost: np.ndarray
    fine_knots: list
    fine_cost: np.ndarray
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


def simulate_model(problem, controller, model, *, paths: int, seed: int,
                   substeps: int) -> PlantRun:
    """Run `paths` paths of `controller` (built for `problem`'s table) on `model` from x0 with
    the generator seeded by `seed` (`numpy.random.default_rng`)."""
    rng = np.random.default_rng(seed)
    n, h = problem.n, 1.0 / problem.tick_hz
    coarse_step, fine_step = controller.real_stepper(paths), controller.real_stepper(paths)
    X = np.tile(problem.x0, (paths, 1)).astype(float)
    Xf = X.copy()
    cost, cost_f = np.zeros(paths), np.zeros(paths)
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
            dz = rng.standard_normal((paths, 2 * substeps, model.mz)) * np.sqrt(dt / 2)
            xs = model.em_steps(t, dt, X, U, dz[:, 0::2] + dz[:, 1::2])
            xf = model.em_steps(t, dt / 2, Xf, Uf, dz)
            for s in range(substeps):       # the left-point rule on every substep
                cost += _running_cost(cost_stage, xs[:, s], U) * dt
                cost_f += (_running_cost(cost_stage, xf[:, 2 * s], Uf)
                           + _running_cost(cost_stage, xf[:, 2 * s + 1], Uf)) * (dt / 2)
            j += 1
            if not np.all(np.isfinite(X)):
                raise ProblemError("plant.source", f"the model's state became NaN or "
                                                   f"infinite on a Monte Carlo path by "
                                                   f"t = {problem.t0 + j * h:g}")
            watch.check(j, X)
        assert j == knot_ticks[k]
        knots.append(X.copy())
        fine.append(Xf.copy())
        cost += _penalty(problem.knots[k], X)
        cost_f += _penalty(problem.knots[k], Xf)
    return PlantRun(paths, seed, substeps, knots, cost, fine, cost_f, watch.exit_tick, worst,
                    saturated)
