"""A design's gains as numpy arrays on a time axis (`Designed.gains`).

At tick ``j`` (time ``t[j] = t0 + j / tick_hz``) the controller applies, and holds for one
tick, ``u = -K[j] x - k0[j] - L[j] v``; at the first tick of stage ``s``
(``stage_start[s]``) it first latches ``v = Lambda[s] x + lambda0[s]`` from the measured x
(a band table re-solves its band dual there instead: see docs/guide/firmware.md).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from stospline.table.format import table_of

__all__ = ["Gains", "gains_of"]


class Gains(NamedTuple):
    """Per-tick gains (float64 arrays; ``n_latch`` = the latched multiplier width, padded with zeros).

    t : (n_ticks,)            time of each tick, ``t0 + j / tick_hz``
    K : (n_ticks, m, n)       feedback
    k0 : (n_ticks, m)         feed-forward
    L : (n_ticks, m, n_latch)       gain of the latched multipliers v
    Lambda : (n_stages, n_latch, n) latch map ``v = Lambda[s] x + lambda0[s]``
    lambda0 : (n_stages, n_latch)
    stage_start : (n_stages + 1,) first tick of each stage, then n_ticks
    """
    t: np.ndarray
    K: np.ndarray
    k0: np.ndarray
    L: np.ndarray
    Lambda: np.ndarray
    lambda0: np.ndarray
    stage_start: np.ndarray


def gains_of(designed, *, quantized: bool = True) -> Gains:
    """The gains of a `stospline.pipeline.Designed`: the float32 values the firmware's table
    holds (``quantized=True``, the default), or the design's double-precision values."""
    table = designed.table if quantized else table_of(designed.design, quantize=False)
    t = table.t0 + np.arange(table.n_ticks) / table.tick_hz
    arrays = [np.array(a, dtype=np.float64) for a in
              (table.K, table.k0, table.L, table.Lambda, table.lambda0)]
    return Gains(t, *arrays, np.array(table.stage_start, dtype=np.int64))
