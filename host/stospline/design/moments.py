"""The exact moment map of one controller tick, shared by the oracle and the sampled-data
designer.

Over a tick the command is held, so ``z = [x; c]`` with constants ``c = [u; v; 1]`` obeys
``dz = Ahat z dt + sum_i z_i Gbar_i dZ`` and its second moment ``M = E zz'`` the linear ODE
``d/dt M = Ahat M + M Ahat' + sum_{i,j<n} M_ij Gbar_i Gbar_j'``. Vectorised row-major,
``vec M(h) = Phi vec M(0)`` and ``vec of the integral of M over the tick = Psi vec M(0)``;
expected running costs are linear functionals ``tr(Lbar M)``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from stospline.expm import expm

from stospline.problem.model import Stage

__all__ = ["TickPropagator", "noise_columns", "moment_generator", "augmented_drift",
           "exact_tick", "euler_tick", "running_cost_matrix"]


def noise_columns(G: np.ndarray, d: int) -> np.ndarray:
    """Matrix mapping vec(M) (row-major, d x d) to vec(sum_{i,j} M_ij Gbar_i Gbar_j').

    ``G`` (n_mult, n, mz): the diffusion is ``sum_i z_i G[i] dZ`` over the first n_mult
    components of z and enters the first n rows; ``Gbar_i`` is ``G[i]`` padded to d rows.
    """
    n_mult, n = G.shape[0], G.shape[1]
    Gbar = np.zeros((n_mult, d, G.shape[2]))
    Gbar[:, :n, :] = G
    out = np.zeros((d * d, d * d))
    for i in range(n_mult):
        for j in range(n_mult):
            out[:, i * d + j] = (Gbar[i] @ Gbar[j].T).ravel()
    return out


def moment_generator(Ahat: np.ndarray, G: np.ndarray) -> np.ndarray:
    """Linear operator of d/dt vec(M) for ``dz = Ahat z dt + sum_i z_i Gbar_i dZ``."""
    d = Ahat.shape[0]
    eye = np.eye(d)
    return np.kron(Ahat, eye) + np.kron(eye, Ahat) + noise_columns(G, d)


@dataclass(frozen=True)
class TickPropagator:
    """One tick of ``z = [x; c]`` with the constants ``c`` held: ``vec M(h) = Phi vec M(0)``,
    ``vec ∫_0^h M dt = Psi vec M(0)``."""
    Phi: np.ndarray
    Psi: np.ndarray


def augmented_drift(stage: Stage, n_const: int) -> np.ndarray:
    n, m = stage.B.shape
    d = n + n_const
    Ahat = np.zeros((d, d))
    Ahat[:n, :n] = stage.A
    Ahat[:n, n:n + m] = stage.B   # u is the first block of the constants
    if stage.f is not None and n_const > m:
        Ahat[:n, -1] = stage.f    # the drift f multiplies the constant 1, the last component
    return Ahat


def exact_tick(stage: Stage, n_const: int, h: float) -> TickPropagator:
    """The exact moment map of the SDE over one tick (Van Loan block exponential)."""
    # z = [x; u; ...]: state and input noise multiply the first n + m components.
    gen = moment_generator(augmented_drift(stage, n_const), stage.noise_tensor)
    D = gen.shape[0]
    big = np.zeros((2 * D, 2 * D))
    big[:D, :D] = gen * h
    big[:D, D:] = np.eye(D) * h
    E = expm(big)
    return TickPropagator(E[:D, :D], E[:D, D:])


def euler_tick(stage: Stage, n_const: int, h: float, substeps: int) -> TickPropagator:
    """The moment map of the Monte Carlo plant scheme: `substeps` exponential Euler–Maruyama
    steps ``z+ = e^{Ahat dt} z + sum_i z_i Gbar_i dZ`` with a left-point cost rule."""
    dt = h / substeps
    Ahat = augmented_drift(stage, n_const)
    Ad = expm(Ahat * dt)
    d = Ahat.shape[0]
    step = np.kron(Ad, Ad) + dt * noise_columns(stage.noise_tensor, d)
    Phi = np.eye(d * d)
    Psi = np.zeros((d * d, d * d))
    for _ in range(substeps):
        Psi += dt * Phi
        Phi = step @ Phi
    return TickPropagator(Phi, Psi)


def running_cost_matrix(stage: Stage, n: int, m: int, d: int, u_at: int) -> np.ndarray:
    """Symmetric matrix Lbar with ``E L(x,u) = tr(Lbar E zz')``; 1 is the last component."""
    Lb = np.zeros((d, d))
    xs, us = slice(0, n), slice(u_at, u_at + m)
    Lb[xs, xs] = stage.Q
    Lb[xs, us] = stage.S
    Lb[us, xs] = stage.S.T
    Lb[us, us] = stage.R
    Lb[xs, -1] = Lb[-1, xs] = stage.q
    Lb[us, -1] = Lb[-1, us] = stage.r
    Lb[-1, -1] = stage.rho
    return Lb


def _cost_generator(stage: Stage, n_const: int) -> np.ndarray:
    """Generator of ``[vec M; J]`` for ``z = [x; u; ...; 1]``: the moment ODE plus
    ``dJ/dt = tr(Lbar M)`` (the expected running cost), as one (d^2 + 1) square matrix."""
    n, m = stage.B.shape
    d = n + n_const
    D = d * d
    out = np.zeros((D + 1, D + 1))
    out[:D, :D] = moment_generator(augmented_drift(stage, n_const), stage.noise_tensor)
    out[D, :D] = running_cost_matrix(stage, n, m, d, n).ravel()
    return out


def varying_tick(stage: Stage, n_const: int, t0: float, h: float) -> tuple[np.ndarray,
                                                                             np.ndarray]:
    """One tick ``[t0, t0 + h]`` of a stage whose data vary in time.

    Returns ``(Phi, cost_row)``: ``vec M(h) = Phi vec M(0)`` and the expected running cost
    over the tick ``cost_row @ vec M(0)``. Computed with the fourth-order Magnus expansion
    at the two Gauss–Legendre points, ``Omega = h/2 (G1 + G2) + sqrt(3) h^2 / 12 [G2, G1]``:
    local error O(h^5) for data smooth within the tick; a kink of linearly interpolated data
    inside a tick lowers that tick's error to O(h^3). Time-invariant data give the exact map.
    """
    c = np.sqrt(3.0) / 6.0
    G1 = _cost_generator(stage.at(t0 + (0.5 - c) * h), n_const)
    G2 = _cost_generator(stage.at(t0 + (0.5 + c) * h), n_const)
    omega = 0.5 * h * (G1 + G2) + (np.sqrt(3.0) / 12.0) * h * h * (G2 @ G1 - G1 @ G2)
    E = expm(omega)
    D = E.shape[0] - 1
    return E[:D, :D], E[D, :D]
