"""What a table with runtime parameters guarantees over its whole box, not only at the nominal.

The table at ``theta`` (`stospline.table.parametric.ParametricTable.at`) keeps the nominal's
feedback and shifts its feed-forward affinely. Run on the problem at ``theta`` (targets,
constraint values, drift and start set to it), its exact moments are, with ``d = theta -
theta_nom``,

* the mean ``E x_j = m_j + S_j d``: affine (the closed loop is linear in its sources);
* the covariance ``Cov x_j = P_j + sum_i d_i G_ij + d' H_j d``: quadratic, not constant. The
  noise is multiplicative (``G(x)``, ``G(u)``), so the second moment is driven by the mean
  and the mean moves with ``theta``.

`box_moments` identifies both exactly from ``1 + 2P + P(P-1)/2`` oracle passes (the
nominal, ``s_i e_i`` and ``s_i e_i / 2`` per parameter, ``s_i e_i + s_j e_j`` per pair, ``s_i``
the longer side of the range from the nominal), as `stospline.oracle.parametric.cost_quadratic`
does for the cost. Over the box ``lower <= theta <= upper``:

* a row ``c' E x_j`` rises by at most ``sum_i max(c'S_ij (upper_i - nom_i), c'S_ij (lower_i -
  nom_i))`` and falls by the like sum: exact (an affine function's extremes over a box are
  at a vertex, each coordinate chosen on its own). `band_margins` gives every band row's
  worst-case margin over the box (knot ``lower``/``upper`` rows at their tick, ``[[regions]]``
  rows at every tick of their interval), `check_bands` refuses a box that breaks one;
* ``a' Cov x_j a`` is bounded above by its value at the nominal plus the largest of its
  linear term over the box plus ``sum_ik |a'H_ik a| r_i r_k`` (``r_i`` the longer side):
  an interval bound, exact when the quadratic term is zero. With the smallest margin, it
  bounds every Cantelli tail over the box (`stospline.oracle.exit_bound.exit_bounds_over_box`).

The moments are those of the table in double precision; the float32 table the firmware
stores differs from them by its rounding (`stospline.table.parametric_spec`'s concern, not
this module's).
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from stospline.errors import DesignError
from stospline.oracle.evaluate import evaluate_table
from stospline.problem.parameters import problem_at

__all__ = ["BoxMoments", "RowMargin", "box_moments", "quadratic_fit", "band_margins",
           "check_bands", "check_swing", "vertices", "sides", "mean_paths", "family",
           "box_state_range", "TOLERANCE"]

# A row holds over the box when its worst-case margin is above -TOLERANCE times max(1, |its
# bounds|): the designs meet their rows to ~1e-13 of that scale (as refine.every_tick).
TOLERANCE = 1e-9


def sides(parameters) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(nominal, up, down)``: each range's extent above and below its nominal (>= 0)."""
    nom = np.array([p.nominal for p in parameters])
    up = np.array([p.upper for p in parameters]) - nom
    down = nom - np.array([p.lower for p in parameters])
    return nom, up, down


def vertices(parameters) -> np.ndarray:
    """The ``2^P`` corners of the box, (2^P, P)."""
    return np.array(list(itertools.product(*[(p.lower, p.upper) for p in parameters])),
                    dtype=float)


def family(parameters, *, most: int = 64, seed: int = 20261128) -> tuple[np.ndarray, str]:
    """``(thetas, what)``: the box's ``2^P`` vertices when there are at most `most` of them,
    else `most` draws uniform in the box (seeded); `what` says which, in words."""
    if 2 ** len(parameters) <= most:
        return vertices(parameters), f"its {2 ** len(parameters)} vertices"
    lo = np.array([p.lower for p in parameters])
    hi = np.array([p.upper for p in parameters])
    return (np.random.default_rng(seed).uniform(lo, hi, size=(most, lo.size)),
            f"{most} draws uniform in it (seed {seed})")


def mean_paths(problem, table, thetas) -> np.ndarray:
    """The exact mean state at every tick (t0 included) of the parametric `table`
    (`ParametricTable`, double precision) on the problem at each of `thetas`: (len(thetas),
    T+1, n). The mean is affine in the parameters (module docstring), so it is fixed by the
    oracle at the nominal and at one end of each range: ``P + 1`` passes."""
    nom, up, down = sides(table.parameters)
    step = np.where(up >= down, up, -down)

    def mean(theta):
        return evaluate_table(problem_at(problem, theta), table.at(theta), path=True).path_mean

    m0 = mean(nom)
    S = np.stack([(mean(nom + np.eye(nom.size)[i] * step[i]) - m0) / step[i]
                  for i in range(nom.size)], axis=-1)
    d = np.atleast_2d(np.asarray(thetas, float)) - nom
    return m0[None] + np.einsum("tnp,kp->ktn", S, d)


def box_state_range(box: BoxMoments, sigmas: float = 6.0) -> np.ndarray:
    """Per state, ``max_t |E x_j| + sigmas sd x_j`` over every tick and every parameter vector
    in the box (n,): the largest mean magnitude over the box (exact, affine) plus `sigmas`
    times the root of `BoxMoments.variance_bound`. The fixed-point state range of a table
    with parameters (`stospline.table.qparams`), as `stospline.table.qformat.state_range` is
    for one parameter vector."""
    _, up, down = sides(box.parameters)
    n = box.mean.shape[1]
    reach = np.maximum(box.S * up, -box.S * down).sum(axis=2)
    reach_low = np.maximum(-box.S * up, box.S * down).sum(axis=2)
    peak = np.maximum(np.abs(box.mean + reach), np.abs(box.mean - reach_low))
    sd = np.sqrt(np.maximum(box.variance_bound(np.eye(n)), 0.0))
    return (peak + sigmas * sd).max(axis=0)


def quadratic_fit(f, parameters):
    """``(f0, g, H)`` with ``f(nom + d) = f0 + 2 g.d + d'H d`` for a function `f` of ``d``
    that is a quadratic in it (array-valued: ``g`` and ``H`` carry the parameter axes last),
    from ``1 + 2P + P(P-1)/2`` values of `f` inside the box."""
    nom, up, down = sides(parameters)
    P = nom.size
    step = np.where(up >= down, up, -down)
    f0 = np.asarray(f(np.zeros(P)), dtype=float)
    g = np.zeros(f0.shape + (P,))
    H = np.zeros(f0.shape + (P, P))
    plus = []
    for i in range(P):
        e = np.eye(P)[i] * step[i]
        full, half = np.asarray(f(e), float), np.asarray(f(e / 2), float)
        plus.append(full)
        H[..., i, i] = 2 * (full - 2 * half + f0) / step[i] ** 2
        g[..., i] = (full - f0 - H[..., i, i] * step[i] ** 2) / (2 * step[i])
    for i in range(P):
        for j in range(i + 1, P):
            d = np.zeros(P); d[i], d[j] = step[i], step[j]
            H[..., i, j] = H[..., j, i] = ((np.asarray(f(d), float) - plus[i] - plus[j] + f0)
                                           / (2 * step[i] * step[j]))
    return f0, g, H


@dataclass(frozen=True)
class BoxMoments:
    """The exact state moments at every tick (``T + 1`` states, t0 included) as functions of
    the parameters (module docstring): ``mean + S d`` and ``cov + sum_i d_i G[..., i] + d'H
    d``."""
    parameters: tuple
    mean: np.ndarray       # (T+1, n)
    S: np.ndarray          # (T+1, n, P)
    cov: np.ndarray        # (T+1, n, n)
    G: np.ndarray          # (T+1, n, n, P)
    H: np.ndarray          # (T+1, n, n, P, P)

    def at(self, theta) -> tuple[np.ndarray, np.ndarray]:
        """``(mean, cov)`` at parameters `theta`, from the fitted forms."""
        nom, _, _ = sides(self.parameters)
        d = np.asarray(theta, float) - nom
        return (self.mean + self.S @ d,
                self.cov + self.G @ d + np.einsum("tijpq,p,q->tij", self.H, d, d))

    def shift(self, c: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """For rows `c` (r, n): ``(rise, fall, top, bottom)``, each (T+1, r) but the last two
        (T+1, r, P): the largest rise and fall of ``c' E x_j`` over the box (>= 0) and each
        parameter's share of them."""
        _, up, down = sides(self.parameters)
        s = np.einsum("rn,tnp->trp", np.atleast_2d(c), self.S)
        top = np.maximum(s * up, -s * down)
        bottom = np.maximum(-s * up, s * down)
        return top.sum(axis=2), bottom.sum(axis=2), top, bottom

    def variance_bound(self, a: np.ndarray) -> np.ndarray:
        """For rows `a` (r, n): an upper bound on ``a' Cov x_j a`` over the box, (T+1, r)."""
        _, up, down = sides(self.parameters)
        a = np.atleast_2d(a)
        v0 = np.einsum("rn,tnm,rm->tr", a, self.cov, a)
        lin = np.einsum("rn,tnmp,rm->trp", a, self.G, a)
        quad = np.abs(np.einsum("rn,tnmpq,rm->trpq", a, self.H, a))
        reach = np.maximum(up, down)
        return (v0 + np.maximum(lin * up, -lin * down).sum(axis=2)
                + np.einsum("trpq,p,q->tr", quad, reach, reach))


def box_moments(problem, table) -> BoxMoments:
    """The `BoxMoments` of the parametric `table` (`ParametricTable`, double precision) on
    `problem`, from the oracle at ``1 + 2P + P(P-1)/2`` points of the box."""
    nom = table.nominal
    n = problem.n

    def moments(d):
        theta = nom + d
        m = evaluate_table(problem_at(problem, theta), table.at(theta), path=True,
                           output=np.eye(n))
        return np.concatenate([m.path_mean, m.path_y_cov.reshape(len(m.path_mean), -1)],
                              axis=1)

    f0, g, H = quadratic_fit(moments, table.parameters)
    T1, P = f0.shape[0], len(nom)
    cov = f0[:, n:].reshape(T1, n, n)
    return BoxMoments(tuple(table.parameters), f0[:, :n], 2 * g[:, :n],
                      0.5 * (cov + np.swapaxes(cov, 1, 2)),
                      2 * g[:, n:].reshape(T1, n, n, P), H[:, n:].reshape(T1, n, n, P, P))


@dataclass(frozen=True)
class RowMargin:
    """One band row's margins: `field` names it (``regions[r]`` or ``knots[k].constraint``),
    `row` its row; ``nominal`` the smallest margin of its expected output to its band at the
    nominal over its ticks, ``worst`` the smallest over the box, at time `t` on side `side`
    ("upper" or "lower"), where parameter `parameter` moves it most (by `moved`)."""
    field: str
    row: int
    nominal: float
    worst: float
    t: float
    side: str
    parameter: str
    moved: float
    scale: float

    @property
    def holds(self) -> bool:
        return self.worst >= -TOLERANCE * self.scale

    def as_dict(self) -> dict:
        return {"field": self.field, "row": self.row, "nominal_margin": self.nominal,
                "worst_margin": self.worst, "t": self.t, "side": self.side,
                "parameter": self.parameter, "moved": self.moved, "holds": self.holds}


def _band_rows(problem):
    """``(field, row, c, lower, upper, ticks)`` of every band row (equality rows skipped)."""
    t0, hz = problem.t0, problem.tick_hz
    for k, kn in enumerate(problem.knots):
        if kn.constraint is None or not kn.constraint.is_band:
            continue
        lo, hi = kn.constraint.bounds
        j = np.array([int(round((kn.t - t0) * hz))])
        for i, c in enumerate(kn.constraint.C):
            if lo[i] != hi[i]:
                yield f"knots[{k}].constraint", i, c, float(lo[i]), float(hi[i]), j
    for reg in problem.tick_regions:
        for i, c in enumerate(reg.C):
            yield (f"regions[{reg.index}]", i, c, float(reg.lower[i]), float(reg.upper[i]),
                   reg.ticks(t0, hz))


def band_margins(problem, box: BoxMoments, extra=None) -> list[RowMargin]:
    """Every band row's `RowMargin` over the box (module docstring), in the file's order.
    `extra`, optional: ``extra(c) -> (T+1, r)``, a further shift of rows `c` (r, n) either way
    at every tick (a fixed-point table's error bound propagated to the mean,
    `stospline.oracle.fixed_point_margin.MeanErrorBound.rows`), taken off both margins."""
    names = [p.name for p in box.parameters]
    out = []
    for field, i, c, lo, hi, ticks in _band_rows(problem):
        y = box.mean[ticks] @ c
        rise, fall, top, bottom = box.shift(c[None, :])
        rise, fall, top, bottom = rise[ticks, 0], fall[ticks, 0], top[ticks, 0], bottom[ticks, 0]
        if extra is not None:
            e = extra(c[None, :])[ticks, 0]
            rise, fall = rise + e, fall + e
        upper, lower = hi - (y + rise), (y - fall) - lo
        nominal = float(np.minimum(hi - y, y - lo).min())
        scale = max(1.0, abs(lo) if np.isfinite(lo) else 0.0, abs(hi) if np.isfinite(hi) else 0.0)
        # The worst tick: the first within TOLERANCE of the least margin. An active band ties
        # at several ticks (drone_gates: 3.52 s and 3.54 s, both -1.9e-14), which round-off
        # alone would order, and the summary names the tick and the parameter.
        margin = np.minimum(upper, lower)
        j = int(np.flatnonzero(margin <= margin.min() + TOLERANCE * scale)[0])
        side = "upper" if upper[j] <= lower[j] else "lower"
        share = top[j] if side == "upper" else bottom[j]
        p = int(np.argmax(share))
        out.append(RowMargin(field, i, nominal, float(min(upper[j], lower[j])),
                             problem.t0 + int(ticks[j]) / problem.tick_hz, side, names[p],
                             float(share[p]), scale))
    return out


def check_bands(margins: list[RowMargin]) -> None:
    """DesignError naming the first row that the box breaks and the parameter that moves it
    most."""
    for r in margins:
        if not r.holds:
            raise DesignError(r.field, f"row {r.row} leaves its band by {-r.worst:.3g} at t = "
                                       f"{r.t:g} ({r.side} bound) for parameters in the box: "
                                       f"{r.parameter} moves it most ({r.moved:.3g}; nominal "
                                       f"margin {r.nominal:.3g}); narrow its range or widen "
                                       f"the band")


def check_swing(problem, box: BoxMoments) -> None:
    """DesignError naming the first band row that the parameters move, at some tick, over
    more than its band's width (rise plus fall over the box): no nominal keeps it inside for
    every parameter vector of the box."""
    names = [p.name for p in box.parameters]
    for field, i, c, lo, hi, ticks in _band_rows(problem):
        rise, fall, top, bottom = box.shift(c[None, :])
        swing = rise[ticks, 0] + fall[ticks, 0]
        over = swing - (hi - lo)
        j = int(np.argmax(over))
        if over[j] > TOLERANCE * max(1.0, abs(lo), abs(hi)):
            share = top[ticks[j], 0] + bottom[ticks[j], 0]
            p = int(np.argmax(share))
            raise DesignError(field, f"row {i} cannot stay in its band for every parameter in "
                                     f"the box: at t = {problem.t0 + ticks[j] / problem.tick_hz:g}"
                                     f" the parameters move its expected value over "
                                     f"{swing[j]:.3g}, more than the band's width {hi - lo:.3g};"
                                     f" {names[p]} moves it most ({share[p]:.3g}); narrow the "
                                     f"ranges or widen the band")
