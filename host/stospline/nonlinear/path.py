"""The mean path a linearisation is taken around: the state at every tick, the command held
over each tick, and the points (tick midpoints) where the model is linearised."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["MeanPath", "path_change"]


@dataclass(frozen=True)
class MeanPath:
    """``x`` (ticks + 1, n) the mean state at the ticks ``t`` (ticks + 1,); ``u`` (ticks, m)
    the mean command held over each tick."""
    t: np.ndarray
    x: np.ndarray
    u: np.ndarray

    @classmethod
    def from_guess(cls, t: np.ndarray, x0: np.ndarray, m: int, guess) -> "MeanPath":
        """The first path: `guess` ``(t, x, u)`` interpolated linearly (its ends held), or x0
        held with zero input."""
        if guess is None:
            return cls(t, np.tile(x0, (t.size, 1)), np.zeros((t.size - 1, m)))
        gt, gx, gu = guess
        x = np.stack([np.interp(t, gt, gx[:, i]) for i in range(gx.shape[1])], axis=1)
        x[0] = x0
        starts = t[:-1]           # a tick's command: the guess at the tick's start
        u = np.zeros((starts.size, m)) if gu is None else \
            np.stack([np.interp(starts, gt, gu[:, j]) for j in range(m)], axis=1)
        return cls(t, x, u)

    def points(self, index: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(t, x, u)`` at the ticks `index`, with the command of the tick that starts there
        (of the last tick at the end)."""
        return self.t[index], self.x[index], self.u[np.minimum(index, self.u.shape[0] - 1)]

    def vector(self) -> np.ndarray:
        return np.concatenate([self.x.ravel(), self.u.ravel()])

    def with_vector(self, v: np.ndarray) -> "MeanPath":
        nx = self.x.size
        return MeanPath(self.t, v[:nx].reshape(self.x.shape), v[nx:].reshape(self.u.shape))


def path_change(old: MeanPath, new: MeanPath) -> float:
    """The largest change of a mean state or command between two paths, each component
    relative to ``1 + its largest magnitude`` on the old path (so a path of metres and one of
    radians are judged alike)."""
    dx = np.abs(new.x - old.x) / (1 + np.max(np.abs(old.x), axis=0))
    du = np.abs(new.u - old.u) / (1 + np.max(np.abs(old.u), axis=0))
    return float(max(np.max(dx, initial=0.0), np.max(du, initial=0.0)))
