"""Sampled time-varying problem data: values at times, interpolated linearly or held."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Series", "sample_varying"]


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

    def many(self, times: np.ndarray) -> np.ndarray:
        """The values at every time of `times` (stacked on a first axis), equal to calling the
        series at each: the same formula, vectorised."""
        times = np.asarray(times, dtype=float)
        ts, vals = self.t, self.values
        if ts.size == 1:
            return np.repeat(vals[:1], times.size, axis=0)
        i = np.clip(np.searchsorted(ts, times, side="right") - 1, 0, ts.size - 2)
        if self.interpolation == "zoh":
            i = np.where(times >= ts[-1], ts.size - 1, i)
            return vals[i]
        w = np.clip((times - ts[i]) / (ts[i + 1] - ts[i]), 0.0, 1.0)[:, None]
        flat = vals.reshape(vals.shape[0], -1)       # one long row per sample: fast loops
        out = flat[i]                     # (1 - w) v_i + w v_{i+1}, as the call computes it
        out *= 1 - w
        hi = flat[i + 1]
        hi *= w
        out += hi
        return out.reshape((times.size,) + vals.shape[1:])


def sample_varying(varying, times, noise: bool = True) -> dict:
    """``Stage.varying`` at every time of `times`, each field stacked on a first axis: its
    ``many(times)`` where it has one (vectorised), else one call per time. `noise` False:
    without G and H (not sampled where the data offer ``many_noise_free``)."""
    many = getattr(varying, "many", None)
    if not noise and getattr(varying, "many_noise_free", None) is not None:
        return varying.many_noise_free(times)
    if many is not None:
        out = many(times)
    else:
        calls = [varying(t) for t in times]
        out = {k: np.stack([np.asarray(c[k], dtype=float) for c in calls])
               for k in (calls[0] if calls else {}) if calls[0][k] is not None}
    return out if noise else {k: v for k, v in out.items() if k not in ("G", "H")}
