"""Sampled time-varying problem data: values at times, interpolated linearly or held."""
from __future__ import annotations

from dataclasses import dataclass

from typing import Any

import numpy as np

from stospline.errors import ProblemError
from stospline.problem.fields import check_keys, join, vector

__all__ = ["Series", "sample_varying", "series_or"]


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


def series_or(value: Any, path: str, parse, *args, hint=None):
    """A constant parsed by `parse`, or ``{t = [...], values = [...], interpolation = ...}``
    (a `Series` of samples each parsed by `parse`); `hint` as `fields.check_keys`'s."""
    if not isinstance(value, dict):
        return parse(value, path, *args)
    check_keys(value, path, {"t", "values", "interpolation"}, {"t", "values"}, hint=hint)
    t = vector(value["t"], join(path, "t"), None)
    if np.any(np.diff(t) <= 0):
        raise ProblemError(join(path, "t"), "sample times must increase strictly")
    vals = value["values"]
    if not isinstance(vals, list) or len(vals) != len(t):
        raise ProblemError(join(path, "values"), f"must be an array of {len(t)} samples, one "
                                                  f"per entry of {join(path, 't')}")
    samples = [parse(v, f"{path}.values[{i}]", *args) for i, v in enumerate(vals)]
    for i, sample in enumerate(samples[1:], start=1):
        if np.shape(sample) != np.shape(samples[0]):
            raise ProblemError(f"{path}.values[{i}]", f"has shape {np.shape(sample)} but "
                                                      f"values[0] has {np.shape(samples[0])}: "
                                                      f"every sample must have the same shape")
    parsed = np.array(samples)
    interp = value.get("interpolation", "linear")
    if interp not in ("linear", "zoh"):
        raise ProblemError(join(path, "interpolation"), f"must be \"linear\" or \"zoh\", "
                                                         f"got {interp!r}")
    return Series(t, parsed, interp, path)
