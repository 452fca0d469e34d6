"""The filter's fixed-point (Q15/Q31) tables, their bit-exact tick and its error bound.

A Q15/Q31 estimator controller (``stsp_est_step`` in a fixed-point build,
firmware/include/stospline/stsp_estimator.h) runs the law of a `FixedPointTable` on the
estimate ``x̂``, which it keeps in the law's state format ``x̂ = x̂_q 2^(x_exp - F)``. The reading
is ``y = y_q 2^(y_exp - F)`` and the innovation ``e = y - C x̂`` is held as
``e_q 2^(e_exp - F)``. Every filter row (innovation i, update r, prediction r) is one sum in a
64-bit accumulator::

    acc = c_q 2^F + p z_q + sum_j G_q[j] z_q[j],    out_q = sat(floor(acc / 2^k + 1/2))

with ``G_q = rhu(G 2^(z_exp[j] - out_exp + k))`` the row's stored entries, ``c_q =
rhu(c 2^(k - out_exp))`` its constant (the prediction's fd) and ``p = 2^(z_exp - out_exp + k)``
the exact coefficient of its pass-through input: the reading y_q in the innovation, ``x̂_q``
itself in the update and in the prediction, which stores ``[Ad - I | Bd | fd]`` (the identity
is exact, and the small increments keep their digits). The row's shift ``k`` (1 .. 61 - F,
one per row over every map or sample) is the largest that keeps every stored entry in
``[-2^F, 2^F - 1]`` and the row's absolute sum ``|c_q| + p + sum |G_q|`` at most
``2^(61 - F)``: then ``|acc| <= 2^61`` for any inputs in their Q ranges, nothing overflows, and
the rounding is exact integer arithmetic. ``sat`` saturates to ``[-2^F, 2^F - 1]`` (the
firmware reports it, STSP_WARN_STATE_CLAMPED).

Scales (`quantize_estimator`): ``x_exp``, ``u_exp`` are the law table's (whose state ranges must
cover the estimate: `estimator_state_range`). ``y_exp[i] = ceil(log2(max_t |E y_i| + sigmas
std y_i))`` over the sampling ticks, ``e_exp[i] = ceil(log2(sigmas max_t std e_i))`` (the
innovation has mean zero), at most ``y_exp[i]``, raised until its row fits the accumulator;
both from the exact moments of the loop (`evaluate_estimator`).

Error bound (`error_bound`): against the double-precision loop (the double LMMSE gains, the
plant's exact mean maps, the double law) fed the same readings, per tick, on ``x̂+`` and on the
command, for readings and states that stay in their Q ranges (no saturation). The error
``xi = [x̂_q - x̂_d; v_q - v_d]`` obeys the linear recursion ``xi' = M_j xi + N_j eta_j`` with the
closed filter transition ``(Ad - Bd K)(I - F C)`` in M_j and a local error ``eta_j`` of each tick
(rounding of each sum, the stored entries' actual errors times the Q ranges of their inputs,
the law's and the latch's bounds of `stospline.table.qformat`). Over blocks of `block` ticks
it is bounded with the exact products of the transitions: ``|xi_J| <= |Phi(J, B)| b_B +
sum_{B <= j < J} |Phi(J, j+1) N_j| eta_j`` (B the block's first tick, b_B the bound there).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from stospline.estimator.ctable import (EstimatorTable, flushed, stage_maps, table_arrays,
                                        table_crc32, table_source)
from stospline.firmware_interface import FRAC_BITS, SCALAR_KIND
from stospline.limits import Q_EXP_MAX
from stospline.table.qformat import DEFAULT_SIGMAS, FixedPointTable, scaled_entries

__all__ = ["QEstimatorTable", "quantize_estimator", "estimator_state_range",
           "QEstimatorSpec", "estimator_q_crc32", "estimator_q_c", "error_bound",
           "double_loop", "measured_error", "ACC_BITS"]

ACC_BITS = 61            # |acc| <= 2^61 for inputs in their Q ranges (stsp_estimator.c)


def _rhu(y) -> np.ndarray:
    return np.floor(np.asarray(y, dtype=float) + 0.5).astype(np.int64)


@dataclass(frozen=True)
class QEstimatorTable(EstimatorTable):
    """What a fixed-point `stsp_est_table_t` holds (integers in int64 arrays), with the double
    filter it came from. ``C`` is ``-C`` scaled (the innovation is a plain sum), ``model`` holds
    ``[Ad - I | Bd | fd]`` scaled, ``shift`` the rows' shifts k ``[innovation rows (ny), update
    rows (nx), prediction rows (nx)]``; the law's ``x_exp``, ``u_exp``."""
    arith: str = "q15"
    y_exp: np.ndarray = None
    e_exp: np.ndarray = None
    shift: np.ndarray = None
    x_exp: np.ndarray = None
    u_exp: np.ndarray = None
    # The double filter: model (maps, nx, nx+nu+1), C (ny, nx), gain (samples, nx, ny), x0.
    double: dict = field(repr=False, default_factory=dict)
    y_range: np.ndarray = field(repr=False, default=None)
    e_range: np.ndarray = field(repr=False, default=None)

    @property
    def frac_bits(self) -> int:
        return FRAC_BITS[self.arith]

    def lsb(self, exps) -> np.ndarray:
        return np.ldexp(1.0, np.asarray(exps, int) - self.frac_bits)

    def real_entries(self) -> dict:
        """The stored entries as the real coefficients they stand for (same shapes as
        `double`): what the firmware's sums multiply by."""
        F = self.frac_bits
        n, m, p = self.nx, self.nu, self.ny
        k_e, k_g, k_p = (self.shift[:p].astype(int), self.shift[p:p + n].astype(int),
                         self.shift[p + n:].astype(int))
        xe, ue, ee = self.x_exp.astype(int), self.u_exp.astype(int), self.e_exp.astype(int)
        C = -self.C * np.ldexp(1.0, ee[:, None] - xe[None, :] - k_e[:, None])
        G = self.gain * np.ldexp(1.0, xe[:, None] - ee[None, :] - k_g[:, None])
        zexp = np.concatenate([xe, ue])
        A = self.model[:, :, :n + m] * np.ldexp(1.0, xe[:, None] - zexp[None, :] - k_p[:, None])
        A[:, :, :n] += np.eye(n)
        c = self.model[:, :, n + m] * np.ldexp(1.0, xe - k_p)
        return {"C": C, "gain": G, "model": np.concatenate([A, c[:, :, None]], axis=2),
                "xhat0": self.xhat0 * np.ldexp(1.0, xe - F)}

    def filter_values(self) -> tuple[np.ndarray, np.ndarray]:
        """``(gain, model)`` as real numbers (`real_entries`): `per_tick` then gives
        `evaluate_estimator` the filter as stored."""
        re = self.real_entries()
        return re["gain"], re["model"]

    def summary(self) -> dict:
        return {"arith": self.arith, "y_exp": self.y_exp.tolist(),
                "e_exp": self.e_exp.tolist(), "shift": self.shift.tolist(),
                "y_range_predicted": [float(r) for r in self.y_range],
                "e_range_predicted": [float(r) for r in self.e_range]}


def estimator_state_range(problem, table, loop, *, sigmas: float = DEFAULT_SIGMAS
                          ) -> np.ndarray:
    """State ranges that cover the true state and the estimate of the loop `loop`
    (`evaluate_estimator(..., path=True)`): ``max_t |E x| + sigmas std x`` and
    ``sqrt(1 + sigmas^2) max_t sqrt(E x̂^2)``, the larger."""
    from stospline.table.qformat import scalable_ranges
    mom = loop.moments
    rx = np.max(np.abs(mom.path_mean) + sigmas * np.sqrt(np.maximum(mom.path_var, 0.0)), axis=0)
    mean = mom.path_mean[:len(loop.estimate_ms)]      # E x̂ = E x (docs/theory/estimator.md)
    rh = np.max(np.abs(mean) + sigmas * np.sqrt(np.maximum(loop.estimate_ms - mean ** 2, 0.0)),
                axis=0)
    return scalable_ranges(np.maximum(rx, rh))


def _row_shift(G, c, p_off: int, F: int):
    """The largest shift k (1 .. 61 - F) of a row family G (rows, cols) and constants c (rows,)
    given at k = 0, with a pass-through coefficient 2^(k + p_off), that fits (module
    docstring): ``(k, G_q, c_q)``, or None when no shift does."""
    qmax, limit = (1 << F) - 1, 1 << (ACC_BITS - F)
    for k in range(ACC_BITS - F, 0, -1):
        Gq, cq = _rhu(np.ldexp(G, k)), _rhu(np.ldexp(c, k))
        if max(int(np.abs(Gq).max(initial=0)), int(np.abs(cq).max(initial=0))) > qmax:
            continue
        if not 0 <= k + p_off <= ACC_BITS - F:
            continue
        total = np.abs(Gq).sum(axis=-1) + np.abs(cq) + (1 << (k + p_off))
        if int(np.max(total, initial=0)) <= limit:
            return k, Gq, cq
    return None


def _exp_of(r: np.ndarray) -> np.ndarray:
    return np.ceil(np.log2(np.where(r > 0, r, 1.0))).astype(int)


def quantize_estimator(problem, ft: FixedPointTable, loop, *, sigmas: float = DEFAULT_SIGMAS
                       ) -> QEstimatorTable:
    """The Q15/Q31 filter tables for the law `ft` (whose ``source`` is the double table `loop`
    was evaluated on, `evaluate_estimator(problem, ft.source, path=True)`).

    Raises ValueError when a row fits no shift (gains too large for the format) or an
    exponent is beyond +-Q_EXP_MAX."""
    meas = problem.measurement
    F = ft.frac_bits
    n, m, _ = ft.dims
    p = meas.p
    xe, ue = ft.x_exp.astype(int), ft.u_exp.astype(int)
    starts, maps = stage_maps(problem, ft.source, loop)
    maps = flushed(maps)
    gains = flushed(loop.gain[::meas.every])
    C = np.asarray(meas.C, float)
    sampled = np.arange(ft.n_ticks) % meas.every == 0
    y_mean = loop.moments.path_mean[:ft.n_ticks][sampled] @ C.T
    y_ms = np.diagonal(loop.output_cov[sampled], axis1=1, axis2=2)
    y_range = np.max(np.abs(y_mean) + sigmas * np.sqrt(np.maximum(y_ms - y_mean ** 2, 0.0)),
                     axis=0)
    e_range = sigmas * np.sqrt(np.maximum(np.diagonal(loop.innovation_cov[sampled], axis1=1,
                                                      axis2=2), 0.0).max(axis=0))
    y_exp = _exp_of(y_range)
    e_exp = np.minimum(_exp_of(e_range), y_exp)
    shift = np.zeros(p + 2 * n, int)
    Cq = np.zeros((p, n), np.int64)
    for i in range(p):
        while True:
            G = -C[i] * np.ldexp(1.0, xe - e_exp[i])
            got = _row_shift(G[None, :], np.zeros(1), y_exp[i] - e_exp[i], F)
            if got is not None:
                break
            if e_exp[i] >= y_exp[i]:
                raise ValueError(f"measurement.C row {i} fits no fixed-point innovation scale")
            e_exp[i] += 1
        shift[i], Cq[i] = got[0], got[1][0]
    Gq = np.zeros((len(gains), n, p), np.int64)
    for r in range(n):
        got = _row_shift(gains[:, r, :] * np.ldexp(1.0, e_exp - xe[r]),
                         np.zeros(len(gains)), 0, F)
        if got is None:
            raise ValueError(f"the filter gains of state {r} fit no {ft.arith} scale")
        shift[p + r], Gq[:, r, :] = got[0], got[1]
    Mq = np.zeros(maps.shape, np.int64)
    zexp = np.concatenate([xe, ue])
    increment = maps[:, :, :n + m] - np.eye(n, n + m)[None]     # x̂ passes through exactly
    for r in range(n):
        got = _row_shift(increment[:, r, :] * np.ldexp(1.0, zexp - xe[r]),
                         maps[:, r, n + m] * np.ldexp(1.0, -xe[r]), 0, F)
        if got is None:
            raise ValueError(f"the predictor row of state {r} fits no {ft.arith} scale")
        shift[p + n + r], Mq[:, r, :n + m], Mq[:, r, n + m] = got
    for what, e in (("reading", y_exp), ("innovation", e_exp)):
        if np.abs(e).max() > Q_EXP_MAX:
            raise ValueError(f"a {what} scale exponent would be beyond +-{Q_EXP_MAX}")
    x0q = np.clip(_rhu(np.asarray(problem.x0, float) * np.ldexp(1.0, F - xe)),
                  -(1 << F), (1 << F) - 1)
    return QEstimatorTable(
        n, m, p, ft.n_ticks, meas.every, np.asarray(ft.stage_start, np.uint32), starts, Mq, Cq,
        Gq, x0q, ft.problem_sha256, ft.arith, y_exp.astype(np.int8), e_exp.astype(np.int8),
        shift.astype(np.uint8), ft.x_exp, ft.u_exp,
        {"model": maps, "C": C, "gain": gains, "xhat0": np.asarray(problem.x0, float)},
        y_range, e_range)


def _round_shift(acc: np.ndarray, k) -> np.ndarray:
    """floor(acc / 2^k + 1/2) for k >= 1 (numpy's >> on int64 is a floor)."""
    k = np.asarray(k, np.int64)
    return (acc + (np.int64(1) << (k - 1))) >> k


class QEstimatorSpec:
    """``step(tick, Yq) -> (Uq, clamped)`` for `paths` fixed-point instances of the law `ft`
    on the filter `qt`, bit-exact with ``stsp_est_step`` (Q15/Q31 builds). Yq (paths, ny)
    integers, or None without a reading; ticks in order or skipped ahead. ``clamped`` (paths,)
    is whether the innovation or the estimate saturated during the step."""

    def __init__(self, ft: FixedPointTable, qt: QEstimatorTable, paths: int):
        self.ft, self.qt = ft, qt
        n, m, nl = ft.dims
        self.F = ft.frac_bits
        self.lo, self.hi = -(1 << self.F), (1 << self.F) - 1
        self.xhat = np.tile(qt.xhat0.astype(np.int64), (paths, 1))
        self.v = np.zeros((paths, nl), np.int64)
        self.u_last = np.tile(ft.u_hold.astype(np.int64), (paths, 1))
        self.next = 0
        self.map_of = np.empty(qt.n_ticks, int)
        for s in range(qt.n_stages):
            a, b = int(qt.stage_start[s]), int(qt.stage_start[s + 1])
            k0, k1 = int(qt.model_start[s]), int(qt.model_start[s + 1])
            self.map_of[a:b] = k0 if k1 - k0 == 1 else np.arange(k0, k1)

    def _sat(self, q, clamped):
        clamped |= np.any((q < self.lo) | (q > self.hi), axis=1)
        return np.clip(q, self.lo, self.hi)

    def _predict(self, j, X, U, clamped):
        qt, F = self.qt, self.F
        n = qt.nx
        P = qt.model[self.map_of[j]]
        k = qt.shift[qt.ny + n:].astype(np.int64)
        acc = (X << k) + (P[None, :, -1] << F) + X @ P[:, :n].T + U @ P[:, n:-1].T
        return self._sat(_round_shift(acc, k), clamped)

    def step(self, j: int, Yq):
        ft, qt, F = self.ft, self.qt, self.F
        n, m, nl = ft.dims
        p = qt.ny
        clamped = np.zeros(self.xhat.shape[0], bool)
        X = self.xhat.copy()
        for missed in range(self.next, j):
            X = self._predict(missed, X, self.u_last, clamped)
        if j % qt.every == 0 and Yq is not None:
            k = qt.shift[:p].astype(np.int64)
            up = k + qt.y_exp.astype(np.int64) - qt.e_exp.astype(np.int64)
            acc = np.asarray(Yq, np.int64) * (np.int64(1) << up) + X @ qt.C.T
            E = self._sat(_round_shift(acc, k), clamped)
            k = qt.shift[p:p + n].astype(np.int64)
            acc = X * (np.int64(1) << k) + E @ qt.gain[j // qt.every].T
            X = self._sat(_round_shift(acc, k), clamped)
        k = int(ft.stage_of_tick(j))
        if j == int(ft.stage_start[k]) and (k == 0 or ft.stage_n_latch[k] > 0):
            from stospline.table.qformat import latch_q
            self.v = latch_q(ft, np.full(X.shape[0], k), X)
        from stospline.table.qformat import law_q
        U = law_q(ft, np.full(X.shape[0], j), X, self.v)
        U = np.clip(U, ft.u_min.astype(np.int64), ft.u_max.astype(np.int64))
        self.xhat = self._predict(j, X, U, clamped)
        self.xhat_plus = X
        self.u_last, self.next = U, j + 1
        return U, clamped


def double_loop(ft: FixedPointTable, qt: QEstimatorTable, Y: np.ndarray):
    """The double-precision estimator loop (double gains, maps, law; no limits) fed the
    readings Y (ticks, paths, ny; rows of non-sampling ticks unused): ``(xhat_plus (ticks,
    paths, nx), u (ticks, paths, nu))``."""
    src = ft.source
    d = qt.double
    n, m, nl = ft.dims
    T, paths = Y.shape[0], Y.shape[1]
    x = np.tile(d["xhat0"], (paths, 1))
    v = np.zeros((paths, nl))
    xs, us = np.empty((T, paths, n)), np.empty((T, paths, m))
    spec = QEstimatorSpec.__new__(QEstimatorSpec)
    QEstimatorSpec.__init__(spec, ft, qt, 1)
    for j in range(T):
        if j % qt.every == 0:
            x = x + (Y[j] - x @ d["C"].T) @ d["gain"][j // qt.every].T
        k = int(ft.stage_of_tick(j))
        if j == int(ft.stage_start[k]) and (k == 0 or ft.stage_n_latch[k] > 0):
            v = x @ np.asarray(src.Lambda[k], float).T + np.asarray(src.lambda0[k], float)
            v[:, int(ft.stage_n_latch[k]):] = 0.0
        u = -(x @ np.asarray(src.K[j], float).T + v @ np.asarray(src.L[j], float).T
              + np.asarray(src.k0[j], float))
        xs[j], us[j] = x, u
        P = d["model"][spec.map_of[j]]
        x = x @ P[:, :n].T + u @ P[:, n:-1].T + P[:, -1]
    return xs, us


def measured_error(ft: FixedPointTable, qt: QEstimatorTable, innovation_cov, ticks: int, *,
                   paths: int = 16, seed: int = 7) -> tuple[np.ndarray, np.ndarray, bool]:
    """``(x_err (ticks, nx), u_err (ticks, nu), clamped)``: per tick, the largest
    ``|x̂+_q - x̂+_d|`` and ``|u_q - u_d|`` over `paths` paths of readings drawn around the Q
    loop's prediction with the innovation covariance (`EstimatorLoop.innovation_cov`),
    quantized to y_q and fed to both loops (`double_loop`); ``clamped`` whether anything
    saturated (then the bound does not apply)."""
    rng = np.random.default_rng(seed)
    spec = QEstimatorSpec(ft, qt, paths)
    ylsb, xlsb, ulsb = qt.lsb(qt.y_exp), qt.lsb(ft.x_exp), qt.lsb(ft.u_exp)
    Y = np.zeros((ticks, paths, qt.ny))
    xq, uq = np.zeros((ticks, paths, qt.nx)), np.zeros((ticks, paths, qt.nu))
    clamped = False
    for j in range(ticks):
        Yq = None
        if j % qt.every == 0:
            chol = np.linalg.cholesky(innovation_cov[j])
            y = (spec.xhat * xlsb) @ qt.double["C"].T + rng.standard_normal((paths, qt.ny)) @ chol.T
            Yq = np.floor(y / ylsb + 0.5).astype(np.int64)
            Y[j] = Yq * ylsb
        U, cl = spec.step(j, Yq)
        clamped |= bool(cl.any())
        xq[j], uq[j] = spec.xhat_plus * xlsb, U * ulsb
    xs, us = double_loop(ft, qt, Y)
    return np.abs(xq - xs).max(axis=1), np.abs(uq - us).max(axis=1), clamped


def error_bound(ft: FixedPointTable, qt: QEstimatorTable, *, ticks: int | None = None,
                block: int = 200) -> tuple[np.ndarray, np.ndarray]:
    """``(xhat_bound (ticks, nx), u_bound (ticks, nu))``: bounds on ``|x̂+_q - x̂+_d|`` and
    ``|u_q - u_d|`` in real units at each tick (module docstring), for every reading sequence
    that keeps the innovation, the estimate and the command in their Q ranges, ticks stepped in
    order with a reading at every sampling tick. `ticks`: only the first ones (the bound is
    causal). Raises ValueError for a table with actuator limits (not covered)."""
    if ft.limited:
        raise ValueError("error_bound: a table with actuator limits is not covered")
    F = ft.frac_bits
    src, d = ft.source, qt.double
    n, m, nl = ft.dims
    p = qt.ny
    T = qt.n_ticks if ticks is None else min(int(ticks), qt.n_ticks)
    re = qt.real_entries()
    xbar, ubar = np.ldexp(1.0, qt.x_exp.astype(int)), np.ldexp(1.0, qt.u_exp.astype(int))
    ebar = np.ldexp(1.0, qt.e_exp.astype(int))
    xlsb, elsb, ulsb = qt.lsb(qt.x_exp), qt.lsb(qt.e_exp), qt.lsb(qt.u_exp)
    vlsb = qt.lsb(ft.v_exp)
    dC = np.abs(re["C"] - d["C"])
    dG = np.abs(re["gain"] - d["gain"])
    dM = np.abs(re["model"] - d["model"])
    # The law's own error at a fixed state and multiplier, and the latch's (qformat).
    Ks, k0s, Ls, Lams, lam0s = scaled_entries(src, F, ft.x_exp, ft.u_exp, ft.v_exp)
    eps_u = (0.5 + np.abs(ft.k0 - k0s) + np.abs(ft.K - Ks).sum(2)
             + np.abs(ft.L - Ls).sum(2)) * ulsb                        # (T, m)
    eps_v = (0.5 + np.abs(ft.lambda0 - lam0s) + np.abs(ft.Lambda - Lams).sum(2)) * vlsb
    spec = QEstimatorSpec(ft, qt, 1)
    dim, q = n + nl, 2 * n + nl + m                     # xi = [dx; dv], eta = [a; rv; eu; p]
    D = dim + q
    ticks = np.arange(T)
    sampled = ticks % qt.every == 0
    # Per tick, all at once: the maps of [xi; eta] to dx+ (Wp), dv' (Wv), du (Wu), dx' (Wx)
    # and the local error bounds eta.
    Fg = np.zeros((T, n, p))
    Fg[sampled] = d["gain"][ticks[sampled] // qt.every]
    eta = np.zeros((T, q))
    eta[sampled, :n] = (np.abs(Fg[sampled]) @ (dC @ xbar + elsb / 2)
                        + dG[ticks[sampled] // qt.every] @ ebar + xlsb / 2)
    Wp = np.zeros((T, n, D))
    Wp[:, :, :n] = np.eye(n) - Fg @ d["C"]
    Wp[:, :, dim:dim + n] = np.eye(n)
    stage = ft.stage_of_tick(ticks)
    latch = (ticks == ft.stage_start[stage]) & ((stage == 0) | (ft.stage_n_latch[stage] > 0))
    keep = np.arange(nl)[None, :] < ft.stage_n_latch[stage][:, None]          # (T, nl)
    Lam = np.asarray(src.Lambda, float)[stage] * keep[:, :, None]
    Wv = np.zeros((T, nl, D))
    Wv[:, :, n:dim] = np.eye(nl)
    Wv[latch] = Lam[latch] @ Wp[latch]
    Wv[latch, :, dim + n:dim + n + nl] = np.eye(nl)
    eta[latch, n:n + nl] = np.where(keep[latch], eps_v[stage[latch]], 0.0)
    K, L = np.asarray(src.K, float)[:T], np.asarray(src.L, float)[:T]
    Wu = -(K @ Wp) - L @ Wv
    Wu[:, :, dim + n + nl:dim + n + nl + m] += np.eye(m)
    eta[:, n + nl:n + nl + m] = eps_u[:T]
    P = d["model"][spec.map_of[:T]]
    Wx = P[:, :, :n] @ Wp + P[:, :, n:-1] @ Wu
    Wx[:, :, dim + n + nl + m:] += np.eye(n)
    eta[:, n + nl + m:] = dM[spec.map_of[:T]] @ np.concatenate([xbar, ubar, [1.0]]) + xlsb / 2
    O = np.concatenate([Wp, Wu], axis=1)                # outputs of tick j from xi_j, eta_j
    G, aH = O[:, :, :dim], np.abs(O[:, :, dim:])
    MN = np.concatenate([Wx, Wv], axis=1)               # xi_{j+1} = M_j xi_j + N_j eta_j
    Ms, Ns = MN[:, :, :dim], MN[:, :, dim:]
    out = np.einsum("toq,tq->to", aH, eta)
    b = np.zeros(dim)
    b[:n] = np.abs(re["xhat0"] - d["xhat0"])
    for B in range(0, T, block):
        Phi0 = np.eye(dim)                              # Phi(J, B)
        stack = np.zeros((min(block, T - B), dim, q))   # Phi(J, j+1) N_j, B <= j < J
        for i, j in enumerate(range(B, min(B + block, T))):
            Gj = G[j]
            out[j] += np.abs(Gj @ Phi0) @ b
            if i:
                out[j] += (np.abs(Gj @ stack[:i]) * eta[B:j, None, :]).sum(axis=(0, 2))
                stack[:i] = Ms[j] @ stack[:i]
            stack[i] = Ns[j]
            Phi0 = Ms[j] @ Phi0
        b = np.abs(Phi0) @ b + np.einsum("kdq,kq->d", np.abs(stack), eta[B:B + len(stack)])
    xb, ub = out[:, :n], out[:, n:]
    return xb, ub


def estimator_q_crc32(qt: QEstimatorTable) -> int:
    """``stsp_est_table_crc32`` of a Q15/Q31 build: the float32 serialization with the arrays
    as little-endian int16/int32, then y_exp, e_exp (int8) and shift (uint8), then the hash."""
    dt = "<i2" if qt.arith == "q15" else "<i4"
    return table_crc32(qt, lambda a: np.asarray(a).astype(dt).tobytes(),
                       (np.asarray(qt.y_exp, np.int8).tobytes(),
                        np.asarray(qt.e_exp, np.int8).tobytes(),
                        np.asarray(qt.shift, np.uint8).tobytes()))


def estimator_q_c(qt: QEstimatorTable, prefix: str) -> tuple[str, str]:
    """``(header, source)`` fragments of ``<prefix>_estimator`` in a Q15/Q31 build."""
    from stospline.table.codegen import _array
    p, name = prefix, prefix.upper()
    i32 = lambda x: f"{int(x)}" if int(x) > -(1 << 31) else "INT32_MIN"  # noqa: E731
    elem = "stsp_q15_t" if qt.arith == "q15" else "stsp_q31_t"
    F = qt.frac_bits
    header = f"""
/* The filter on the sensor (stsp_estimator.h), {qt.arith.upper()}: y = y_q 2^(y_exp - {F}),
 * innovation e = e_q 2^(e_exp - {F}), x̂ in the law's x_exp. */
#include "stospline/stsp_estimator.h"

#define {name}_NY {qt.ny}u
#define {name}_EVERY {qt.every}u
/* y_exp = {{{", ".join(str(int(e)) for e in qt.y_exp)}}}, e_exp = {{{", ".join(str(int(e)) for e in qt.e_exp)}}}
 * (predicted ranges y [{", ".join(f"{r:.4g}" for r in qt.y_range)}], e [{", ".join(f"{r:.4g}" for r in qt.e_range)}]). */
extern const stsp_est_table_t {p}_estimator;
"""
    arrays = table_arrays(qt, p, elem, i32, ("[Ad - I | Bd | fd] scaled", "-C scaled",
                                             "update gains scaled", "prior mean (x_exp)")) + [
        _array("int8_t", f"{p}_est_y_exp", qt.y_exp, str, "[ny] reading scale exponents"),
        _array("int8_t", f"{p}_est_e_exp", qt.e_exp, str, "[ny] innovation scale exponents"),
        _array("uint8_t", f"{p}_est_shift", qt.shift, lambda x: f"{int(x)}u",
               "[ny + 2 nx]: row shifts (innovation, update, prediction)"),
    ]
    tail = f",\n    {p}_est_y_exp, {p}_est_e_exp, {p}_est_shift"
    return header, table_source(qt, p, arrays, SCALAR_KIND[qt.arith], estimator_q_crc32(qt),
                                tail)
