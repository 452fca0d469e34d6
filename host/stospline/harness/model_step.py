"""The linear part of a ``[plant]`` model's step in the Monte Carlo (`user_plant`): the
linearisation the table was designed on, frozen over a tick, and its exact step.

The model's step is exponential Euler–Maruyama about that linearisation (A, B, c):

    x+ = Ad x + Bd u + fd + dt (f(t, x, u) − A x − B u − c) + g(t, x, u) dZ,

``Ad, Bd, fd`` the exact step of ``dx = (A x + B u + c) dt`` over dt (`plant_spec.zoh_step`, the
linear harness's). The remainder f − A x − B u − c vanishes on a model linear in x and u (to
rounding; exactly when the linearisation gives its coefficients), and the step is then the
linear harness's; otherwise it is Euler–Maruyama's on the remainder: weak order 1, the same
as plain Euler–Maruyama, with the linear part of the drift integrated exactly.
"""
from __future__ import annotations

import numpy as np

from stospline.harness.plant_spec import zoh_step

__all__ = ["linear_step", "TickSteps"]


def linear_step(stage, dt: float) -> np.ndarray:
    """``[Ad, Bd, fd, A, B, c]`` raveled (`PlantModel.exp_em_steps`'s `lin`): `stage`'s
    linear drift (time-invariant: frozen already) and its exact step over dt."""
    Ad, Bd, fd = zoh_step(stage, dt)
    n = stage.A.shape[0]
    zero = np.zeros(n)
    return np.concatenate([Ad.ravel(), Bd.ravel(), zero if fd is None else fd,
                           np.ravel(stage.A), np.ravel(stage.B),
                           zero if stage.f is None else np.ravel(stage.f)])


class TickSteps:
    """`at(k, t)`: the `linear_step` pair (steps of dt, of dt / 2) of stage k over the tick
    from t: a time-invariant stage's computed once, a varying one's at the tick's midpoint."""

    def __init__(self, problem, dt: float):
        self.problem, self.dt, self.h = problem, dt, 1.0 / problem.tick_hz
        self._fixed = {}

    def at(self, k: int, t: float) -> tuple[np.ndarray, np.ndarray]:
        stage = self.problem.stages[k]
        if stage.varying is None and k in self._fixed:
            return self._fixed[k]
        frozen = stage.at(t + self.h / 2)
        pair = linear_step(frozen, self.dt), linear_step(frozen, self.dt / 2)
        if stage.varying is None:
            self._fixed[k] = pair
        return pair
