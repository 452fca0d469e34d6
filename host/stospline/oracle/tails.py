"""Exact fourth moments of the Monte Carlo plant scheme: the standard errors a Monte Carlo
run's mean cost, knot means and knot variances really have.

With multiplicative noise the closed loop's state is heavy-tailed (between commands a
velocity is a geometric Brownian motion), so the sample's own standard errors, from its
second and fourth central sums, are unreliable: the fourth central sum of a few thousand
paths misses the rare large excursions that dominate it. The exact ones come from the same
loop the second-moment oracle (`evaluate.evaluate_table` with ``propagator="euler"``)
propagates, carried to degree four.

Over one plant step of the scheme every quantity is linear in the augmented state
``q = [x; u; v; 1]`` (u held over the tick, v latched over the stage): ``q+ = (A + sum_k
xi_k N_k) q`` with ``A = e^{Ahat dt}`` on ``[x; u; 1]`` and ``N_k q = sum_i q_i Gbar_i[:, k]``
the diffusion, ``xi ~ N(0, dt I)``. So the moments ``E q^{(x)4}`` (a symmetric 4-tensor,
kept on the multisets of indices), ``E[J q q']`` and ``E[J^2]`` of the cost accumulated so far
(left-point rule, ``J += dt L(q)``, as the scheme charges it) map linearly through a step;
the expectation over ``xi`` is exact by the three-point Gauss-Hermite rule per noise channel
(exact for polynomials of degree five in each). A tick starts with the law's command ``u =
-K x - L v - k0`` (an affine map of ``y = [x; v; 1]``), the stage's first tick with the latch,
a knot adds its penalty. Lower moments are slices of the 4-tensor (the index of the constant
1 repeated): the second moments and the mean cost are checked against the second-moment
oracle at every knot (`TailsMismatch` when they differ beyond rounding).

The step's map and the ticks run in C (`oracle.tails_kernel`) where the oracle's module can be
built; the numpy loop here is their reference and fallback.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from stospline.errors import StosplineError
from stospline.expm import expm
from stospline.design.moments import augmented_drift, running_cost_matrix
from stospline.oracle.tails_kernel import compiled_tails
from stospline.oracle.tick_moments import _table_latch
from stospline.problem.model import Problem

__all__ = ["TailMoments", "TailsMismatch", "evaluate_tails", "tails_unsupported"]

# The second moments from the fourth-moment loop agree with the second-moment oracle's to
# this, relative to the largest second moment (rounding in two orders of summation).
CHECK_RTOL = 1e-8
# The largest loops evaluated: the step's map has C(d + 3, 4) rows (3060 at d = 15), and its
# expectation 3^channels Gauss-Hermite nodes.
MAX_DIM = 15
MAX_CHANNELS = 5


class TailsMismatch(StosplineError, RuntimeError):
    """The fourth-moment loop's second moments differ from the second-moment oracle's."""


@dataclass(frozen=True)
class TailMoments:
    """The cost's mean and variance and, per knot, each state component's mean, variance and
    fourth central moment, of the loop under the plant scheme with `substeps` steps per
    tick."""
    J: float
    cost_var: float
    knot_mean: list[np.ndarray]
    knot_cov: list[np.ndarray]
    knot_mu4: list[np.ndarray]        # E (x_i - E x_i)^4 per component
    substeps: int

    def cost_mean_se(self, paths: int) -> float:
        """Standard error of the mean cost of `paths` independent paths."""
        return float(np.sqrt(max(self.cost_var, 0.0) / paths))

    def knot_mean_se(self, k: int, paths: int) -> np.ndarray:
        return np.sqrt(np.maximum(np.diag(self.knot_cov[k]), 0.0) / paths)

    def knot_var_se(self, k: int, paths: int) -> np.ndarray:
        """Standard error of the unbiased sample variance of each component at knot k:
        ``Var s^2 = mu4 / N - sigma^4 (N - 3) / (N (N - 1))``."""
        s4 = np.maximum(np.diag(self.knot_cov[k]), 0.0) ** 2
        N = float(paths)
        v = self.knot_mu4[k] / N - s4 * (N - 3.0) / (N * (N - 1.0))
        return np.sqrt(np.maximum(v, 0.0))

    def knot_excess_kurtosis(self, k: int) -> np.ndarray:
        """``mu4 / sigma^4 - 3`` per component at knot k (0 for a component without spread)."""
        v = np.diag(self.knot_cov[k])
        with np.errstate(divide="ignore", invalid="ignore"):
            out = np.where(v > 0, self.knot_mu4[k] / np.where(v > 0, v, 1.0) ** 2 - 3.0, 0.0)
        return out


def tails_unsupported(problem: Problem, table) -> str | None:
    """Why `evaluate_tails` cannot evaluate `table` on `problem` (None: it can)."""
    if getattr(table, "delay_ticks", 0):
        return "a table designed for a one-tick delay"
    if any(st.varying is not None for st in problem.stages[:table.n_stages]):
        return "time-varying stage data"
    n, m, n_latch = table.dims
    if n + m + n_latch + 1 > MAX_DIM:
        return f"more than {MAX_DIM - 1} states, inputs and multipliers together"
    return too_many_channels(problem, table)


def too_many_channels(problem: Problem, table) -> str | None:
    """Why the plant's noise has too many channels for the step's quadrature (None: it has
    not)."""
    channels = max(int(np.count_nonzero(st.noise_tensor.any(axis=(0, 1))))
                   for st in problem.stages[:table.n_stages])
    if channels > MAX_CHANNELS:
        return f"more than {MAX_CHANNELS} noise channels"
    return None


class _Sym:
    """Symmetric tensors of one order on R^d, kept on the multisets of indices."""

    def __init__(self, d: int, order: int):
        self.d, self.order = d, order
        self.idx = np.array(list(itertools.combinations_with_replacement(range(d), order)),
                            dtype=np.intp).reshape(-1, order)
        shape = (d,) * order
        full = np.indices(shape).reshape(order, -1).T
        lookup = np.full(d ** order, -1, dtype=np.intp)
        self.rep = np.ravel_multi_index(tuple(self.idx.T), shape)
        lookup[self.rep] = np.arange(len(self.idx))
        self.of_full = lookup[np.ravel_multi_index(tuple(np.sort(full, axis=1).T), shape)]
        self.size = len(self.idx)

    def compress(self, T: np.ndarray) -> np.ndarray:
        return T.ravel()[self.rep]

    def expand(self, s: np.ndarray) -> np.ndarray:
        return s[self.of_full].reshape((self.d,) * self.order)

    def summed(self, weights: np.ndarray) -> np.ndarray:
        """The row ``r`` with ``<weights, T> = r @ compress(T)`` for symmetric T."""
        return np.bincount(self.of_full, weights=weights.ravel(), minlength=self.size)

    def operator(self, nodes) -> np.ndarray:
        """Matrix of ``T -> sum_w w M^{(x)order} T`` on compressed tensors, over `nodes`
        ``(w, M)``."""
        from scipy import sparse
        d, order = self.d, self.order
        collapse = sparse.csr_matrix((np.ones(d ** order), (self.of_full, np.arange(d ** order))),
                                     shape=(self.size, d ** order))
        out = np.zeros((self.size, self.size))
        for start in range(0, self.size, 64):
            I = self.idx[start:start + 64]
            for w, M in nodes:
                R = M[I[:, 0]]
                for a in range(1, order):
                    R = (R[:, :, None] * M[I[:, a]][:, None, :]).reshape(len(I), -1)
                out[start:start + len(I)] += w * (collapse @ R.T).T
        return out


def _mode(T: np.ndarray, M: np.ndarray) -> np.ndarray:
    """``M`` applied along every axis of ``T``."""
    for _ in range(T.ndim):
        T = np.tensordot(T, M, axes=([0], [1]))
    return T


def _step_maps(stage, n: int, m: int, n_latch: int, dt: float):
    """A plant step on ``q = [x; u; v; 1]``: the mean map and the diffusion maps ``N_k``."""
    d = n + m + n_latch + 1
    Ad = expm(augmented_drift(stage, m + 1) * dt)         # on [x; u; 1]
    w_cols = np.r_[0:n + m, d - 1]
    A = np.eye(d)
    A[:n, w_cols] = Ad[:n]
    G = stage.noise_tensor                                 # (n + m, n, mz)
    N = np.zeros((G.shape[2], d, d))
    N[:, :n, :n + m] = np.transpose(G, (2, 1, 0))
    return A, N


def _nodes(A: np.ndarray, N: np.ndarray, dt: float):
    """Gauss-Hermite nodes ``(w, A + sum_k xi_k N_k)`` exact for ``xi ~ N(0, dt I)`` up to
    degree five per channel; only the channels with a nonzero map."""
    live = [k for k in range(len(N)) if N[k].any()]
    x = np.sqrt(3.0 * dt) * np.array([-1.0, 0.0, 1.0])
    w = np.array([1.0, 4.0, 1.0]) / 6.0
    out = []
    for pick in itertools.product(range(3), repeat=len(live)):
        M = A.copy()
        weight = 1.0
        for k, p in zip(live, pick):
            M = M + x[p] * N[k]
            weight *= w[p]
        out.append((weight, M))
    return out


def step_matrix(stage, n: int, m: int, n_latch: int, dt: float, s4: _Sym, s2: _Sym,
                operator=None) -> np.ndarray:
    """The dense map of ``V = [E q^(x)4; E J q q'; E J^2]`` (compressed) over one plant step
    of `dt`. `operator(s, nodes)`: `_Sym.operator`'s matrix (None: `_Sym.operator` itself)."""
    d = n + m + n_latch + 1
    A, N = _step_maps(stage, n, m, n_latch, dt)
    nodes = _nodes(A, N, dt)
    P4 = s4.operator(nodes) if operator is None else operator(s4, nodes)
    P2 = s2.operator(nodes) if operator is None else operator(s2, nodes)
    Lw = running_cost_matrix(stage, n, m, n + m + 1, n)
    w_idx = np.r_[0:n + m, d - 1]
    L = np.zeros((d, d))
    L[np.ix_(w_idx, w_idx)] = Lw
    # E[L(q) q_a q_b] = sum_ij L_ij E q_i q_j q_a q_b, compressed on (a, b).
    CL = np.zeros((s2.size, s4.size))
    for r, (a, b) in enumerate(s2.idx):
        W = np.zeros((d, d, d, d))
        W[:, :, a, b] = L
        CL[r] = s4.summed(W)
    l2 = s2.summed(L)
    l4 = s4.summed(np.multiply.outer(L, L))
    D4, D2 = s4.size, s2.size
    S = np.zeros((D4 + D2 + 1, D4 + D2 + 1))
    S[:D4, :D4] = P4
    S[D4:D4 + D2, :D4] = dt * P2 @ CL
    S[D4:D4 + D2, D4:D4 + D2] = P2
    S[-1, :D4] = dt * dt * l4
    S[-1, D4:D4 + D2] = 2.0 * dt * l2
    S[-1, -1] = 1.0
    return S


class _TickOperator:
    """The linear map of ``V = [E q^(x)4; E J q q'; E J^2]`` (compressed) over one tick of a
    constant stage: `substeps` plant steps (`operator`: as `step_matrix`'s)."""

    def __init__(self, stage, n, m, n_latch, h, substeps, s4: _Sym, s2: _Sym, operator=None):
        S = step_matrix(stage, n, m, n_latch, h / substeps, s4, s2, operator)
        # Sparse: an output index of u, v or 1 takes only inputs that carry it.
        from scipy import sparse
        step = sparse.csr_matrix(S)
        power = None
        for bit in bin(substeps)[2:]:               # binary powering, most significant first
            power = None if power is None else power @ power
            if bit == "1":
                power = step if power is None else power @ step
        self.tick = power.tocsr()

        self.s4, self.s2 = s4, s2

    def apply(self, T4: np.ndarray, P: np.ndarray, J2: float, into: np.ndarray,
              out: np.ndarray):
        """One tick from ``E y^(x)4``, ``E J y y'`` and ``E J^2``: ``q = into @ y`` (the
        command and the passengers), the plant steps, then ``y+ = out @ q``."""
        s4, s2 = self.s4, self.s2
        V = np.concatenate([s4.compress(_mode(T4, into)), s2.compress(into @ P @ into.T), [J2]])
        V = self.tick @ V
        T4 = _mode(s4.expand(V[:s4.size]), out)
        Pq = s2.expand(V[s4.size:s4.size + s2.size])
        return T4, out @ Pq @ out.T, float(V[-1])


def evaluate_tails(problem: Problem, table, *, substeps: int, check=None) -> TailMoments:
    """The exact mean and variance of the cost and the knot moments up to the fourth of
    `table` in the loop with `problem`'s plant advanced by the Monte Carlo scheme with
    `substeps` steps per tick (`harness.montecarlo.simulate`). `check`: the second-moment
    oracle of the same scheme (`evaluate_table(..., propagator="euler", substeps=...)`; computed
    when None; False leaves the check to the caller, `check_second_moments`) whose knot
    covariances and cost the loop must reproduce (`TailsMismatch`).
    Raises ValueError for what `tails_unsupported` names."""
    why = tails_unsupported(problem, table)
    if why is not None:
        raise ValueError(f"evaluate_tails: {why} is not supported")
    n, m, n_latch = table.dims
    h = 1.0 / table.tick_hz
    d_y, d_q = n + n_latch + 1, n + m + n_latch + 1
    s4, s2 = _Sym(d_q, 4), _Sym(d_q, 2)
    x0 = np.asarray(problem.x0, float)
    y0 = np.concatenate([x0, np.zeros(n_latch), [1.0]])
    T4 = np.einsum("i,j,k,l->ijkl", y0, y0, y0, y0)
    P = np.zeros((d_y, d_y))         # E J y y'
    J2 = 0.0
    Tq = np.zeros((d_q, d_y))
    Tq[:n, :n] = np.eye(n)
    Tq[n + m:, n:] = np.eye(n_latch + 1)
    back = np.zeros((d_y, d_q))      # y's components in q
    back[np.arange(d_y), np.r_[0:n, n + m:d_q]] = 1.0
    c = d_y - 1
    means, covs, mu4s = [], [], []
    ops: dict = {}
    loop = compiled_tails(n, m, n_latch, s4, s2, sym=_Sym,       # None: the numpy loop
                          step_matrix=step_matrix)
    for k in range(table.n_stages):
        stage = problem.stages[k]
        if k == 0 or table.stage_n_latch[k] > 0:
            T = _table_latch(table, k, x0, d_y)
            T4 = _mode(T4, T)
            P = T @ P @ T.T
        key = id(stage)
        if key not in ops:
            ops[key] = (stage, _TickOperator(stage, n, m, n_latch, h, substeps, s4, s2)
                        if loop is None else loop.step(stage, h, substeps))
        op = ops[key][1]
        start, stop = int(table.stage_start[k]), int(table.stage_start[k + 1])
        if loop is not None:
            T4, P, J2 = loop.ticks(op, table.K[start:stop], table.L[start:stop],
                                   table.k0[start:stop], T4, P, J2)
        for j in range(start, stop) if loop is None else ():
            Tq[n:n + m, :n] = -table.K[j]
            Tq[n:n + m, n:n + n_latch] = -table.L[j]
            Tq[n:n + m, -1] = -table.k0[j]
            T4, P, J2 = op.apply(T4, P, J2, Tq, back)
        P, J2, mean, cov, mu4 = knot_step(problem.knots[k], T4, P, J2, n)
        means.append(mean)
        covs.append(cov)
        mu4s.append(mu4)
    J = float(P[c, c])
    out = TailMoments(J, J2 - J * J, means, covs, mu4s, substeps)
    _check(problem, table, out, substeps, check)
    return out


def knot_step(knot, T4: np.ndarray, P: np.ndarray, J2: float, n: int):
    """At a knot: the penalty added to the cost (``E J y y'`` and ``E J^2`` move; the state's
    first n components of ``y``, the constant 1 last), and the state's mean, covariance and
    fourth central moments from ``E y^(x)4``. Returns ``(P, J2, mean, cov, mu4)``."""
    d = T4.shape[0]
    c = d - 1
    if knot.penalty is not None:
        C, rho, w = knot.penalty.C, knot.penalty.target, knot.penalty.weight
        Pen = np.zeros((d, d))
        Pen[:n, :n] = w * C.T @ C
        Pen[:n, c] = Pen[c, :n] = -w * C.T @ rho
        Pen[c, c] = w * rho @ rho
        J2 = J2 + 2.0 * np.sum(Pen * P) + np.einsum("ij,kl,ijkl->", Pen, Pen, T4)
        P = P + np.einsum("ij,ijab->ab", Pen, T4)
    mean = T4[:n, c, c, c].copy()
    M2 = T4[:n, :n, c, c]
    cov = M2 - np.outer(mean, mean)
    i = np.arange(n)
    m3, m4 = T4[i, i, i, c], T4[i, i, i, i]
    mu4 = m4 - 4 * m3 * mean + 6 * np.diag(M2) * mean ** 2 - 3 * mean ** 4
    return P, float(J2), mean, 0.5 * (cov + cov.T), np.maximum(mu4, np.diag(cov) ** 2)


def check_second_moments(tails: TailMoments, check) -> None:
    """`TailsMismatch` unless `tails` has the knot means, covariances and cost of `check`
    (the second-moment oracle's `Moments` of the same loop) to rounding."""
    for k, (mean, cov) in enumerate(zip(tails.knot_mean, tails.knot_cov)):
        scale = max(1.0, float(np.max(np.abs(cov + np.outer(mean, mean)))))
        err = max(float(np.max(np.abs(cov - check.knot_cov[k]), initial=0.0)),
                  float(np.max(np.abs(mean - check.knot_mean[k]), initial=0.0)))
        if err > CHECK_RTOL * scale:
            raise TailsMismatch(f"evaluate_tails: knot {k} moments differ from the oracle's "
                                f"by {err:.3g} (scale {scale:.3g})")
    if abs(tails.J - check.J) > CHECK_RTOL * max(1.0, abs(check.J)):
        raise TailsMismatch(f"evaluate_tails: cost {tails.J!r} differs from the oracle's "
                            f"{check.J!r}")


def _check(problem, table, tails: TailMoments, substeps: int, check) -> None:
    if check is False:                 # the caller checks (`check_second_moments`)
        return
    if check is None:
        from stospline.oracle.evaluate import evaluate_table
        check = evaluate_table(problem, table, propagator="euler", substeps=substeps,
                               path=False)
    check_second_moments(tails, check)
