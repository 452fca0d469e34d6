"""Everything a spline table's assembler needs from one design: the spline fit, the per-tick
gains the firmware will compute from it, and the latch maps re-solved for those gains."""
from __future__ import annotations

import numpy as np

from stospline.table.spline.fit import DEFAULT_MAX_SPANS, INITIAL_SPANS, SplineGains, _fit
from stospline.table.format import _to_float32   # flushes round-off zeros, as per-tick tables
from stospline.errors import DesignError
from stospline.table.spline.latch import resolve_latch

__all__ = ["compress", "compress_band"]


def compress(problem, exact, quantized, tolerance: float, *,
             max_spans: int = DEFAULT_MAX_SPANS, initial_spans: int = INITIAL_SPANS,
             resolve: bool = True, varying_maps=None
             ) -> tuple[SplineGains, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Fit, evaluate as the firmware does, re-solve the latch maps, round them to float32 on
    the grid that meets the constraints at the design's start (`spline_latch.round_latch`).

    Parameters
    ----------
    problem : Problem
        The problem the tables were designed for.
    exact : GainTable
        The design's own law, ``table_of(design, quantize=False)``.
    quantized : GainTable
        Its float32 per-tick table (``table_of(design)``): the latch maps kept when
        ``resolve=False`` and everything the spline does not replace.
    tolerance : float
        Relative tolerance of every gain entry (`stospline.table.spline.fit.fit_spline`).
    max_spans, initial_spans : int
        Spans allowed per stage, and of the first fit (`fit_spline`).
    resolve : bool
        Re-solve ``Lambda, lambda0`` for the spline's gains (`spline_latch.resolve_latch`), so
        that the constraints hold in expectation as they do for the per-tick table; False keeps
        the design's, which then miss them by about the tolerance.
    varying_maps : callable, optional
        The per-tick mean maps of time-varying stage data (`spline_latch.resolve_latch`).

    Returns
    -------
    spline : SplineGains
    K, k0, L : ndarray
        float32 per-tick gains, exactly `stospline.table.spline.fit.evaluate` of `spline`.
    Lambda, lambda0 : ndarray
        float32 latch maps, shaped as the table's (the quantized table's when ``resolve=False``).

    Raises
    ------
    SplineBudgetError
        The tolerance cannot be met (`fit_spline`).
    DesignError
        (field ``design.table``) The re-solve is not exact for this table (band or
        state-latching tables): pass ``resolve=False`` to keep the design's latch maps.
    """
    if exact.dims != quantized.dims or not np.array_equal(exact.stage_start,
                                                          quantized.stage_start):
        raise ValueError("the exact and the quantized tables are of different designs")
    spline, K, k0, L = _fit(exact, tolerance, max_spans, initial_spans)
    if not resolve:
        return spline, K, k0, L, quantized.Lambda, quantized.lambda0
    if quantized.band_qp is not None:
        raise DesignError("design.table", "a band table's spline re-solves its band dual: "
                                          "use compress_band")
    Lam, lam0 = resolve_latch(problem, quantized.with_arrays(K=K, k0=k0, L=L), spline,
                              varying_maps, rounded=True)
    return spline, K, k0, L, Lam, lam0


def compress_band(problem, exact, quantized, tolerance: float, *,
                  max_spans: int = DEFAULT_MAX_SPANS, initial_spans: int = INITIAL_SPANS):
    """`compress` for a table that carries a band dual (``quantized.band_qp``): the spline fit
    and its evaluation as `compress`, then the band dual re-solved for those gains
    (`stospline.table.spline.band.resolve_band`), which the firmware's stage-0 latch solves
    for the measured x0, and the stage-0 latch maps of the design x0's active set under it
    (the firmware's fallback), rounded to float32. Returns ``(spline, K, k0, L, Lambda,
    lambda0, band_qp)``. Raises DesignError (``design.table``) as `resolve_band` does, or
    SplineBudgetError as `compress`."""
    from stospline.table.spline.band import resolve_band
    if exact.dims != quantized.dims or not np.array_equal(exact.stage_start,
                                                          quantized.stage_start):
        raise ValueError("the exact and the quantized tables are of different designs")
    if quantized.band_qp is None:
        raise ValueError("compress_band: the table carries no band dual")
    spline, K, k0, L = _fit(exact, tolerance, max_spans, initial_spans)
    band_qp, Lam, lam0 = resolve_band(problem, quantized.with_arrays(K=K, k0=k0, L=L), spline)
    return spline, K, k0, L, _to_float32(Lam), _to_float32(lam0), band_qp
