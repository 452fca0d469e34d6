"""The linear part of a ``[plant]`` model's step in the Monte Carlo (`user_plant`): the
linearisation the table was designed on, frozen over a tick, and its exact step.

The model's step is exponential Euler–Maruyama about that linearisation (A, B, c):

    x+ = Ad x + Bd u + fd + dt (f(t, x, u) − A x − B u − c) + g(t, x, u) dZ,

``Ad, Bd, fd`` the exact step of ``dx = (A x + B u + c) dt`` over dt (of time-invariant data,
the linear harness's own: `plant_spec.zoh_step`). The remainder f − A x − B u − c vanishes
on a model linear in x and u (to rounding; exactly when the linearisation gives its
coefficients), and the step is then the linear harness's; otherwise it is Euler–Maruyama's on
the remainder: weak order 1, the same as plain Euler–Maruyama, with the linear part of the
drift integrated exactly.
"""
from __future__ import annotations

import numpy as np

from stospline.expm import expm_many
from stospline.harness.plant_spec import zoh_step

__all__ = ["linear_step", "TickSteps"]

# Ticks of a time-varying stage whose steps are computed at once (`expm_many`).
_CHUNK = 256


def linear_step(stage, dt: float) -> np.ndarray:
    """``[Ad, Bd, fd, A, B, c]`` raveled (`PlantModel.exp_em_steps`'s `lin`) of a
    time-invariant `stage`: its linear drift and its exact step over dt as the linear harness
    computes it (`zoh_step`)."""
    Ad, Bd, fd = zoh_step(stage, dt)
    n = stage.A.shape[0]
    zero = np.zeros(n)
    return np.concatenate([Ad.ravel(), Bd.ravel(), zero if fd is None else fd,
                           np.ravel(stage.A), np.ravel(stage.B),
                           zero if stage.f is None else np.ravel(stage.f)])


def _linear_steps(data: dict, dt: float) -> np.ndarray:
    """`linear_step` of each of a stack of samples (`Stage.samples`), (T, length)."""
    A, B = data["A"], data["B"]
    T, n, m = B.shape
    f = np.zeros((T, n)) if data["f"] is None else data["f"]
    big = np.zeros((T, n + m + 1, n + m + 1))
    big[:, :n, :n], big[:, :n, n:n + m], big[:, :n, -1] = A, B, f
    E = expm_many(big * dt)
    return np.concatenate([E[:, :n, :n].reshape(T, -1), E[:, :n, n:n + m].reshape(T, -1),
                           E[:, :n, -1], A.reshape(T, -1), B.reshape(T, -1), f], axis=1)


class TickSteps:
    """`at(k, j)`: the `linear_step` pair (steps of dt, of dt / 2) of stage k over tick j: a
    time-invariant stage's computed once, a varying one's with its data at the tick's
    midpoint, `_CHUNK` ticks at a time."""

    def __init__(self, problem, dt: float):
        self.problem, self.dt, self.h = problem, dt, 1.0 / problem.tick_hz
        self._fixed: dict = {}
        self._chunk = (-1, 0, None)          # (stage, first tick, (steps of dt, of dt / 2))

    def at(self, k: int, j: int) -> tuple[np.ndarray, np.ndarray]:
        stage = self.problem.stages[k]
        if stage.varying is None:
            if k not in self._fixed:
                self._fixed[k] = linear_step(stage, self.dt), linear_step(stage, self.dt / 2)
            return self._fixed[k]
        ck, first, steps = self._chunk
        if ck != k or not first <= j < first + _CHUNK:
            times = self.problem.t0 + (j + 0.5 + np.arange(_CHUNK)) * self.h
            data = stage.samples(times)
            first, steps = j, (_linear_steps(data, self.dt), _linear_steps(data, self.dt / 2))
            self._chunk = (k, first, steps)
        return steps[0][j - first], steps[1][j - first]
