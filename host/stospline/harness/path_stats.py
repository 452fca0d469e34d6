"""Statistics of a Monte Carlo run that stream: each block of paths summarises itself, and the
summaries merge in block order, so a run holds a number of values set by its ticks, states
and corridor walls, not by its paths.

`Moments` are the count, mean, comoment matrix, third and fourth central sums per component
and the extremes of a sample of vectors, merged pairwise (Chan, Golub & LeVeque 1979 for the
comoments; Pébay 2008, "Formulas for robust, one-pass parallel computation of covariances
and arbitrary-order statistical moments", for the third and fourth). Each block's own are
computed in two passes over its (at most `BLOCK_PATHS`) rows. `CorridorExits` counts each
corridor's first exits by state tick and by wall and keeps the first few exiting paths.
`RunStats` is a block's (or a run's) whole summary.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Moments", "CorridorExits", "RunStats", "COST_SAMPLE", "EXIT_EXAMPLES"]

# The costs of the first this many paths are kept for a histogram (80 KB).
COST_SAMPLE = 10_000
# The first this many exiting paths of each corridor are kept as examples.
EXIT_EXAMPLES = 10


@dataclass
class Moments:
    """Count, mean, comoments and per-component third and fourth central sums, low and high
    of a sample of d-vectors."""
    count: int
    mean: np.ndarray          # (d,)
    comoment: np.ndarray      # (d, d): sum of (x - mean)(x - mean)'
    m3: np.ndarray            # (d,): sum of (x_i - mean_i)^3
    m4: np.ndarray            # (d,): sum of (x_i - mean_i)^4
    low: np.ndarray
    high: np.ndarray

    @classmethod
    def of(cls, X: np.ndarray) -> "Moments":
        """The moments of the rows of X (k, d), k >= 1, in two passes."""
        X = np.asarray(X, dtype=float)
        X = X[:, None] if X.ndim == 1 else X
        mean = X.mean(axis=0)
        dev = X - mean
        sq = dev * dev
        return cls(X.shape[0], mean, dev.T @ dev, (sq * dev).sum(axis=0), (sq * sq).sum(axis=0),
                   X.min(axis=0), X.max(axis=0))

    def merge(self, other: "Moments") -> "Moments":
        """The moments of both samples together (`self` first)."""
        na, nb = float(self.count), float(other.count)
        n = na + nb
        delta = other.mean - self.mean
        d2 = delta * delta
        m2a, m2b = np.diag(self.comoment), np.diag(other.comoment)
        m3 = (self.m3 + other.m3 + d2 * delta * na * nb * (na - nb) / n ** 2
              + 3.0 * delta * (na * m2b - nb * m2a) / n)
        m4 = (self.m4 + other.m4 + d2 * d2 * na * nb * (na * na - na * nb + nb * nb) / n ** 3
              + 6.0 * d2 * (na * na * m2b + nb * nb * m2a) / n ** 2
              + 4.0 * delta * (na * other.m3 - nb * self.m3) / n)
        return Moments(self.count + other.count, self.mean + delta * (nb / n),
                       self.comoment + other.comoment + np.outer(delta, delta) * (na * nb / n),
                       m3, m4, np.minimum(self.low, other.low),
                       np.maximum(self.high, other.high))

    def cov(self) -> np.ndarray:
        """Sample covariance (ddof 1; NaN for one sample, as numpy's)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return self.comoment / (self.count - 1)

    def std(self) -> np.ndarray:
        """Sample standard deviation per component (ddof 1)."""
        return np.sqrt(np.maximum(np.diag(self.cov()), 0.0))

    def mean_se(self) -> np.ndarray:
        """Standard error of the mean per component."""
        return self.std() / np.sqrt(self.count)

    def var_se(self) -> np.ndarray:
        """Standard error of the variance per component: that of the mean of the squared
        deviations from the mean (``std((x - mean)^2, ddof=1) / sqrt(count)``)."""
        m2 = np.diag(self.comoment)
        with np.errstate(invalid="ignore", divide="ignore"):
            spread = (self.m4 - m2 * m2 / self.count) / (self.count - 1)
        return np.sqrt(np.maximum(spread, 0.0)) / np.sqrt(self.count)

    def alike(self) -> np.ndarray:
        """Per component: every sample equal (zero spread, exactly)."""
        return self.high == self.low


@dataclass
class CorridorExits:
    """First exits of the paths from each corridor: how many, by state tick and by wall, and
    the first `EXIT_EXAMPLES` exiting paths (path index, state tick, wall)."""
    paths: int
    by_tick: list[np.ndarray]       # per corridor (ticks + 1,) int64
    by_wall: list[np.ndarray]       # per corridor (walls,) int64
    examples: list[list[tuple[int, int, int]]]

    @classmethod
    def of(cls, exit_tick: np.ndarray, exit_wall: np.ndarray, walls: list[int],
           n_ticks: int, first_path: int = 0) -> "CorridorExits":
        """The exits of a block (`exit_tick`, `exit_wall`: corridors x paths, -1: none)
        whose first path is path `first_path` of the run; corridor i has ``walls[i]``."""
        by_tick, by_wall, examples = [], [], []
        for et, ew, nw in zip(exit_tick, exit_wall, walls):
            out = np.flatnonzero(et >= 0)
            by_tick.append(np.bincount(et[out], minlength=n_ticks + 1).astype(np.int64))
            by_wall.append(np.bincount(ew[out], minlength=nw).astype(np.int64))
            examples.append([(first_path + int(p), int(et[p]), int(ew[p]))
                             for p in out[:EXIT_EXAMPLES]])
        return cls(exit_tick.shape[1], by_tick, by_wall, examples)

    def merge(self, other: "CorridorExits") -> "CorridorExits":
        """Both runs' exits (`self`'s paths first)."""
        return CorridorExits(
            self.paths + other.paths,
            [a + b for a, b in zip(self.by_tick, other.by_tick)],
            [a + b for a, b in zip(self.by_wall, other.by_wall)],
            [(a + b)[:EXIT_EXAMPLES] for a, b in zip(self.examples, other.examples)])

    def tick_percentile(self, corridor: int, q: float) -> float:
        """The `q`-th percentile (0..100) of the exit ticks of the paths that left
        `corridor`, as ``numpy.percentile`` of those ticks (linear interpolation); NaN
        without exits."""
        cum = np.cumsum(self.by_tick[corridor])
        if cum[-1] == 0:
            return float("nan")
        pos = q / 100.0 * (cum[-1] - 1)
        lo = int(np.floor(pos))
        at_lo, at_hi = (int(np.searchsorted(cum, k, side="right"))
                        for k in (lo, min(lo + 1, cum[-1] - 1)))
        return at_lo + (pos - lo) * (at_hi - at_lo)

    @property
    def count(self) -> np.ndarray:
        """Paths that left each corridor."""
        return np.array([int(t.sum()) for t in self.by_tick], dtype=np.int64)


@dataclass
class RunStats:
    """What a run reports, for a block of paths or, merged in block order, a whole run."""
    paths: int
    cost: Moments                    # d = 1
    knots: list[Moments]             # the state at each knot
    x_sum: np.ndarray                # (ticks + 1, n): the sum of the states at every tick
    worst: int                       # the worst status the controllers returned
    saturated_ticks: int             # (path, tick) steps with STSP_WARN_SATURATED
    saturated_paths: int             # paths with at least one
    u_low: np.ndarray                # (m,) least and greatest command issued
    u_high: np.ndarray
    cost_sample: np.ndarray          # the costs of the first COST_SAMPLE paths
    exits: CorridorExits | None = None

    def merge(self, other: "RunStats") -> "RunStats":
        """Both (`self`'s paths first); the state sums add in this order, so a run's are
        the same whichever process ran which block."""
        room = max(0, COST_SAMPLE - len(self.cost_sample))
        return RunStats(
            self.paths + other.paths, self.cost.merge(other.cost),
            [a.merge(b) for a, b in zip(self.knots, other.knots)],
            self.x_sum + other.x_sum, min(self.worst, other.worst),
            self.saturated_ticks + other.saturated_ticks,
            self.saturated_paths + other.saturated_paths,
            np.minimum(self.u_low, other.u_low), np.maximum(self.u_high, other.u_high),
            np.concatenate([self.cost_sample, other.cost_sample[:room]]),
            None if self.exits is None else self.exits.merge(other.exits))
