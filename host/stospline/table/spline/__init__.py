"""Spline tables: a design's per-tick gains as cubic B-splines of the tick, which the firmware
evaluates bit for bit as the host does. One entry point, `spline_table`, takes the arithmetic.

- `fit`: the float32 format (`SplineGains`), its evaluation and the fit to a tolerance;
- `fixed_point`: the Q15/Q31 format (integer coefficients, exact integer evaluation);
- `latch`: the latch maps re-solved for the gains as evaluated, then rounded;
- `band`: a band table's dual re-solved for the spline's gains;
- `restore`: the feed-forward of a table that latches the state, restored for the start;
- `compress`: fit + latch (or band) for a float32 table.

Imports no designer: a design's per-tick mean maps of time-varying data come in as
``varying_maps`` (`stospline.design.varying.mean_maps`)."""
from __future__ import annotations

from dataclasses import replace

from stospline.errors import DesignError
from stospline.limits import BANDQP_MAX

__all__ = ["spline_table"]

ARITHMETICS = ("float32", "q15", "q31")


def spline_table(problem, exact, tolerance: float, *, arith: str = "float32", per_tick=None,
                 x_range=None, varying_maps=None):
    """The spline table of a design in arithmetic `arith`.

    Parameters
    ----------
    problem : Problem
    exact : GainTable
        The design's per-tick law in double precision (``table_of(design, quantize=False)``).
    tolerance : float
        The fit's budget: the largest error of a gain entry relative to its stage's peak.
    arith : {"float32", "q15", "q31"}
    per_tick : GainTable
        float32 only: the design's float32 per-tick table (its band dual and latch are
        re-solved for the spline's gains).
    x_range : array_like (n,)
        Q15/Q31 only: the state ranges the scales cover (`stospline.table.qformat`).
    varying_maps : callable, optional
        The per-tick mean maps of time-varying stage data.

    Returns
    -------
    GainTable (float32) or FixedPointTable (Q15/Q31)
        Whose ``spline`` holds the arrays the firmware stores and whose K, k0, L are their
        evaluation at every tick, bit for bit.

    Raises
    ------
    DesignError
        ``design.table`` for what has no spline table, ``design.spline_tolerance`` when the
        budget cannot be met within the firmware's limits.
    ValueError
        Q15/Q31: scales beyond the firmware's exponents (`stospline.table.qformat`).
    """
    if arith == "float32":
        if per_tick is None:
            raise TypeError("a float32 spline table needs the per-tick float32 table")
        return _float32_table(problem, exact, per_tick, tolerance, varying_maps)
    if arith in ("q15", "q31"):
        if x_range is None:
            raise TypeError(f"a {arith} spline table needs the state ranges (x_range)")
        from stospline.table.spline.fixed_point import q_spline_table
        return q_spline_table(problem, exact, arith, x_range, tolerance,
                              varying_maps=varying_maps)
    raise ValueError(f"arith must be one of {', '.join(ARITHMETICS)}, not {arith!r}")


def _float32_table(problem, exact, per_tick, tolerance: float, varying_maps):
    """Fit, then re-solve the latch (or the band dual, or restore the feed-forward of a table
    that latches the state) for the spline's gains as the firmware evaluates them."""
    from stospline.table.spline.compress import compress, compress_band
    from stospline.table.spline.restore import is_state_latching, restore
    band_qp = per_tick.band_qp
    if is_state_latching(per_tick):
        # The state latched at t0 (every-tick regions, bands beyond a band dual, more
        # constraint rows than states): the feed-forward restored for the design's x0.
        spline, K, k0, L, info = restore(problem, exact, per_tick, tolerance,
                                         varying_maps=varying_maps)
        return replace(per_tick, name=f"{per_tick.name}_spline", K=K, k0=k0, L=L,
                       spline=spline, restored=info, spline_tolerance=tolerance)
    if band_qp is None and any(kn.constraint is not None and kn.constraint.is_band
                               for kn in problem.knots):
        raise DesignError("design.table", f"a band design with more than {BANDQP_MAX} "
                                          f"constraint rows carries no band dual (its tables "
                                          f"latch the affine map of one active set): no exact "
                                          f"spline table")
    if band_qp is not None:
        spline, K, k0, L, Lam, lam0, band_qp = compress_band(problem, exact, per_tick, tolerance)
    else:
        spline, K, k0, L, Lam, lam0 = compress(problem, exact, per_tick, tolerance,
                                               varying_maps=varying_maps)
    return replace(per_tick, name=f"{per_tick.name}_spline", K=K, k0=k0, L=L, Lambda=Lam,
                   lambda0=lam0, spline=spline, band_qp=band_qp, spline_tolerance=tolerance)
