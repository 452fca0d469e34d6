"""How far a path leaves a set of time-boxed regions: a check of a design's expected path
against regions that may be wider than the ``[[regions]]`` bands it was designed with (the
walls of a corridor, say, where the bands keep a margin to them)."""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

_T_TOL = 1e-9    # a tick time within this of an interval end belongs to the interval


def distance_outside(t: np.ndarray, y: np.ndarray,
                     regions: Sequence[tuple[float, float, Sequence[float], Sequence[float]]]
                     ) -> np.ndarray:
    """Distance of each point ``y[i]`` at time ``t[i]`` outside the regions that hold at that time.

    Parameters
    ----------
    t : (T,) array
        Times.
    y : (T, q) array
        The path's outputs at those times.
    regions : sequence of ``(t_start, t_end, lower, upper)``
        ``lower <= y <= upper`` (q values each, ``-inf``/``inf`` for no bound) on the closed
        interval ``[t_start, t_end]``.

    Returns
    -------
    (T,) array
        0 inside; else the largest bound violation, for the most lenient region that holds at
        that time (where intervals meet, the point may be in either). Infinity where no region
        holds.
    """
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    out = np.full(t.shape, np.inf)
    for a, b, lower, upper in regions:
        inside_t = (t >= a - _T_TOL) & (t <= b + _T_TOL)
        excess = np.maximum(np.max(np.asarray(lower, dtype=float) - y, axis=1),
                            np.max(y - np.asarray(upper, dtype=float), axis=1))
        out = np.where(inside_t, np.minimum(out, np.maximum(excess, 0.0)), out)
    return out
