"""Exact zero-order-hold discretisation of the plant's drift, for closed loops run on the host
(noise-free checks, replay recordings)."""
from __future__ import annotations

import numpy as np

from stospline.expm import expm


def zoh(A: np.ndarray, B: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """``(Ad, Bd)`` with ``x(t + dt) = Ad x(t) + Bd u`` for ``x' = A x + B u``, u held over `dt`.

    Examples
    --------
    >>> import numpy as np
    >>> Ad, Bd = zoh(np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0], [1.0]]), 0.5)
    >>> Ad.tolist(), Bd.ravel().tolist()
    ([[1.0, 0.5], [0.0, 1.0]], [0.125, 0.5])
    """
    n, m = B.shape
    big = np.zeros((n + m, n + m))
    big[:n, :n], big[:n, n:] = A, B
    E = expm(big * dt)
    return E[:n, :n], E[:n, n:]
