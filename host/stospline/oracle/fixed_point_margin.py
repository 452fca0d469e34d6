"""How far a bounded command error can move the expected state: the fixed-point error bound of
a Q15/Q31 table propagated through the closed loop, as a margin on mean constraints.

The device's command at tick ``t`` is the double law's plus an error ``e_t`` with ``|e_t| <=
b_t`` (input by input; `stospline.table.qparams.command_error_bound`: every stored entry's
rounding, the parameter deviation's, the state's rounding to its Q format and the command's
own). The expected state obeys the linear recursion of the plant's mean (zero-order hold,
``x+ = Ad x + Bd u + fd``; the noise has zero mean whatever multiplies it), so the deviation
of the mean is linear in the mean errors,

    E x_j - E x_j(double) = sum_{t<j} R_jt E e_t,

``R_jt`` the closed loop's response at tick ``j`` to a unit command at tick ``t``: the feedback
``-K x`` and the latched ``-L v``, ``v = Lambda x`` at each stage start that latches (the
latch offsets ``lambda0`` are constants and cancel). Hence for a row ``c``,

    |c' (E x_j - E x_j(double))| <= sum_{t<j} |c' R_jt| b_t,

the worst case over every error sequence within the bound (each ``e_t`` may take either sign).
This is a bound on the mean only: the rounding is a function of the state, so it also moves
the spread, which this module does not bound.
"""
from __future__ import annotations

import numpy as np
from scipy.linalg import expm

__all__ = ["MeanErrorBound", "mean_error_bound", "fixed_point_certificate"]


class MeanErrorBound:
    """`mean_error_bound`: ``rows(c)`` is the bound (T+1, r) on ``|c' dE x_j|`` for rows
    `c` (r, n), tick by tick (tick 0, the start, is 0)."""

    def __init__(self, steps, latch, K, L, bound):
        self._steps = steps          # per tick (Ad, Bd)
        self._latch = latch          # per tick: Lambda (n_latch, n) with dead rows zero, or None
        self._K, self._L = K, L
        self._b = np.asarray(bound, float)

    def rows(self, c) -> np.ndarray:
        c = np.atleast_2d(np.asarray(c, float))
        b = self._b.reshape(-1)
        out = np.zeros((len(self._steps) + 1, c.shape[0]))
        for j, Rx in self._responses(len(self._steps)):
            out[j + 1] = np.abs(c @ Rx) @ b[:Rx.shape[1]]
        return out

    def attaining(self, c, j: int) -> np.ndarray:
        """The errors (ticks, m) within the bound that move ``c' E x_j`` (`c` one row) by the
        whole bound ``rows(c)[j]``: ``b_t`` times the sign of its response, zero from tick
        `j` on."""
        e = np.zeros(self._b.size)
        for _, Rx in self._responses(j):
            pass
        if j > 0:
            w = Rx.shape[1]
            e[:w] = np.sign(np.asarray(c, float) @ Rx) * self._b.reshape(-1)[:w]
        return e.reshape(self._b.shape)

    def _responses(self, ticks: int):
        """``(j, R)`` for j < `ticks`: R (n, (j+1) m) the response of the mean after tick j to
        the errors of ticks 0 .. j."""
        T, m = self._b.shape
        n = self._steps[0][0].shape[0] if self._steps else 0
        n_latch = self._L.shape[2]
        Rx = np.zeros((n, T * m))       # d E x / d e, all ticks' errors at once
        Rv = np.zeros((n_latch, T * m))
        for j in range(ticks):
            w = (j + 1) * m                           # only errors before tick j + 1 matter
            if self._latch[j] is not None:
                Rv[:, :w] = self._latch[j] @ Rx[:, :w]
            Ru = -self._K[j] @ Rx[:, :w] - self._L[j] @ Rv[:, :w]
            Ru[:, j * m:w] += np.eye(m)
            Ad, Bd = self._steps[j]
            Rx[:, :w] = Ad @ Rx[:, :w] + Bd @ Ru
            yield j, Rx[:, :w]


def mean_error_bound(problem, table, bound) -> MeanErrorBound:
    """The bound (module docstring) for the law of `table` (a `GainTable`, its gains; the
    feed-forward does not enter) on `problem`'s plant (constant stage data) with command
    errors within `bound` ((n_ticks, m), real units). ValueError for time-varying plant
    data."""
    n, m, n_latch = table.dims
    if n != problem.n or len(problem.stages) != table.n_stages:
        raise ValueError("mean_error_bound: the table's states or stages are not the "
                         "problem's (a delayed table is not covered)")
    h = 1.0 / table.tick_hz
    start = np.asarray(table.stage_start, int)
    steps, latch = [], []
    for k, stage in enumerate(problem.stages):
        if stage.varying is not None:
            raise ValueError("mean_error_bound: time-varying plant data are not covered")
        big = np.zeros((n + m, n + m))
        big[:n, :n], big[:n, n:] = stage.A, stage.B
        E = expm(big * h)
        lam = None
        if k == 0 or table.stage_n_latch[k] > 0:
            lam = np.array(table.Lambda[k], float)
            lam[int(table.stage_n_latch[k]):] = 0.0
        for j in range(start[k], start[k + 1]):
            steps.append((E[:n, :n], E[:n, n:]))
            latch.append(lam if j == start[k] else None)
    return MeanErrorBound(steps, latch, np.asarray(table.K, float), np.asarray(table.L, float),
                          bound)


def fixed_point_certificate(problem, ptable, pf, box=None) -> dict:
    """What holds over the box for the Q15/Q31 parametric table `pf` as flashed
    (`stospline.table.qparams.ParametricFixedPoint` of `ptable`), from the double table's
    moments over the box `box` (default `box_moments` of `ptable`) and the fixed-point error
    bound propagated to the mean (`mean_error_bound` of `pf.command_error_bound`):
    ``{"bound": MeanErrorBound, "margins": [RowMargin] (every band row, both margins less
    the bound), "corridors": [exit bounds per corridor (each wall's margin less the
    bound; the spread the double table's)]}``."""
    from stospline.oracle.exit_bound import exit_bounds_over_box
    from stospline.oracle.over_box import band_margins, box_moments
    box = box if box is not None else box_moments(problem, ptable)
    meb = mean_error_bound(problem, ptable.table, pf.command_error_bound(ptable))
    return {"bound": meb, "margins": band_margins(problem, box, extra=meb.rows),
            "corridors": [exit_bounds_over_box(c, box, problem.t0, problem.tick_hz,
                                               extra=meb.rows) for c in problem.corridors]}
