"""Numbers of the JSON summaries, rounded so that regenerated files stay byte-identical.

The designs agree to ~1e-14 however the arithmetic is ordered: summaries keep `SIGNIFICANT`
digits and an absolute quantum of 10^-`DECIMALS` (a residual of 1e-15, or a zero computed as
2e-18, prints as 0).
"""
from __future__ import annotations

import numpy as np

from stospline.precision import RoundedUp, Verbatim

__all__ = ["rounded", "cov_digits", "SIGNIFICANT", "DECIMALS"]

SIGNIFICANT, DECIMALS = 10, 10


def rounded(x):
    """Round floats (recursively through dicts, lists and arrays) for stable, readable JSON."""
    if isinstance(x, dict):
        return {k: rounded(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [rounded(v) for v in x]
    if isinstance(x, np.ndarray):
        return rounded(x.tolist())
    if isinstance(x, (RoundedUp, Verbatim)):  # a bound at its own precision, rounded up:
        return float(x)  # rounding it to nearest could lower it; an input: echoed as given
    if isinstance(x, (float, np.floating)):
        v = float(f"{round(float(x), DECIMALS):.{SIGNIFICANT}g}")
        return 0.0 if v == 0 else v
    if isinstance(x, np.integer):
        return int(x)
    return x


def cov_digits(cov: np.ndarray, mean: np.ndarray) -> np.ndarray:
    """A knot covariance for the summary. The oracle computes it as ``E xx' - mean mean'``, so
    it keeps only the digits of ``E xx'``: rounded to `SIGNIFICANT` digits of
    ``max(|cov|, |mean|^2)`` (a wealth of 100 with a variance of 12 loses three digits, and
    the last bits of the design would otherwise show)."""
    cov, mean = np.asarray(cov, dtype=float), np.asarray(mean, dtype=float)
    scale = max(float(np.abs(cov).max(initial=0.0)), float(np.max(mean ** 2, initial=0.0)))
    if not np.isfinite(scale) or scale == 0.0:
        return cov
    # The decade rounded to nearest, not down: means at constrained knots are round numbers
    # (a mean of 100 gives a scale of exactly 1e4), and the digits kept must not flip there.
    return np.round(cov, SIGNIFICANT - 1 - int(np.floor(np.log10(scale) + 0.5)))
