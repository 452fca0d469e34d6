"""Monte Carlo of the compiled controller against a ``[plant]`` model itself
(`stospline.problem.plant_c.PlantModel`), not its linearisation.

Each tick the controller (the firmware built with the table, `CompiledController`) computes
the commands of every path from its state; the model is then integrated over the tick with
`substeps` steps, the command held, by exponential Euler–Maruyama about the linearisation the
table was designed on (`model_step`):

    x+ = Ad x + Bd u + fd + dt (f(t, x, u) − A x − B u − c) + g(t, x, u) dZ.

The increments dZ ~ N(0, dt I) come from the linear harness's normal numbers (`block_streams`:
blocks of 512 paths, each on its own stream, drawn by the harness's C generator), so on a model
linear in x and u, whose remainder f − A x − B u − c is zero, a run is the linear harness's
run of the linearisation with the same seed: the same paths, to rounding.

Alongside, the same paths are integrated with twice the substeps on the same Brownian path
(each coarse increment split in two by a Brownian bridge), each with its own controllers: for a
scheme of weak order 1, twice the difference of the two runs estimates the coarse run's bias,
which the verdict reports beside the statistical error. The running cost is the left-point
rule per substep; knot penalties are added at the knots; corridor exits are watched after
every tick.

With faults (`stospline.problem.faults.Faults`) the loop around the model is the linear
harness's (``harness_tick_faults``): per tick the controller measures the state plus
``sensor_noise`` times a standard normal, rounded to ``sensor_quantum``; a missed tick (a
uniform number below ``miss_probability``) does not run the controller, whose state is left as
it was, and the actuator holds its command; with ``delay_ticks = 1`` the command is applied
from the next tick (the safe command ``u_hold`` over tick 0); the model receives the applied
command plus ``actuator_noise`` times a standard normal; ``plant_noise_scale`` multiplies the
model's diffusion. The fault numbers are drawn as the harness draws them (`FaultDraws`, sensor
then actuator then missed ticks, from each block's fault stream), and the coarse and the fine
run share them. ``plant_A_scale`` and ``plant_B_scale`` have no meaning for a
model whose drift is not split into A x + B u (`model_faults_unsupported`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stospline.errors import ProblemError
from stospline.harness.controller import STATUS, CorridorWatch, FaultDraws
from stospline.harness.block_streams import BlockStreams
from stospline.harness.model_step import TickSteps
from stospline.problem.faults import Faults

__all__ = ["PlantRun", "simulate_model", "model_faults_unsupported"]

# The faults that scale the linear plant's A and B: a model's drift has no such parts.
_LINEAR_ONLY = ("plant_A_scale", "plant_B_scale")


def model_faults_unsupported(faults: Faults) -> tuple[str, str] | None:
    """``(key, reason)`` of the first fault the loop around a ``[plant]`` model cannot apply,
    or None."""
    for key in _LINEAR_ONLY:
        if key in faults.as_dict():
            return key, ("does not apply to a [plant] model: its drift f(t, x, u) is not "
                         "split into A x + B u to scale (plant_noise_scale scales its "
                         "diffusion)")
    return None


@dataclass
class PlantRun:
    """Per path: ``knots[k]`` the state at knot k (paths, n), ``cost`` the realised cost
    (paths,); ``fine_knots``, ``fine_cost`` the same with half the step (same Brownian
    path); ``exits`` (corridors, paths) the first state tick outside each corridor (-1:
    none); ``worst_status`` the lowest controller status; ``saturated`` commands clipped.
    For figures, as the linear harness's `MonteCarloResult`: ``sample_t`` the tick times
    (ticks + 1,), ``mean_x`` the mean path (ticks + 1, n), ``sample_x`` path 0 (ticks + 1, n)
    and ``sample_u`` the commands applied to it (ticks, m); ``u_low``, ``u_high`` the
    smallest and largest command applied per input (m,)."""
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
    sample_t: np.ndarray
    mean_x: np.ndarray
    sample_x: np.ndarray
    sample_u: np.ndarray
    u_low: np.ndarray
    u_high: np.ndarray
    faults: Faults = Faults()


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


class _Loop:
    """One of the two runs (coarse or fine) of the loop: its controllers, the actuator's held
    commands (with faults or a table designed for a delay) and the controllers' memory, kept
    to undo the step of a missed tick."""

    def __init__(self, controller, paths: int, draws: FaultDraws | None):
        self.step = controller.real_stepper(paths)
        self.held = None if draws is None else draws.held.copy()
        self.memory = None
        if draws is not None and draws.miss_u is not None:
            ffi = controller.ffi
            self.memory = np.frombuffer(ffi.buffer(self.step.instances),
                                        dtype=np.uint8).reshape(paths, -1)

    def command(self, j: int, X: np.ndarray, draws: FaultDraws | None):
        """``(applied command (paths, m), status of the paths whose controller ran)``."""
        if draws is None:
            U, status = self.step(j, X)
            return np.asarray(U, dtype=float), status
        xm = X
        if draws.sensor_std is not None:
            xm = X + draws.sensor_std * draws.sensor_z
        if draws.quantum is not None:
            q = np.where(draws.quantum > 0, draws.quantum, 1.0)
            xm = np.where(draws.quantum > 0, q * np.floor(xm / q + 0.5), xm)
        if draws.feed_held:
            xm = np.hstack([xm, self.held])
        run = (slice(None) if draws.miss_u is None
               else draws.miss_u >= draws.miss_probability)
        saved = None if self.memory is None else self.memory.copy()
        U, status = self.step(j, xm)
        if saved is not None:               # a missed tick leaves the controller untouched
            missed = ~run
            self.memory[missed] = saved[missed]
        c = np.asarray(U, dtype=float)
        ud = self.held.copy()
        self.held[run] = c[run]
        if not draws.delay_ticks:
            ud[run] = c[run]
        if draws.actuator_std is not None:
            ud += draws.actuator_std * draws.actuator_z
        return ud, np.asarray(status)[run]


def simulate_model(problem, controller, model, *, paths: int, seed,
                   substeps: int, faults: Faults | None = None) -> PlantRun:
    """Run `paths` paths of `controller` (built for `problem`'s table; `problem` the
    linearisation it was designed on) on `model` from x0 with the random streams of `seed` (an
    integer or a `numpy.random.SeedSequence`, as the linear harness's `simulate`), in a loop
    with `faults` (default none; `model_faults_unsupported` refused with ValueError)."""
    faults = Faults() if faults is None else faults
    why = model_faults_unsupported(faults)
    if why:
        raise ValueError(f"{why[0]} {why[1]}")
    n, h = problem.n, 1.0 / problem.tick_hz
    table = controller.table
    delayed = int(getattr(table, "delay_ticks", 0))
    draws = (FaultDraws.of(faults, paths, n, np.asarray(table.u_hold, dtype=float), delayed)
             if faults.any or delayed else None)
    dt = h / substeps
    noise = float(faults.plant_noise_scale)
    scale, scale_fine = float(np.sqrt(dt)) * noise, float(np.sqrt(dt / 2)) * noise
    streams = BlockStreams(controller, seed, paths, substeps, model.mz,
                           faults=draws is not None)
    steps = TickSteps(problem, dt)
    coarse, fine = _Loop(controller, paths, draws), _Loop(controller, paths, draws)
    X = np.tile(problem.x0, (paths, 1)).astype(float)
    Xf = X.copy()
    cost, cost_f = np.zeros(paths), np.zeros(paths)
    watch = CorridorWatch.of(problem.corridors, paths, problem.t0, problem.tick_hz)
    watch.check(0, X)
    knot_ticks = np.cumsum(problem.ticks_per_stage)
    knots, fine_knots, worst, saturated = [], [], 0, 0
    total = int(knot_ticks[-1])
    mean_x, sample_x = np.empty((total + 1, n)), np.empty((total + 1, n))
    sample_u = np.empty((total, problem.m))
    u_low, u_high = np.full(problem.m, np.inf), np.full(problem.m, -np.inf)
    mean_x[0], sample_x[0] = X.mean(axis=0), X[0]
    j = 0
    for k, (stage, ticks) in enumerate(zip(problem.stages, problem.ticks_per_stage)):
        for _ in range(ticks):
            t = problem.t0 + j * h
            streams.draw(draws)
            U, status = coarse.command(j, X, draws)
            Uf = fine.command(j, Xf, draws)[0]
            if status.size:
                worst = min(worst, int(status.min()))
            saturated += int(np.sum(status == STATUS["WARN_SATURATED"]))
            cost_stage = stage.at(t + h / 2)
            lin, lin_fine = steps.at(k, j)
            xs = model.exp_em_steps(t, dt, scale, X, U, lin, streams.z)
            xf = model.exp_em_steps(t, dt / 2, scale_fine, Xf, Uf, lin_fine, streams.z_fine)
            for s in range(substeps):       # the left-point rule on every substep
                cost += _running_cost(cost_stage, xs[:, s], U) * dt
                cost_f += (_running_cost(cost_stage, xf[:, 2 * s], Uf)
                           + _running_cost(cost_stage, xf[:, 2 * s + 1], Uf)) * (dt / 2)
            sample_u[j] = U[0]
            u_low, u_high = np.minimum(u_low, U.min(axis=0)), np.maximum(u_high, U.max(axis=0))
            j += 1
            mean_x[j], sample_x[j] = X.mean(axis=0), X[0]
            if not np.all(np.isfinite(X)):
                raise ProblemError("plant.source", f"the model's state became NaN or "
                                                   f"infinite on a Monte Carlo path by "
                                                   f"t = {problem.t0 + j * h:g}")
            watch.check(j, X)
        assert j == knot_ticks[k]
        knots.append(X.copy())
        fine_knots.append(Xf.copy())
        cost += _penalty(problem.knots[k], X)
        cost_f += _penalty(problem.knots[k], Xf)
    return PlantRun(paths, seed, substeps, knots, cost, fine_knots, cost_f, watch.exit_tick,
                    worst, saturated, problem.t0 + np.arange(total + 1) * h, mean_x, sample_x,
                    sample_u, u_low, u_high, faults)
