"""Linearise a nonlinear Itô SDE ``dX = f(t, X, u) dt + g(t, X, u) dZ`` along a path.

At each point ``(t_k, xbar_k, ubar_k)`` of the path

    f(t, x, u) ≈ A x + B u + c,        c = f(t, xbar, ubar) - A xbar - B ubar
    g(t, x, u) ≈ g0 + Σ_i x_i G_i + Σ_j u_j H_j,      G_i = ∂g/∂x_i,  H_j = ∂g/∂u_j,
    g0 = g(t, xbar, ubar) - Σ xbar_i G_i - Σ ubar_j H_j

(the problem's diffusion is ``Σ x_i G_i + Σ u_j H_j``: `g0` is returned so that the caller can
refuse an additive part it cannot represent).

Derivatives are central differences with the step ``h_i = eps^(1/3) max(1, |z_i|)`` (the step
that balances truncation, O(h²), against rounding, O(eps/h)); the same difference with ``2h``
estimates the truncation error: ``|D(2h) - D(h)| / 3``. Where the model is affine in z_i the
rounding of that step, ~eps^(2/3) relative, is all the error: so each entry is also taken
with the wide steps ``H_i = max(1, |z_i|)`` and ``2 H_i`` (divided by the step as rounded), and
where they agree with each other within the narrow one's error estimate and with the narrow
one within that and its values' rounding, the wide one, exact to a few eps, stands. A model
linear in x and u thus linearises to its own coefficients to rounding. The wide points may
lie outside the model's domain: a model that refuses one of them (`ProblemError`: a status or
a value not finite) keeps the narrow differences.

A drift constant ``c`` within the rounding of its own terms (``8 eps (|f| + |A||x| + |B||u|)``)
is zero.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stospline.errors import ProblemError

__all__ = ["Linearisation", "linearise"]

_EPS = np.finfo(float).eps


@dataclass(frozen=True)
class Linearisation:
    """The linear model at N points: A (N, n, n), B (N, n, m), c (N, n), G (N, n, n, mz)
    (``G[k, i]`` multiplies x_i), H (N, m, n, mz), g0 (N, n, mz); `error` the largest
    estimated error of a derivative entry, relative to ``1 + |entry|``."""
    A: np.ndarray
    B: np.ndarray
    c: np.ndarray
    G: np.ndarray
    H: np.ndarray
    g0: np.ndarray
    error: float


def _differences(fun, t, z, n: int, width: tuple, step: np.ndarray):
    """``(D(step), D(2 step), rounding of D(step))``: the central differences of `fun` along
    each z_i (shape (nz, N) + width), each divided by its step as rounded,
    ``(z + s) - (z - s)``, from one batch of ``4 (n + m)`` perturbed copies of the N points;
    the rounding is that of the values, ``4 eps (|f(z + s)| + |f(z - s)|) / 2s``."""
    N, nz = z.shape
    batch, spans = [], []
    for i in range(nz):
        for s in (1.0, 2.0):
            zp, zm = z.copy(), z.copy()
            zp[:, i] += s * step[:, i]
            zm[:, i] -= s * step[:, i]
            batch += [zp, zm]
            spans.append(zp[:, i] - zm[:, i])
    zz = np.concatenate(batch)
    vals = fun(np.tile(t, 4 * nz), zz[:, :n], zz[:, n:]).reshape((nz, 2, 2, N) + width)
    span = np.reshape(spans, (nz, 2, N) + (1,) * len(width))
    d = (vals[:, :, 0] - vals[:, :, 1]) / span
    rounding = 4 * _EPS * (np.abs(vals[:, 0, 0]) + np.abs(vals[:, 0, 1])) / span[:, 0]
    return d[:, 0], d[:, 1], rounding


def _derivatives(fun, t, z, n: int, width: tuple) -> tuple[np.ndarray, np.ndarray]:
    """``∂fun/∂z_i`` for every i (shape (N, n + m) + width) and its error estimate per entry:
    the narrow differences, or the wide ones where the model is affine to rounding."""
    d1, d2, rounding = _differences(fun, t, z, n, width,
                                    _EPS ** (1 / 3) * np.maximum(1.0, np.abs(z)))
    err = np.abs(d2 - d1) / 3 + _EPS ** (2 / 3) * (1 + np.abs(d1))
    try:
        w1, w2, _ = _differences(fun, t, z, n, width, np.maximum(1.0, np.abs(z)))
    except ProblemError:
        w1 = None
    if w1 is not None:
        # the wide steps' truncation within the narrow error; the two within its rounding
        affine = (np.abs(w1 - d1) <= err + rounding) & (np.abs(w2 - w1) <= err)
        d1 = np.where(affine, w1, d1)
        err = np.where(affine, np.abs(w2 - w1) / 3 + 4 * _EPS * (1 + np.abs(w1)), err)
    return np.moveaxis(d1, 0, 1), np.moveaxis(err, 0, 1)


def linearise(model, t, xbar, ubar) -> Linearisation:
    """The linear model of `model` (``drift(t, x, u)`` (N, n) and ``diffusion(t, x, u)``
    (N, n, mz), batched over points, as `stospline.problem.plant_c.PlantModel`) at the points
    ``(t[k], xbar[k], ubar[k])``.

    Examples
    --------
    >>> import numpy as np
    >>> class Pendulum:      # dx = (x1, -sin x0 + u) dt + 0.1 x1 dZ
    ...     def drift(self, t, x, u): return np.stack([x[:, 1], -np.sin(x[:, 0]) + u[:, 0]], 1)
    ...     def diffusion(self, t, x, u): return np.stack([0 * x[:, :1], 0.1 * x[:, 1:]], 1)
    >>> lin = linearise(Pendulum(), np.zeros(1), np.array([[0.0, 1.0]]), np.zeros((1, 1)))
    >>> np.round(lin.A[0], 6).tolist(), lin.error < 1e-8
    ([[0.0, 1.0], [-1.0, 0.0]], True)
    """
    t = np.asarray(t, dtype=float)
    xbar, ubar = np.atleast_2d(xbar).astype(float), np.atleast_2d(ubar).astype(float)
    N, n = xbar.shape
    z = np.hstack([xbar, ubar])
    f0 = model.drift(t, xbar, ubar)
    g = model.diffusion(t, xbar, ubar)
    mz = g.shape[2]
    Jf, ef = _derivatives(model.drift, t, z, n, (n,))              # (N, nz, n)
    Jg, eg = _derivatives(model.diffusion, t, z, n, (n, mz))       # (N, nz, n, mz)
    A = np.swapaxes(Jf[:, :n], 1, 2)
    B = np.swapaxes(Jf[:, n:], 1, 2)
    Ax, Bu = np.einsum("kij,kj->ki", A, xbar), np.einsum("kij,kj->ki", B, ubar)
    c = f0 - Ax - Bu
    terms = np.abs(f0) + np.einsum("kij,kj->ki", np.abs(A), np.abs(xbar)) \
        + np.einsum("kij,kj->ki", np.abs(B), np.abs(ubar))
    c[np.abs(c) <= 8 * _EPS * terms] = 0.0
    G, H = Jg[:, :n], Jg[:, n:]
    g0 = g - np.einsum("kiab,ki->kab", G, xbar) - np.einsum("kjab,kj->kab", H, ubar)
    error = max(float(np.max(ef / (1 + np.abs(Jf)), initial=0.0)),
                float(np.max(eg / (1 + np.abs(Jg)), initial=0.0)))
    return Linearisation(A, B, c, G, H, g0, error)
