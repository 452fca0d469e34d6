"""The linear minimum mean-square error (Kalman-type) measurement update."""
from __future__ import annotations

import numpy as np

__all__ = ["lmmse_gain"]

# Directions of C P C' + R below this fraction of its largest eigenvalue carry no information
# (an exactly measured, exactly known state): the pseudo-inverse gives them no gain.
_RCOND = 1e-12


def lmmse_gain(P: np.ndarray, C: np.ndarray, R: np.ndarray) -> np.ndarray:
    """``L = P C' (C P C' + R)^+``: the gain of ``x̂+ = x̂ + L (y - C x̂)`` that minimises the
    error covariance ``E (x - x̂+)(x - x̂+)'`` (in the positive semidefinite order) when the
    prior error has covariance `P`, is uncorrelated with the sensor noise ``r = y - C x`` and
    ``E rr' = R``.

    Parameters
    ----------
    P : (n, n) ndarray
        Prior error covariance.
    C : (p, n) ndarray
        Output matrix.
    R : (p, p) ndarray
        The sensor noise's (unconditional) covariance.

    Returns
    -------
    (n, p) ndarray
    """
    S = C @ P @ C.T + R
    S = 0.5 * (S + S.T)
    return P @ C.T @ np.linalg.pinv(S, rcond=_RCOND, hermitian=True)
