"""Rows of linear constraints, brought to one scale as they are read.

A row ``lower <= c'y <= upper`` (a knot constraint, a region, a corridor wall ``a'y <= b``)
means the same for any positive multiple of ``c`` and its bounds. Every solver and every check
downstream (feasibility, active sets, band and region tolerances, corridor distances) works on
rows whose largest coefficient lies in ``[1, 2)``: `normalise_rows` scales each row and its
bounds by a power of two, which is exact in binary floating point, so a row and its multiple by
any positive factor give the same design up to rounding, and a row already in that form is left
bit for bit as it was. A coefficient that is subnormal, or a coefficient or bound that the
scaling would push outside the normal range of doubles, cannot be represented to full
precision: it is refused, naming its key, rather than rounded away.
"""
from __future__ import annotations

import numpy as np

from stospline.errors import ProblemError

__all__ = ["normalise_rows", "check_no_subnormal", "TINY"]

TINY = float(np.finfo(float).tiny)   # smallest normal double, 2.2e-308


def check_no_subnormal(M: np.ndarray, path: str) -> None:
    """Refuse a subnormal entry of `M` (0 < |x| < 2.2e-308), naming ``path[i][j]``."""
    bad = np.argwhere((M != 0) & (np.abs(M) < TINY))
    if bad.size:
        at = "".join(f"[{int(k)}]" for k in bad[0])
        v = float(M[tuple(bad[0])])
        raise ProblemError(f"{path}{at}", f"{v:g} is subnormal (below {TINY:.4g}, the smallest "
                                          f"normal double): it has lost precision; write 0 or "
                                          f"scale its row up")


def _row_exponents(C: np.ndarray) -> np.ndarray:
    """Per row, the power of two that brings its largest |coefficient| into [1, 2) (0 for a
    zero row)."""
    top = np.abs(C).max(axis=1)
    _, e = np.frexp(top)            # top = f * 2**e with f in [0.5, 1)
    return np.where(top > 0, 1 - e, 0).astype(int)


def _refuse_unrepresentable(scaled: np.ndarray, raw: np.ndarray, top: np.ndarray,
                            path: str, what: str) -> None:
    """Refuse an entry that the row scaling made infinite or subnormal (or zero from nonzero)."""
    lost = ~np.isfinite(scaled) | ((raw != 0) & (np.abs(scaled) < TINY))
    bad = np.argwhere(lost)
    if bad.size:
        idx = tuple(int(k) for k in bad[0])
        row = idx[0]
        at = "".join(f"[{k}]" for k in idx)
        ratio = "overflows" if not np.isfinite(scaled[idx]) else "underflows"
        raise ProblemError(f"{path}{at}", f"{float(raw[idx]):g} divided by its row's largest "
                                          f"coefficient {float(top[row]):g} {ratio} double "
                                          f"precision ({what})")


def normalise_rows(C: np.ndarray, path: str,
                   bounds: dict[str, np.ndarray]) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """``(C, bounds)`` with each row of `C` and its entry of every bound vector scaled by the
    power of two that brings the row's largest |coefficient| into ``[1, 2)``.

    Parameters
    ----------
    C : (rows, p) array
        The rows (finite; zero rows are left as they are).
    path : str
        The key of `C` (``"knots[1].constraint.C"``), for errors.
    bounds : dict
        Key of each bound vector (``"knots[1].constraint.upper"``) -> its values (rows,).

    Raises
    ------
    ProblemError
        Naming ``path[i][j]`` for a subnormal coefficient, or a coefficient too small beside
        its row's largest to stay normal; naming the bound key for a bound whose ratio to its
        row's largest coefficient overflows or underflows.
    """
    check_no_subnormal(C, path)
    for key, v in bounds.items():
        check_no_subnormal(v, key)
    shift, top = _row_exponents(C), np.abs(C).max(axis=1)
    out = np.ldexp(C, shift[:, None])
    _refuse_unrepresentable(out, C, top, path, "a row spans at most the range of "
                                                 "normal doubles")
    scaled = {}
    for key, v in bounds.items():
        scaled[key] = np.ldexp(v, shift)
        _refuse_unrepresentable(scaled[key], v, top, key, "rows are solved scaled to a largest "
                                                            "coefficient in [1, 2)")
    return out, scaled
