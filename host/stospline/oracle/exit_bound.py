"""Upper bounds on the probability that a path leaves a corridor, from exact moments.

For the output ``y = C x(t_j)`` with the oracle's exact mean ``mu_j`` and covariance ``S_j``
at tick j, wall ``a' y <= b`` has margin ``d = b - a' mu_j`` and spread ``s^2 = a' S_j a``, and

* Cantelli (one-sided Chebyshev; valid for any distribution with these two moments):
  ``P(a' y > b) <= s^2 / (s^2 + d^2)`` when ``d > 0``, else 1;
* Gaussian: ``P(a' y > b) = Phi(-d / s)``, exact *if* y were Gaussian. It is an assumption:
  noise proportional to the state (or input) makes x(t) a mixture, not Gaussian, with heavier
  tails than the normal of the same variance, so this is an estimate, not a guarantee.

A point outside the union of the polygons is outside each of them, so per tick
``P(exit) <= min_k P(y outside P_k) <= min_k min(1, sum_{rows of P_k} P(a' y > b))`` (a union
bound over rows); over the ticks of ``[a, b]``, ``P(exit at some tick) <= min(1, sum_j ...)``
(a union bound over time, loose when the tick events are strongly correlated, which at a
fine tick rate they are). Both tails are reported; only the Cantelli sum is a certificate.

With runtime parameters, `exit_bounds_over_box` bounds the same sums for every parameter
vector of the box at once (the smallest margin and the largest spread over the box per tick
and wall).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stospline.problem.corridors import Corridor, corridor_ticks

__all__ = ["ExitBound", "wall_tails", "exit_bounds", "exit_bounds_over_box", "corridor_outputs"]


def wall_tails(a: np.ndarray, b: np.ndarray, mean: np.ndarray, cov: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """``(cantelli, gaussian)`` bounds on ``P(a_i' y > b_i)`` per tick and wall, shapes (ticks,
    walls), for y of `mean` (ticks, p) and `cov` (ticks, p, p); a: (walls, p), b: (walls,).

    A variance that rounding made slightly negative counts as 0; with no spread the event is
    certain (``d < 0``) or impossible (``d >= 0``: the wall is ``a' y <= b``, so a point on it
    is inside)."""
    return _tails(b[None, :] - mean @ a.T, np.einsum("wp,tpq,wq->tw", a, cov, a))


def _tails(d: np.ndarray, var: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`wall_tails` from the margins `d` and variances `var` (ticks, walls)."""
    from scipy.special import ndtr     # lazy, as the rest of scipy here
    var = np.maximum(var, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        cant = np.where(d > 0, var / (var + d * d), 1.0)
        gauss = np.where(var > 0, ndtr(-d / np.sqrt(var)), (d < 0).astype(float))
    cant = np.where((var == 0) & (d >= 0), 0.0, cant)
    return cant, gauss


@dataclass(frozen=True)
class ExitBound:
    """Bounds on the exit probability of one corridor under one tail (`tail`).

    ``per_tick`` (ticks,) bounds ``P(y(t_j) outside)`` at each tick ``ticks[0] ... ticks[-1]``
    (`corridor_ticks`); ``total`` bounds ``P(outside at some tick)`` (their sum, at most 1);
    ``per_wall`` (walls,) is each wall's share of the sum (its terms at the ticks where its
    polygon gave the minimum)."""
    tail: str
    ticks: tuple[int, int]
    per_tick: np.ndarray
    per_wall: np.ndarray

    @property
    def total(self) -> float:
        return float(min(1.0, self.per_tick.sum()))

    @property
    def worst_tick(self) -> float:
        return float(self.per_tick.max()) if self.per_tick.size else 0.0

    def by_bins(self, edges: np.ndarray) -> np.ndarray:
        """The bound summed over tick bins ``[edges[i], edges[i+1])`` (tick indices), each at
        most 1."""
        j = np.arange(self.ticks[0], self.ticks[1] + 1)
        out = np.array([self.per_tick[(j >= lo) & (j < hi)].sum()
                        for lo, hi in zip(edges[:-1], edges[1:])])
        return np.minimum(out, 1.0)


def _bound(corridor: Corridor, tails: np.ndarray, tail: str, ticks) -> ExitBound:
    starts = corridor.row_start
    per_poly = np.stack([np.minimum(1.0, tails[:, starts[k]:starts[k + 1]].sum(axis=1))
                         for k in range(len(corridor.polygons))], axis=1)   # ticks x polygons
    best = np.argmin(per_poly, axis=1)
    per_tick = per_poly[np.arange(len(best)), best]
    per_wall = np.zeros(len(corridor.b))
    for k in range(len(corridor.polygons)):
        rows = best == k
        # The polygon's terms where it is the minimum, scaled so they add up to the capped
        # per-tick value.
        part = tails[rows, starts[k]:starts[k + 1]]
        total = part.sum(axis=1, keepdims=True)
        with np.errstate(invalid="ignore", divide="ignore"):
            share = np.where(total > 0, part / total, 0.0) * per_tick[rows, None]
        per_wall[starts[k]:starts[k + 1]] += share.sum(axis=0)
    return ExitBound(tail, ticks, per_tick, per_wall)


def exit_bounds(corridor: Corridor, y_mean: np.ndarray, y_cov: np.ndarray, t0: float,
                tick_hz: int) -> dict[str, ExitBound]:
    """``{"cantelli": ..., "gaussian": ...}`` for `corridor`, from the exact moments of its
    outputs at every tick of the plan, ``y_mean`` (ticks + 1, p) and ``y_cov`` (ticks + 1,
    p, p) (`corridor_outputs`)."""
    lo, hi = corridor_ticks(corridor, t0, tick_hz)
    mean, cov = y_mean[lo:hi + 1], y_cov[lo:hi + 1]
    cant, gauss = wall_tails(corridor.A, corridor.b, mean, cov)
    return {"cantelli": _bound(corridor, cant, "cantelli", (lo, hi)),
            "gaussian": _bound(corridor, gauss, "gaussian", (lo, hi))}


def exit_bounds_over_box(corridor: Corridor, box, t0: float,
                         tick_hz: int, extra=None) -> dict[str, ExitBound]:
    """`exit_bounds` that hold for every parameter vector in the box of a table with runtime
    parameters, from its moments over the box `box` (`stospline.oracle.over_box.BoxMoments`).

    Per tick and wall, the Cantelli tail ``s^2 / (s^2 + d^2)`` rises with the spread and falls
    with the margin, so it is bounded over the box by its value at the smallest margin (the
    nominal's less the wall's largest mean shift over the box: exact, the mean is affine in
    the parameters) and the largest spread (an interval bound on the quadratic covariance,
    `BoxMoments.variance_bound`); the union bounds over rows and ticks then follow as for one
    parameter vector. The Gaussian tail is likewise evaluated there (an estimate, as ever).

    `extra`, optional: ``extra(walls) -> (T+1, r)``, a further shift of each wall's mean
    (a fixed-point table's error bound propagated to the mean,
    `stospline.oracle.fixed_point_margin.MeanErrorBound.rows`), taken off the margin; the
    spread stays the box's."""
    lo, hi = corridor_ticks(corridor, t0, tick_hz)
    walls = corridor.A @ corridor.C                               # walls in the state
    rise = box.shift(walls)[0][lo:hi + 1]
    if extra is not None:
        rise = rise + extra(walls)[lo:hi + 1]
    d = corridor.b[None, :] - box.mean[lo:hi + 1] @ walls.T - rise
    cant, gauss = _tails(d, box.variance_bound(walls)[lo:hi + 1])
    return {"cantelli": _bound(corridor, cant, "cantelli", (lo, hi)),
            "gaussian": _bound(corridor, gauss, "gaussian", (lo, hi))}


def corridor_outputs(problem, table, **oracle_options) -> "_Outputs":
    """``(y_mean, y_cov)`` of each corridor's outputs at every tick, from one exact oracle
    pass (`oracle.evaluate_table`), as a sequence indexed by corridor.

    The pass records the corridors' rows stacked when they are no more than the states;
    otherwise it records the state's moments and each corridor's are projected when asked
    for: the stacked covariance grows with the square of all the corridors' rows (300
    corridors of 2 rows over 6 000 ticks: 17 GB), the state's does not."""
    from stospline.oracle.evaluate import evaluate_table
    if not problem.corridors:
        return _Outputs([], None, None)
    C = np.vstack([c.C for c in problem.corridors])
    stacked = C.shape[0] <= problem.n
    mom = evaluate_table(problem, table, path=False,
                         output=C if stacked else np.eye(problem.n), **oracle_options)
    return _Outputs([c.C for c in problem.corridors], mom.path_y_mean, mom.path_y_cov,
                    stacked)


class _Outputs:
    """Per corridor ``(y_mean, y_cov)``: slices of the stacked outputs' moments, or the
    projection of the state's (`corridor_outputs`), made when indexed."""

    def __init__(self, Cs: list, mean, cov, stacked: bool = True):
        self._Cs, self._mean, self._cov, self._stacked = Cs, mean, cov, stacked
        self._start = np.concatenate([[0], np.cumsum([C.shape[0] for C in Cs])]).astype(int)

    def __len__(self) -> int:
        return len(self._Cs)

    def __getitem__(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        if not -len(self) <= i < len(self):
            raise IndexError(i)
        i %= len(self)
        if self._stacked:
            s = slice(self._start[i], self._start[i + 1])
            return self._mean[:, s], self._cov[:, s, s]
        C = self._Cs[i]
        yc = C @ self._cov @ C.T
        return self._mean @ C.T, 0.5 * (yc + np.swapaxes(yc, 1, 2))

    def __iter__(self):
        return (self[i] for i in range(len(self)))
