"""A plant scheme of weak order two in the second moments ("weak2"), run by the harness's
exponential Euler–Maruyama step on substitute stage data.

The harness's step (`montecarlo.simulate`, ``plant.c``) is ``x+ = Ad x + Bd u + fd + W(z) ξ
sqrt(dt)`` with ``W(z) = sum_i z_i G_i`` linear in ``z = [x; u]``, and a running cost
``dt L(z)`` per step. Its mean is exact; its conditional covariance ``dt G(z) G(z)'`` and its
left-point cost are first-order, so the expected cost's bias falls as 1/substeps
(`plant_scheme`). Here the same step runs on a stage whose data are chosen per step length
dt so that

* the conditional covariance of a step is the SDE's to O(dt^3): expanding the covariance
  ODE ``dC/dt = A C + C A' + E[G(z(t)) G(z(t))']`` about the step's start,
  ``C(dt) = dt G G' + dt^2/2 [(A G + G(Az)) G' + G (A G + G(Az))' + sum_k M_k M_k'] + O(dt^3)``
  with ``G = G(z)``, ``Az = A x + B u`` (the input held) and ``M_k = G_x(G e_k)`` (the noise
  of the noise: column k of G read as a state, through the state multipliers only). With
  ``M_k = G T_k`` for constant ``T_k`` (every noise that multiplies the component it drives,
  as the robot's velocity noise) ``W = G (I + dt/4 sum_k T_k T_k') + dt/2 (A G + G(Az))``
  matches it, with the same normal numbers; otherwise the ``M_k`` become extra columns
  ``sqrt(dt/2) M_k`` (mz^2 more numbers a step);
* the running cost of a step is its exact conditional expectation given the step's start,
  ``E[∫_0^dt L(z(s)) ds | z] = z' Hc z`` (the Van Loan integral of the exact moment map,
  `design.moments.exact_tick`), written as the stage's cost data ``Hc / dt``.

So the second moments at the ticks, and with them the expected cost, carry an O(dt^2) error:
the bias falls as 1/substeps^2. It is computed exactly, as the Euler scheme's is: the oracle's
"euler" propagator on the substitute stages (`scheme_problem`) is this scheme's exact moment
map. Per path the cost is the conditional expectation of the step's cost (the same mean, a
smaller spread). Third and higher moments keep an O(dt) error (the noise is Gaussian); the
exits a run counts are compared with fine-step runs in docs/evidence/corridor-exit.md.

Needs time-invariant stages whose drift ``f`` does not enter the noise (``G(f) = 0``): a
constant term in W has no multiplier in ``[x; u]`` (ValueError otherwise).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from stospline.design.moments import exact_tick, running_cost_matrix
from stospline.problem.model import Problem, Stage

__all__ = ["SCHEMES", "scheme_stage", "scheme_problem"]

SCHEMES = ("euler", "weak2")


def _absorbing_factors(Gx: np.ndarray, M: np.ndarray) -> np.ndarray | None:
    """``P = sum_k T_k T_k'`` when every ``M_k(z) = G(z) T_k`` (M (k, n+m, n, mz): the
    multiplier tensors of M_k; Gx (n+m, n, mz) those of G), else None."""
    nm, n, mz = Gx.shape
    # G(z) T for every z: the rows of the stacked multiplier matrices times T
    lhs = Gx.reshape(nm * n, mz)
    P = np.zeros((mz, mz))
    for Mk in M:
        rhs = Mk.reshape(nm * n, mz)
        T, *_ = np.linalg.lstsq(lhs, rhs, rcond=None)
        if not np.allclose(lhs @ T, rhs, rtol=0.0, atol=1e-14 * max(1.0, np.abs(rhs).max())):
            return None
        P += T @ T.T
    return P


def scheme_stage(stage: Stage, dt: float) -> Stage:
    """The stage data on which the harness's step of length `dt` is the weak-order-two scheme
    (module docstring): noise multipliers (G, H) and running cost (Q, S, R, q, r, rho)."""
    if stage.varying is not None:
        raise ValueError("scheme weak2: time-varying stage data are not supported")
    n, m = stage.B.shape
    Gt = stage.noise_tensor                                   # (n + m, n, mz) over [x; u]
    mz = Gt.shape[2]
    if stage.f is not None and np.any(np.tensordot(stage.f, Gt[:n], axes=(0, 0))):
        raise ValueError("scheme weak2: the drift f enters the noise (G(f) != 0)")
    # Az as a linear map of z = [x; u]: (n, n + m)
    Az = np.hstack([stage.A, stage.B])
    # multiplier tensors (over z) of A G(z) and of G(Az): both (n + m, n, mz)
    AG = np.einsum("ab,ibk->iak", stage.A, Gt)
    GAz = np.einsum("ji,jak->iak", Az, Gt[:n])
    E = 0.5 * (AG + GAz)
    # M_k(z) = sum_j (G(z) e_k)_j G_j (j over the states): multipliers (k, n + m, n, mz)
    M = np.einsum("ijk,jal->kial", Gt, Gt[:n])
    P = _absorbing_factors(Gt, M)
    if P is not None:
        W = np.einsum("iak,kl->ial", Gt, np.eye(mz) + 0.25 * dt * P) + dt * E
    else:
        extra = np.sqrt(0.5 * dt) * np.concatenate(list(M), axis=2)   # mz^2 more columns
        W = np.concatenate([Gt + dt * E, extra], axis=2)
    # the exact conditional expectation of the step's running cost, z' Hc z (z = [x; u; 1])
    d = n + m + 1
    Psi = exact_tick(stage, m + 1, dt).Psi
    Hc = (running_cost_matrix(stage, n, m, d, n).ravel() @ Psi).reshape(d, d)
    Hc = 0.5 * (Hc + Hc.T) / dt
    xs, us = slice(0, n), slice(n, n + m)
    return replace(stage, G=W[:n], H=W[n:], Q=Hc[xs, xs], S=Hc[xs, us], R=Hc[us, us],
                   q=Hc[xs, -1], r=Hc[us, -1], rho=float(Hc[-1, -1]))


def scheme_problem(problem: Problem, substeps: int, scheme: str = "weak2") -> Problem:
    """`problem` with its stages replaced by those the harness runs for `scheme` at
    `substeps` plant steps per tick (``"euler"``: the problem itself)."""
    if scheme not in SCHEMES:
        raise ValueError(f"scheme: {scheme!r} is not one of {', '.join(SCHEMES)}")
    if scheme == "euler":
        return problem
    dt = 1.0 / (problem.tick_hz * substeps)
    return replace(problem, stages=tuple(scheme_stage(s, dt) for s in problem.stages))
