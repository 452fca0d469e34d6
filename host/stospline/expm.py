"""Matrix exponential in numpy (scaling and squaring with Padé approximants, Higham 2005,
"The scaling and squaring method for the matrix exponential revisited", Algorithm 2.3).

Why not ``scipy.linalg.expm``: importing scipy.linalg costs about 0.3 s of CPU, more than the
whole robot design, and the exponential is all the designer and the oracle take from it. The
two agree to rounding (``tests/python/sim/test_fast_paths.py``).
"""
from __future__ import annotations

import numpy as np

from stospline.errors import StosplineError

__all__ = ["expm", "expm_many", "NonFiniteMatrix", "require_finite"]


class NonFiniteMatrix(StosplineError, FloatingPointError, ValueError):
    """The matrix holds NaN or Inf (products of the problem's data overflowed)."""

# Padé degree m -> the largest 1-norm for which [m/m] is accurate to unit roundoff (Table 2.3)
_THETA = {3: 1.495585217958292e-2, 5: 2.539398330063230e-1, 7: 9.504178996162932e-1,
          9: 2.097847961257068e0, 13: 5.371920351148152e0}
_B = {3: (120., 60., 12., 1.),
      5: (30240., 15120., 3360., 420., 30., 1.),
      7: (17297280., 8648640., 1995840., 277200., 25200., 1512., 56., 1.),
      9: (17643225600., 8821612800., 2075673600., 302702400., 30270240., 2162160., 110880.,
          3960., 90., 1.),
      13: (64764752532480000., 32382376266240000., 7771770303897600., 1187353796428800.,
           129060195264000., 10559470521600., 670442572800., 33522128640., 1323241920.,
           40840800., 960960., 16380., 182., 1.)}


_MAX_SQUARINGS = 8   # beyond: scipy.linalg.expm (a norm above ~1400)


def require_finite(values: np.ndarray) -> np.ndarray:
    """`values` itself, or NonFiniteMatrix when an entry is NaN or Inf (an ODE start state or
    a matrix built from data whose products overflowed)."""
    if not np.all(np.isfinite(values)):
        raise NonFiniteMatrix("the design's intermediate numbers are not finite")
    return values


def _pade(A: np.ndarray, m: int, powers: dict) -> tuple[np.ndarray, np.ndarray]:
    """``(U, V)`` of the [m/m] Padé approximant: ``exp(A) ~ (V - U)^-1 (V + U)``."""
    b = _B[m]
    eye = np.eye(A.shape[0])
    if m < 13:
        U = b[1] * eye
        V = b[0] * eye
        for k in range(1, m // 2 + 1):
            P = powers[2 * k]
            U = U + b[2 * k + 1] * P
            V = V + b[2 * k] * P
        return A @ U, V
    A2, A4, A6 = powers[2], powers[4], powers[6]
    U = A @ (A6 @ (b[13] * A6 + b[11] * A4 + b[9] * A2)
             + b[7] * A6 + b[5] * A4 + b[3] * A2 + b[1] * eye)
    V = (A6 @ (b[12] * A6 + b[10] * A4 + b[8] * A2)
         + b[6] * A6 + b[4] * A4 + b[2] * A2 + b[0] * eye)
    return U, V


def expm(A) -> np.ndarray:
    """``exp(A)`` of a square real matrix."""
    A = np.asarray(A, dtype=float)
    if A.ndim != 2 or A.shape[0] != A.shape[1]:
        raise ValueError(f"expm needs a square matrix, got shape {A.shape}")
    if A.shape[0] == 0:
        return A.copy()
    if not np.all(np.isfinite(A)):
        raise NonFiniteMatrix("expm needs a finite matrix")
    norm = float(np.abs(A).sum(axis=0).max())
    powers = {2: A @ A}
    for m in (3, 5, 7, 9):
        if m >= 5:
            powers[m - 1] = powers[m - 3] @ powers[2]
        if norm <= _THETA[m]:
            U, V = _pade(A, m, powers)
            return np.linalg.solve(V - U, V + U)
    s = max(0, int(np.ceil(np.log2(norm / _THETA[13])))) if norm > 0 else 0
    if s > _MAX_SQUARINGS:
        # Plain scaling and squaring over-scales a matrix whose norm comes from a huge
        # off-diagonal block (Van Loan's block matrices of a large Q): many squarings amplify
        # rounding. scipy's expm bounds s with the norms of A^k (Al-Mohy and Higham 2009);
        # loading it only here keeps its import off the ordinary path.
        from scipy.linalg import expm as scipy_expm
        return scipy_expm(A)
    # ldexp and a fresh square: 4.0 ** s overflows a Python float (OverflowError) for s > 511,
    # and A @ A itself may already be inf for a huge A, where (A / 2^s)^2 is finite.
    As = np.ldexp(A, -s)
    scaled = {2: As @ As}
    scaled[4] = scaled[2] @ scaled[2]
    scaled[6] = scaled[4] @ scaled[2]
    U, V = _pade(As, 13, scaled)
    X = np.linalg.solve(V - U, V + U)
    for _ in range(s):
        X = X @ X
    return X


def expm_many(A) -> np.ndarray:
    """``exp`` of each of a stack of square matrices ``(N, d, d)``: `expm`'s algorithm with
    the degree and the scaling of the largest norm in the stack (a higher degree than one
    matrix needs is as accurate), vectorised over the stack."""
    A = np.asarray(A, dtype=float)
    if A.ndim != 3 or A.shape[1] != A.shape[2]:
        raise ValueError(f"expm_many needs a stack of square matrices, got shape {A.shape}")
    if A.shape[0] == 0 or A.shape[1] == 0:
        return A.copy()
    if not np.all(np.isfinite(A)):
        raise NonFiniteMatrix("expm needs a finite matrix")
    norm = float(np.abs(A).sum(axis=1).max())
    if norm > _THETA[13] * 2.0 ** _MAX_SQUARINGS:
        return np.stack([expm(a) for a in A])          # the rare path, one by one
    eye = np.eye(A.shape[1])
    for m in (3, 5, 7, 9):
        if norm <= _THETA[m]:
            powers = {2: A @ A}
            for k in range(4, m, 2):
                powers[k] = powers[k - 2] @ powers[2]
            b = _B[m]
            U, V = b[1] * eye, b[0] * eye
            for k in range(1, m // 2 + 1):
                U = U + b[2 * k + 1] * powers[2 * k]
                V = V + b[2 * k] * powers[2 * k]
            U = A @ U
            return np.linalg.solve(V - U, V + U)
    s = max(0, int(np.ceil(np.log2(norm / _THETA[13]))))
    As = np.ldexp(A, -s)
    A2 = As @ As
    A4 = A2 @ A2
    A6 = A4 @ A2
    b = _B[13]
    U = As @ (A6 @ (b[13] * A6 + b[11] * A4 + b[9] * A2)
              + b[7] * A6 + b[5] * A4 + b[3] * A2 + b[1] * eye)
    V = (A6 @ (b[12] * A6 + b[10] * A4 + b[8] * A2)
         + b[6] * A6 + b[4] * A4 + b[2] * A2 + b[0] * eye)
    X = np.linalg.solve(V - U, V + U)
    for _ in range(s):
        X = X @ X
    return X
