"""The zero-order-hold tick data computed the slow, direct way: Van Loan's exponential of
size 2 d^2 (`moments.exact_tick`), the reference that the packed tick map of the exact-ZOH
designer is checked against (tests) and timed against (tools/bench/zoh_design.py)."""
from __future__ import annotations

import numpy as np

from stospline.expm import expm
from stospline.design.moments import augmented_drift, exact_tick, running_cost_matrix


def van_loan_tick_data(stage, h: float):
    """Tick data of `stage` over one tick of length `h`, from Van Loan's 2 d^2 exponential.

    Returns ``(A2, Hc, F)``: the adjoint moment map restricted to the ``[x; 1]`` rows and
    columns that act on the value (d^2 by (n+1)^2, d = n + m + 1), the symmetric running-cost
    integral over the tick (d by d), and the mean map ``[Ad, Bd, ...]`` (n rows of the
    augmented drift's exponential).
    """
    n, m = stage.B.shape
    d = n + m + 1
    prop = exact_tick(stage, m + 1, h)
    Hc = (prop.Psi.T @ running_cost_matrix(stage, n, m, d, n).ravel()).reshape(d, d)
    xs1 = np.r_[0:n, d - 1]
    idx = (xs1[:, None] * d + xs1[None, :]).ravel()
    F = expm(augmented_drift(stage, m + 1) * h)[:n]
    return prop.Phi.T[:, idx], 0.5 * (Hc + Hc.T), F
