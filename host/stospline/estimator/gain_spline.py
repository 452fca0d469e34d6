"""The filter's update gains as cubic B-splines of the sample (`stsp_est_gain_spline_t`,
firmware/include/stospline/stsp_estimator.h): the estimator's counterpart of the controller's
spline tables (`stospline.table.spline.fit`), fitted by the same machinery to the same
relative tolerance, coefficients on the same float32 grid, and evaluated here as the firmware
evaluates them, bit for bit.

Stage s's samples are the sampling ticks of the stage, ``q = q0(s) .. q0(s + 1) - 1`` with
``q0(s) = ceil(stage_start[s] / every)``; the spline's abscissa is ``tau = q - q0(s)``. A stage
with samples has the clamped knot vector ``[0,0,0,0, b_1 .. b_(S-1), T,T,T,T]`` (T its number
of samples) and its stored entries, ``S + 3`` coefficients each: entry ``e = r * ny + i`` is
``F[r][i]``, the entries not stored (zero over the stage, round-off zeros flushed) are exact
zeros; a stage without samples has no knots, entries or coefficients. The arrays::

    knot_start   uint32 (n_stages + 1,)   knot[knot_start[s]:knot_start[s+1]]
    knot         float32
    entry_start  uint32 (n_stages + 1,)   entry[entry_start[s]:...]: increasing, < nx ny
    entry        uint8
    coef_start   uint32 (n_stages + 1,)   coef[coef_start[s]:...]: entries x (S_s + 3)
    coef         float32
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stospline.table.format import positive_zeros
from stospline.table.spline.fit import DEFAULT_MAX_SPANS, INITIAL_SPANS, _basis, _combine, _fit

__all__ = ["EstGainSpline", "fit_gain_spline", "evaluate_gain_spline", "sample_starts",
           "EST_SPLINE_MAGIC"]

EST_SPLINE_MAGIC = 0x47535453     # STSP_EST_SPLINE_MAGIC, "STSG"


def sample_starts(stage_start, every: int) -> np.ndarray:
    """``q0(s)`` for s = 0 .. n_stages: each stage's first sample, then the number of samples."""
    start = np.asarray(stage_start, dtype=np.int64)
    return -(-start // int(every))


@dataclass(frozen=True)
class EstGainSpline:
    """The six arrays of the module docstring, for gains of `nx` x `ny`."""
    knot_start: np.ndarray
    knot: np.ndarray
    entry_start: np.ndarray
    entry: np.ndarray
    coef_start: np.ndarray
    coef: np.ndarray
    nx: int
    ny: int

    DTYPES = {"knot_start": np.uint32, "knot": np.float32, "entry_start": np.uint32,
              "entry": np.uint8, "coef_start": np.uint32, "coef": np.float32}

    def __post_init__(self):
        for name, dtype in self.DTYPES.items():
            object.__setattr__(self, name,
                               positive_zeros(np.ascontiguousarray(getattr(self, name), dtype)))

    @property
    def n_stages(self) -> int:
        return len(self.knot_start) - 1

    @property
    def nbytes(self) -> int:
        """Bytes of the six arrays (what the spline stores in place of the gains)."""
        return sum(getattr(self, name).nbytes for name in self.DTYPES)

    def spans(self) -> list[int]:
        """Spans per stage (0 for a stage without samples)."""
        return [max(int(n) - 7, 0) for n in np.diff(self.knot_start.astype(np.int64))]


def evaluate_gain_spline(spline: EstGainSpline, stage_start, every: int) -> np.ndarray:
    """The gains (samples, nx, ny) float32 the firmware computes from `spline`, bit for bit
    (stsp_estimator.h: The NURBS Book A2.2 in binary32, then ``((N0 c0 + N1 c1) + N2 c2) + N3
    c3``)."""
    q0 = sample_starts(stage_start, every)
    nx, ny = spline.nx, spline.ny
    out = np.zeros((int(q0[-1]), nx * ny), np.float32)
    for s in range(spline.n_stages):
        T = int(q0[s + 1] - q0[s])
        if T == 0:
            continue
        U = spline.knot[spline.knot_start[s]:spline.knot_start[s + 1]]
        entry = spline.entry[spline.entry_start[s]:spline.entry_start[s + 1]]
        if entry.size == 0:
            continue
        C = spline.coef[spline.coef_start[s]:spline.coef_start[s + 1]].reshape(entry.size, -1)
        sigma, N = _basis(U, np.arange(T, dtype=np.float32))
        out[q0[s]:q0[s + 1], entry] = _combine(sigma, N, C)
    return out.reshape(-1, nx, ny)


class _SampleGains:
    """The gains of the samples as the per-tick table `stospline.table.spline.fit._fit`
    compresses: F (samples, nx, ny) as K of a law with ny states and nx inputs, the stages'
    samples as its ticks (the stages with samples only)."""

    def __init__(self, F: np.ndarray, starts: np.ndarray):
        samples, nx, ny = F.shape
        self.K, self.stage_start = F, starts
        self.k0 = np.zeros((samples, nx))
        self.L = np.zeros((samples, nx, 0))
        self.dims = (ny, nx, 0)
        self.n_stages = len(starts) - 1


def fit_gain_spline(gain: np.ndarray, stage_start, every: int, tolerance: float, *,
                    max_spans: int = DEFAULT_MAX_SPANS, initial_spans: int = INITIAL_SPANS
                    ) -> tuple[EstGainSpline, np.ndarray]:
    """Compress the filter's gains per sample to cubic B-splines per stage.

    Parameters
    ----------
    gain : (samples, nx, ny) ndarray
        The gains in double precision, round-off zeros flushed (`estimator.ctable.flushed`),
        so that the entries stored and their coefficients are the same on every machine.
    stage_start : array_like
        The gain table's stage starts (ticks), then its number of ticks.
    every : int
        A sample every `every` ticks from tick 0.
    tolerance : float
        Every entry, as the firmware evaluates it, is within ``tolerance`` times its largest
        magnitude over the stage of `gain` (`stospline.table.spline.fit.fit_spline`).

    Returns
    -------
    spline : EstGainSpline
    values : (samples, nx, ny) float32
        `evaluate_gain_spline` of `spline` (computed by the fit).

    Raises
    ------
    SplineBudgetError
        As `fit_spline`: the tolerance is out of range or a stage needs more than `max_spans`.
    """
    gain = np.asarray(gain, dtype=float)
    samples, nx, ny = gain.shape
    q0 = sample_starts(stage_start, every)
    if int(q0[-1]) != samples:
        raise ValueError(f"{samples} gains for {int(q0[-1])} samples")
    live = np.flatnonzero(np.diff(q0) > 0)          # the stages with samples
    fitted, F, _, _ = _fit(_SampleGains(gain, np.r_[q0[live], q0[-1]]), tolerance,
                           max_spans, initial_spans)
    empty = [np.zeros(0)] * (len(q0) - 1)
    knots, entries, coefs = list(empty), list(empty), list(empty)
    for k, s in enumerate(live):
        inputs, cols = fitted.entries(k)            # row r of F is input r of the fit
        knots[s], entries[s] = fitted.knots(k), inputs * ny + cols
        coefs[s] = fitted.coefficients(k).ravel()
    starts = [np.r_[0, np.cumsum([a.size for a in arrays])] for arrays in (knots, entries, coefs)]
    spline = EstGainSpline(starts[0], np.concatenate(knots), starts[1], np.concatenate(entries),
                           starts[2], np.concatenate(coefs), nx, ny)
    return spline, F
