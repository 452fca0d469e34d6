"""Numbers written at the precision they really have, so that regenerated files agree between
machines (docs/guide/firmware.md, "Reproducible tables").

Another CPU, BLAS kernel or library build changes the last bits of every double the design
computes: measured here, up to 1.5e-14 relative on the gains (the numpy tick loop against the
compiled one) and ~1e-16 of an array's largest entry on its small entries. A number printed to
more digits than that, or a bound derived from such last bits, differs from one machine to
the next. `ceil_significant` writes a bound rounded up (never down); `round_to_scale` writes an
array to a fixed number of digits of its largest entry.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from decimal import Decimal

__all__ = ["RoundedUp", "Verbatim", "verbatim", "ceil_significant", "round_to_scale"]


class RoundedUp(float):
    """A bound already rounded up to the digits it is written with. JSON writers print it as it
    is (`report.json_numbers.rounded` leaves it alone: rounding it again to nearest could
    lower it)."""


class Verbatim(float):
    """A number the user gave (a knot time, x0, epsilon, a fault level): JSON writers echo it
    exactly (`report.json_numbers.rounded` leaves it alone: rounding it to a computed number's
    quantum would print 1e-300 as 0.0)."""


def verbatim(x):
    """`x` (a number, or nested lists/tuples/arrays of numbers) with every float a
    `Verbatim`; other values unchanged."""
    if isinstance(x, np.ndarray):
        return verbatim(x.tolist())
    if isinstance(x, (list, tuple)):
        return [verbatim(v) for v in x]
    if isinstance(x, dict):
        return {k: verbatim(v) for k, v in x.items()}
    if isinstance(x, (float, np.floating)) and not isinstance(x, bool):
        return Verbatim(x)
    return x


def ceil_significant(x: float | Decimal, digits: int) -> RoundedUp:
    """The smallest decimal with `digits` significant digits that is >= `x` (x > 0), exactly
    (of the binary value: ``ceil_significant(2.928018756, 3)`` is 2.93, of 2.5 is 2.5, of 2.93,
    whose double is 2.93000000000000016, 2.94)."""
    from decimal import ROUND_CEILING, Decimal   # here: a design's float32 path needs none
    d = Decimal(x)  # exact: a float converts without rounding
    if not d.is_finite() or d <= 0:
        raise ValueError(f"a bound must be positive and finite, got {x}")
    return RoundedUp(d.quantize(Decimal(1).scaleb(d.adjusted() - digits + 1), ROUND_CEILING))


def round_to_scale(a, digits: int) -> np.ndarray:
    """`a` rounded to nearest at ``digits`` significant digits of its largest magnitude (one
    absolute quantum for the whole array, as its rounding errors scale with that entry; zeros
    stay +0.0, so that -1e-18 and +1e-18 print alike)."""
    a = np.asarray(a, dtype=float)
    big = float(np.abs(a).max()) if a.size else 0.0
    if big == 0.0 or not np.isfinite(big):
        return a + 0.0
    from decimal import Decimal
    places = digits - 1 - Decimal(big).adjusted()
    # Python's round() of a float is correctly rounded in decimal (numpy's is not).
    return np.array([round(float(v), places) for v in a.ravel()]).reshape(a.shape) + 0.0
