"""Sampled time-varying problem data: values at times, interpolated linearly or held."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Series"]


@dataclass(frozen=True)
class Series:
    """Samples ``values[i]`` at times ``t[i]`` with "linear" or "zoh" (hold the last sample)
    interpolation; times outside the samples take the nearest end value."""
    t: np.ndarray
    values: np.ndarray
    interpolation: str
    path: str

    def __call__(self, t: float) -> np.ndarray:
        ts = self.t
        if t <= ts[0]:
            return self.values[0]
        if t >= ts[-1]:
            return self.values[-1]
        i = int(np.searchsorted(ts, t, side="right")) - 1
        if self.interpolation == "zoh":
            return self.values[i]
        w = (t - ts[i]) / (ts[i + 1] - ts[i])
        return (1 - w) * self.values[i] + w * self.values[i + 1]
