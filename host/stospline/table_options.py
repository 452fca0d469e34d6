"""The table kinds a design can be written as, and the spline's error budget: shared by the
problem file (``[design] table``, ``spline_tolerance``), the command line and the pipeline."""
from __future__ import annotations

import math

from stospline.errors import ProblemError

__all__ = ["TABLE_KINDS", "DEFAULT_SPLINE_TOLERANCE", "check_spline_tolerance"]

TABLE_KINDS = ("per-tick", "spline")
# Largest relative error of any gain entry of the spline (against the entry's largest
# magnitude over its stage): the examples' costs then move by less than 1e-6 relative
# (docs/evidence/spline-tables.md).
DEFAULT_SPLINE_TOLERANCE = 1e-5
_TOLERANCE_RANGE = (1e-9, 0.1)   # below 1e-9 float32 coefficients cannot follow the gains


def check_spline_tolerance(value, field: str) -> float:
    """`value` as a float in [1e-9, 0.1], else ProblemError naming `field`."""
    lo, hi = _TOLERANCE_RANGE
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(value) or not lo <= value <= hi:
        raise ProblemError(field, f"must be a number in [{lo:g}, {hi:g}] (the largest "
                                  f"relative error of a spline gain), got {value!r}")
    return float(value)
