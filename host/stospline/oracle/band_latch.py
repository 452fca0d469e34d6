"""The multipliers the firmware latches at t0 from the measured state of a band table: the
design's band dual (W symmetric, `stospline.design.bands.solve_band_dual`) or a spline table's,
re-solved for its gains (W not symmetric: the box LCP, `stospline.table.spline.band`). Here,
above both, because the oracles model the firmware whichever table it runs."""
from __future__ import annotations

import numpy as np

from stospline.design.bands import solve_band_dual
from stospline.table.format import BandQP
from stospline.table.spline.band import solve_band_lcp

__all__ = ["target_latch"]


def target_latch(qp: BandQP, x0: np.ndarray, *, float32: bool = True) -> np.ndarray:
    """The multipliers the firmware latches at t0 from the measured state: the solution of the
    band dual at ``float32(x0)`` (what ``stsp_step`` hands to ``stsp_bandqp_solve``), rounded
    to float32 as the controller stores them. ``float32=False``: in double precision (for an
    unquantized table)."""
    x = np.asarray(x0, dtype=np.float32 if float32 else float).astype(float)
    if np.array_equal(qp.W, qp.W.T):
        lam = solve_band_dual(qp.e(x), qp.W, qp.lo, qp.hi).lam
    else:
        lam = solve_band_lcp(qp.e(x), qp.W, qp.lo, qp.hi)[0]
    return lam.astype(np.float32) if float32 else lam
