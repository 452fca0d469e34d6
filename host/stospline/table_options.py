"""The table kinds a design can be written as, the spline's error budget and the state range
of a fixed-point table: shared by the problem file (``[design] table``, ``spline_tolerance``),
the command line, the pipeline and the oracle."""
from __future__ import annotations

import math

from stospline.errors import ProblemError

__all__ = ["TABLE_KINDS", "DEFAULT_SPLINE_TOLERANCE", "MIN_SPLINE_TOLERANCE",
           "DEFAULT_SIGMAS", "check_spline_tolerance"]

TABLE_KINDS = ("per-tick", "spline")
# Largest relative error of any gain entry of the spline (against the entry's largest
# magnitude over its stage): the examples' costs then move by less than 1e-6 relative
# (docs/evidence/spline-tables.md).
DEFAULT_SPLINE_TOLERANCE = 1e-5
# 2^-21 = 4 float32 roundings (float32's epsilon is 2^-23, relative to the entry's largest):
# the float32 coefficients and the float32 evaluation of the spline cannot promise less,
# whatever the knots (`stospline.table.spline.fit.fit_spline`).
MIN_SPLINE_TOLERANCE = 2.0 ** -21
_TOLERANCE_RANGE = (MIN_SPLINE_TOLERANCE, 0.1)
DEFAULT_SIGMAS = 6.0    # Q15/Q31 state range: mean +- 6 standard deviations over the plan


def check_spline_tolerance(value, field: str) -> float:
    """`value` as a float in [2^-21 (about 4.77e-7), 0.1], else ProblemError naming `field`."""
    lo, hi = _TOLERANCE_RANGE
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(value) or not lo <= value <= hi:
        raise ProblemError(field, f"must be a number in [{lo:.3g}, {hi:g}] (the largest "
                                  f"relative error of a spline gain; below 2^-21 = 4 float32 "
                                  f"roundings the float32 spline cannot promise it), "
                                  f"got {value!r}")
    return float(value)
