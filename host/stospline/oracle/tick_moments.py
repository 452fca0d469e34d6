"""The building blocks of the moment oracles' tick loops (`oracle.evaluate_table`,
`fault_oracle.evaluate_with_faults`): the `Moments` they return, a knot's terms, the latch
transform, one tick of the plant's moments (exact or the Monte Carlo plant scheme, constant or
time-varying data, with their cached maps) and the per-tick path record."""
from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np
from stospline.expm import expm, require_finite

from stospline.design.moments import (TickPropagator, augmented_drift, euler_tick, exact_tick,
                                      running_cost_matrix)
from stospline.errors import KernelBuildError
from stospline.problem.model import Problem

__all__ = ["Moments"]


@dataclass
class Moments:
    """Exact outcome of a law on a problem.

    ``knot_mean[k]``/``knot_cov[k]`` are the state's mean and covariance at knot k (end of
    stage k); ``knot_constraint[k]`` is ``E{C2 x}`` there (empty when unconstrained).
    ``path_t``/``path_mean`` sample the mean trajectory.
    """
    J: float
    knot_mean: list[np.ndarray]
    knot_cov: list[np.ndarray]
    knot_constraint: list[np.ndarray]
    path_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    path_mean: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    path_var: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # state variances
    # The command's mean and variance over each tick (ticks, m), with path=True.
    path_u_mean: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    path_u_var: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    # With evaluate_table(output=Cy): the mean (ticks + 1, p) and covariance (ticks + 1, p, p)
    # of Cy x at every tick.
    path_y_mean: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    path_y_cov: np.ndarray = field(default_factory=lambda: np.zeros((0, 0, 0)))


def _knot_terms(problem: Problem, k: int, M: np.ndarray, n: int):
    """Penalty expectation, mean, covariance and constrained output at knot k from E yy'."""
    mean = M[:n, -1].copy()
    Mxx = M[:n, :n]
    cov = Mxx - np.outer(mean, mean)
    knot = problem.knots[k]
    pen = 0.0
    if knot.penalty is not None:
        C, rho, w = knot.penalty.C, knot.penalty.target, knot.penalty.weight
        pen = w * (np.trace(C @ Mxx @ C.T) - 2 * rho @ C @ mean + rho @ rho)
    con = knot.constraint.C @ mean if knot.constraint is not None else np.zeros(0)
    return pen, mean, 0.5 * (cov + cov.T), con


def _latch_transform(n: int, n_latch: int, Lam: np.ndarray, lam0: np.ndarray, d_old: int) -> np.ndarray:
    """Map ``y_old = [x; v_old; 1]`` to ``[x; Lam x + lam0; 1]``."""
    T = np.zeros((n + n_latch + 1, d_old))
    T[:n, :n] = np.eye(n)
    T[n:n + n_latch, :n] = Lam
    T[n:n + n_latch, -1] = lam0
    T[-1, -1] = 1.0
    return T


def _table_latch(table, k: int, x0: np.ndarray, d_y: int) -> np.ndarray:
    """The latch transform (`_latch_transform`) of a table's stage k on ``y = [x; v; 1]``:
    its latch map, or at the first stage of a band table the target the firmware solves the
    band dual for from the (deterministic) start state, in float32 for a quantized table."""
    n, _, n_latch = table.dims
    Lam = table.Lambda[k].astype(float)
    lam0 = table.lambda0[k].astype(float)
    if k == 0 and table.band_qp is not None:
        from stospline.oracle.band_latch import target_latch
        Lam = np.zeros_like(Lam)
        lam0 = np.zeros(n_latch)
        lam0[:table.band_qp.q] = target_latch(table.band_qp, x0,
                                              float32=table.K.dtype == np.float32)
    return _latch_transform(n, n_latch, Lam, lam0, d_y)


def _tick_varying(stage, Mw: np.ndarray, t0: float, h: float, n: int, m: int,
                  rtol: float = 1e-12, atol: float = 1e-15):
    """One tick of time-varying stage data for ``w = [x; u; 1]`` (u held): integrate the
    moment ODE, the expected running cost and the mean transition ``[Phi, Gamma]`` (x+ =
    Phi x + Gamma u in expectation) with DOP853. Independent of the designer's tick maps."""
    d = n + m + 1

    def rhs(t, y):
        sd = stage.at(t)
        M = y[:d * d].reshape(d, d)
        Ah = np.zeros((d, d))
        Ah[:n, :n], Ah[:n, n:n + m] = sd.A, sd.B
        if sd.f is not None:
            Ah[:n, -1] = sd.f
        AM = Ah @ M
        G = sd.noise_tensor                                  # multipliers [x; u]
        dM = AM + AM.T
        dM[:n, :n] += np.einsum("ij,iak,jbk->ab", M[:n + m, :n + m], G, G)
        Lb = running_cost_matrix(sd, n, m, d, n)
        F = y[d * d + 1:].reshape(n, d)
        dF = sd.A @ F                                        # d/dt of E x = F [x0; u; 1]
        dF[:, n:n + m] += sd.B
        if sd.f is not None:
            dF[:, -1] += sd.f
        return np.concatenate([dM.ravel(), [np.sum(Lb * M)], dF.ravel()])

    F0 = np.hstack([np.eye(n), np.zeros((n, m + 1))])
    from scipy.integrate import solve_ivp   # lazy: a slow import the CLI rarely needs
    res = solve_ivp(rhs, (t0, t0 + h),
                    require_finite(np.concatenate([Mw.ravel(), [0.0], F0.ravel()])),
                    method="DOP853", rtol=rtol, atol=atol)
    y = res.y[:, -1]
    M = y[:d * d].reshape(d, d)
    return 0.5 * (M + M.T), float(y[d * d]), y[d * d + 1:].reshape(n, d)


def _plant_tick(stage, maps, Mw: np.ndarray, t: float, h: float, n: int, m: int):
    """The moments of ``w = [x; u; 1]`` after one tick from `Mw` (u held), the tick's expected
    running cost, and the mean map ``[Ad, Bd]``: from the stage's tick `maps` (`_tick_maps`),
    or with None (time-varying data) by integrating from time `t`."""
    if maps is None:
        return _tick_varying(stage, Mw, t, h, n, m)
    prop, cost_row, Fmean = maps
    d = n + m + 1
    return (prop.Phi @ Mw.ravel()).reshape(d, d), float(cost_row @ Mw.ravel()), Fmean


class _PathRecord:
    """Mean and variance of the state at every tick and of the command over each (kept
    only when `on`); with an output matrix `Cy`, the mean and covariance of ``Cy x`` at every
    tick too."""

    def __init__(self, x0: np.ndarray, on: bool, Cy: np.ndarray | None = None):
        self.on = on
        self.x_mean, self.x_var = ([x0.copy()], [np.zeros(len(x0))]) if on else ([], [])
        self.u_mean, self.u_var = [], []
        self.Cy = Cy
        if Cy is not None:
            self.y_mean, self.y_cov = [Cy @ x0], [np.zeros((len(Cy), len(Cy)))]

    def command(self, Mw: np.ndarray, n: int, m: int) -> None:
        if self.on:
            mu = Mw[n:n + m, -1]
            self.u_mean.append(mu.copy())
            self.u_var.append(np.diag(Mw[n:n + m, n:n + m]) - mu ** 2)

    def extend(self, x_mean, x_var, u_mean, u_var) -> None:
        """Many ticks at once (None: not recorded)."""
        if self.on:
            self.x_mean.extend(x_mean); self.x_var.extend(x_var)
            self.u_mean.extend(u_mean); self.u_var.extend(u_var)

    def outputs(self, xx: np.ndarray) -> None:
        """The output's moments after many ticks from the state's (`kernel.oracle_stage_ticks`'
        ``xx``: rows ``[E x_a x_b (b < n), E x_a]``), as `state` forms them tick by tick."""
        n = xx.shape[1]
        mu = xx[:, :, n]
        cov = xx[:, :, :n] - mu[:, :, None] * mu[:, None, :]
        yc = self.Cy @ cov @ self.Cy.T
        self.y_mean.extend(mu @ self.Cy.T)
        self.y_cov.extend(0.5 * (yc + np.swapaxes(yc, 1, 2)))

    def state(self, M: np.ndarray, n: int) -> None:
        if self.on:
            mu = M[:n, -1]
            self.x_mean.append(mu.copy())
            self.x_var.append(np.diag(M[:n, :n]) - mu ** 2)
        if self.Cy is not None:
            mu = M[:n, -1]
            cov = M[:n, :n] - np.outer(mu, mu)
            ym = self.Cy @ mu
            yc = self.Cy @ cov @ self.Cy.T
            self.y_mean.append(ym)
            self.y_cov.append(0.5 * (yc + yc.T))

    def moments(self, J, means, covs, cons, t0: float, h: float, ticks: int) -> "Moments":
        path_t = t0 + np.arange(ticks + 1) * h if self.on else np.zeros(0)
        var = np.maximum(np.array(self.x_var), 0.0) if self.on else np.zeros((0, 0))
        out = Moments(float(J), means, covs, cons, path_t, np.array(self.x_mean), var,
                      np.array(self.u_mean), np.maximum(np.array(self.u_var), 0.0))
        if self.Cy is not None:
            out.path_y_mean, out.path_y_cov = np.array(self.y_mean), np.array(self.y_cov)
        return out


# Tick maps of recent stages: the design's law and its float32 table are evaluated on the
# same stages, and consecutive stages often share one Stage object. Keyed by the object's id;
# the entry holds the stage itself, so the id cannot be reused while it is cached.
_MAPS: dict = {}
_MAPS_MAX = 16


def _tick_maps(stage, n: int, m: int, h: float, propagator: str, substeps: int):
    """``(prop, cost_row, Fmean)`` of one tick of a time-invariant stage (cached)."""
    return _tick_entry(stage, n, m, h, propagator, substeps)[1]


def _tick_entry(stage, n: int, m: int, h: float, propagator: str, substeps: int):
    """The cache entry ``(stage, maps, extra)`` of `_tick_maps`: held by the caller, so another
    thread clearing the cache cannot take it away."""
    key = (id(stage), m, h, propagator, substeps)
    hit = _MAPS.get(key)
    if hit is not None and hit[0] is stage:
        return hit
    if propagator == "exact" and not stage.noise_tensor.any():
        prop, cost_row = _noise_free_tick(stage, n, m, h)
    else:
        prop = (exact_tick(stage, m + 1, h) if propagator == "exact"
                else euler_tick(stage, m + 1, h, substeps))
        cost_row = running_cost_matrix(stage, n, m, n + m + 1, n).ravel() @ prop.Psi
    # Mean map of one tick: E x+ = Ad x + Bd u + fd = Fmean [x; u; 1] (exact for both
    # propagators).
    Fmean = expm(augmented_drift(stage, m + 1) * h)[:n]
    if len(_MAPS) >= _MAPS_MAX:
        _MAPS.clear()
    entry = _MAPS[key] = (stage, (prop, cost_row, Fmean), {})
    return entry


class FactoredTick:
    """The moment map of a noise-free tick, ``M+ = F M F'`` with ``F = exp(Ahat h)``: `factor`
    is F; `Phi`, the same map on ``vec M`` (``F ⊗ F``, d² x d²), is formed on first use only
    (the numpy loop's reference product); `Psi` is not formed (None)."""

    Psi = None

    def __init__(self, factor: np.ndarray):
        self.factor = factor
        self._kron = None

    @property
    def Phi(self) -> np.ndarray:
        if self._kron is None:
            self._kron = np.kron(self.factor, self.factor)
        return self._kron


def _noise_free_tick(stage, n: int, m: int, h: float):
    """`exact_tick`'s moment map and cost row for a stage without noise, from d-square
    exponentials instead of a 2d²-square one: M+ = Phi M Phi' with ``Phi = exp(Ahat h)``, so
    the map is ``Phi ⊗ Phi`` (`FactoredTick`), and the cost ``∫ <Lb, Phi(s) M Phi(s)'> ds =
    <C, M>`` with ``C = ∫ Phi(s)' Lb Phi(s) ds`` from Van Loan's 2d-square exponential."""
    d = n + m + 1
    Ahat = augmented_drift(stage, m + 1)
    Lb = running_cost_matrix(stage, n, m, d, n)
    big = np.zeros((2 * d, 2 * d))
    big[:d, :d], big[:d, d:], big[d:, d:] = -Ahat.T * h, Lb * h, Ahat * h
    E = expm(big)
    Phi = E[d:, d:]
    return FactoredTick(Phi), (Phi.T @ E[:d, d:]).ravel()


def _euler_varying_maps(stage, n: int, m: int, t0: float, h: float, substeps: int):
    """``(prop, cost_row, Fmean)`` of the Monte Carlo plant scheme over the tick ``[t0, t0 +
    h]`` of a stage whose data vary: as the harness does (`montecarlo._plant_tick`), each of
    the `substeps` steps takes the data at its midpoint; the step maps are composed."""
    d = n + m + 1
    dt = h / substeps
    Phi = np.eye(d * d)
    Psi = np.zeros((d * d, d * d))
    cost_row = np.zeros(d * d)
    F = np.eye(d)
    for i in range(substeps):
        sd = stage.at(t0 + (i + 0.5) * dt)
        step = euler_tick(sd, m + 1, dt, 1)
        cost_row += (running_cost_matrix(sd, n, m, d, n).ravel() @ step.Psi) @ Phi
        Psi += step.Psi @ Phi
        Phi = step.Phi @ Phi
        F = expm(augmented_drift(sd, m + 1) * dt) @ F
    return TickPropagator(Phi, Psi), cost_row, F[:n]


def _stage_maps(stage, varying: bool, n: int, m: int, t0: float, h: float, propagator: str,
                substeps: int):
    """The maps `_plant_tick` needs for the tick starting at `t0`: cached constant-stage maps,
    the plant scheme's composed maps of a varying stage ("euler"), or None (a varying stage's
    exact moments, integrated by `_tick_varying`)."""
    if not varying:
        return _tick_maps(stage, n, m, h, propagator, substeps)
    if propagator == "euler":
        return _euler_varying_maps(stage, n, m, t0, h, substeps)
    return None


def _w_map(n: int, m: int, d: int, xs) -> np.ndarray:
    """The map ``z -> w = [x; u; 1]`` of a loop state `z` (`d` entries, the constant last;
    the state at `xs`), with its `m` input rows left to fill."""
    Tw = np.zeros((n + m + 1, d))
    Tw[:n, xs] = np.eye(n)
    Tw[-1, -1] = 1.0
    return Tw


class _StagePlant:
    """One stage's plant over its ticks (`_plant_tick`): its maps computed at the first tick
    for constant data, at every tick for time-varying data (`_stage_maps`)."""

    def __init__(self, stage, n: int, m: int, t0: float, h: float, propagator: str,
                 substeps: int):
        self.stage, self.n, self.m, self.t0, self.h = stage, n, m, t0, h
        self.propagator, self.substeps = propagator, substeps
        self.varying = stage.varying is not None
        self.maps = None

    def tick(self, Mw: np.ndarray, j: int):
        """`_plant_tick` of tick `j`: the moments of ``w`` after it, its cost and mean map."""
        t = self.t0 + j * self.h
        if self.maps is None or self.varying:
            self.maps = _stage_maps(self.stage, self.varying, self.n, self.m, t, self.h,
                                    self.propagator, self.substeps)
        return _plant_tick(self.stage, self.maps, Mw, t, self.h, self.n, self.m)


def _packed_maps(stage, n: int, m: int, h: float, propagator: str, substeps: int):
    """`kernel.pack_oracle_maps` of `_tick_maps` (cached alongside it)."""
    _, (prop, cost_row, _), extra = _tick_entry(stage, n, m, h, propagator, substeps)
    if "packed" not in extra:
        from stospline.oracle.kernel import pack_oracle_maps
        extra["packed"] = pack_oracle_maps(prop.Phi, cost_row, n)
    return extra["packed"]


def _factored_maps(stage, n: int, m: int, h: float, propagator: str, substeps: int):
    """``(F, cost)`` of a noise-free stage's exact tick for `kernel.factored_stage_ticks`
    (cached alongside `_tick_maps`), or None when the stage's map is not factored."""
    _, (prop, cost_row, _), extra = _tick_entry(stage, n, m, h, propagator, substeps)
    if not isinstance(prop, FactoredTick):
        return None
    if "factored" not in extra:
        from stospline.oracle.kernel import pack_cost
        extra["factored"] = (np.ascontiguousarray(prop.factor), pack_cost(cost_row))
    return extra["factored"]


def _has_drift(problem: Problem) -> bool:
    return any(st.f is not None for st in problem.stages)


def _c_kernel():
    """`kernel.oracle_stage_ticks`, or None: ``STOSPLINE_ORACLE_KERNEL=numpy`` asks for the
    numpy loop (the reference), and so does a host where the kernel cannot be built."""
    from stospline.oracle.kernel import load_kernel, oracle_stage_ticks
    return _compiled(load_kernel, oracle_stage_ticks)


def _factored_kernel():
    """`kernel.factored_stage_ticks`, or None (as `_c_kernel`)."""
    from stospline.oracle.kernel import factored_stage_ticks, load_kernel
    return _compiled(load_kernel, factored_stage_ticks)


def _compiled(load, loop):
    """`loop`, or None when ``STOSPLINE_ORACLE_KERNEL=numpy`` or `load` cannot build it."""
    if os.environ.get("STOSPLINE_ORACLE_KERNEL", "c") == "numpy":
        return None
    from stospline.errors import KernelBuildError
    try:
        load()
    except KernelBuildError:
        return None
    return loop
