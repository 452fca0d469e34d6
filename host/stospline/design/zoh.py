"""Exact sampled-data design: the optimal latched law for a controller that updates ``u`` at
ticks of period ``h`` and holds it in between (stage-wise or joint multipliers).

Conditioned on the state at a tick, one tick maps ``zz'`` (``z = [x; u; 1]``) to the exact
second moment after it and to the exact expected running cost (`moments.exact_tick`), and
``E x+ = F z`` with ``F = [e^{Ah}, Gamma, 0]``. A value after the tick

    x'Px + 2p'x + c + 2 lambda'(N'x + m) - lambda'W lambda      (lambda: latched multipliers)

is therefore exactly, before it, ``z'Hz + 2 lambda'(N'F z + m e') - lambda'W lambda`` with
``H = mat(Phi' vec([[P, p], [p', c]] on x,1)) + mat(Psi' vec(Lbar))``. Minimising over ``u``
is a Riccati recursion over ticks with ``u = -K x - k0 - L lambda``. At a latching stage start
``lambda = W^-1 (N'x + m)`` is substituted, as in continuous time: for each fixed start state
the problem is convex in the policy and Lagrangian duality is exact.
"""
from __future__ import annotations

import os
import warnings
from dataclasses import dataclass, replace

import numpy as np

from stospline.expm import expm

from stospline import progress
from stospline.design.stage_values import StageStart, StageValues, check_group, knot_terminal
from stospline.errors import DesignError
from stospline.design.moments import augmented_drift, moment_generator, running_cost_matrix, varying_tick
from stospline.design.latch import latch_groups
from stospline.problem.model import Knot, Problem, Stage, ticks_per_stage

__all__ = ["ZohStage", "ZohDesign", "design_zoh"]


@dataclass
class ZohStage(StageStart):
    """Per-tick gains of one stage and its start-of-stage value data (`StageStart`)."""
    index: int
    K: np.ndarray        # (T, m, n)
    k0: np.ndarray       # (T, m)
    L: np.ndarray        # (T, m, p): p = width of the multiplier vector acting on the stage

    @property
    def n_constraints(self) -> int:
        return self.L.shape[2]


@dataclass
class ZohDesign(StageValues):
    """The optimal zero-order-hold law at `tick_hz` for a `Problem`."""
    problem: Problem
    tick_hz: int
    stages: list[ZohStage]
    noise_aware: bool
    mode: str = "stagewise"
    # 1: the command computed at tick j is applied at tick j+1; the law's state is then
    # [x; a], a the command being applied (`_delayed_tick_data`), the first a the table's
    # safe command u_hold.
    delay_ticks: int = 0

    def start_state(self, x0: np.ndarray) -> np.ndarray:
        """The law's state at t0 from the plant's `x0`: `x0` itself, or with a delay ``[x0;
        u_hold]`` (the command applied over the first tick: the safe command, as float32)."""
        x0 = np.asarray(x0, dtype=float)
        if not self.delay_ticks:
            return x0
        hold = self.problem.u_hold
        hold = np.zeros(self.problem.m) if hold is None else np.asarray(hold, float)
        return np.concatenate([x0, hold.astype(np.float32).astype(float)])

    @property
    def J0(self) -> float:
        return self.cost_to_go(0, self.start_state(self.problem.x0))

    def cost_from(self, x0: np.ndarray) -> float:
        return self.cost_to_go(0, self.start_state(x0))

    def summary_terms(self) -> dict:
        if not self.delay_ticks:
            return {}
        return {"delay_ticks": self.delay_ticks,
                "controller_state": delayed_state_names(self.problem)}

    def tick_gains(self, tick_hz: int | None = None) -> tuple[int, list[tuple]]:
        """Per-stage ``(K, k0, L, Lambda, lambda0)`` of the law, exact at its own tick rate
        only (None: that rate): the `stospline.table.format.TickGains` interface."""
        if tick_hz is not None and int(tick_hz) != self.tick_hz:
            raise ValueError(f"a zero-order-hold design for {self.tick_hz} Hz has no gains "
                             f"at {tick_hz} Hz: design it again at that rate")
        return self.tick_hz, [(s.K, s.k0, s.L, s.Lambda, s.lambda0) for s in self.stages]


def _sym(a: np.ndarray) -> np.ndarray:
    return 0.5 * (a + a.T)


@dataclass(frozen=True)
class _TickData:
    """Per-stage constants of the tick recursion (d = n + m + 1). "Packed": the upper
    triangle of a symmetric matrix, row by row (`numpy.triu_indices` order)."""
    A2: np.ndarray      # (d*d, (n+1)^2): vec([[P, p], [p', c]]) -> vec(H) before the tick
    Hc: np.ndarray      # (d, d): expected running cost over the tick, as a quadratic in z
    F: np.ndarray       # (n, d): E x+ = F z
    A2sT: np.ndarray    # ((n+1)(n+2)/2, d(d+1)/2): packed V -> packed H, transposed (C kernel)
    Hcs: np.ndarray     # (d(d+1)/2,): Hc packed


def _tick_data(stage: Stage, h: float) -> _TickData:
    """The tick map on symmetric matrices only, from one exponential of size d(d+1)/2 + 1.

    ``H = mat(Phi' vec Vbar)`` and ``Hc = mat(Psi' vec Lbar)`` are the adjoint moment map
    ``e^{gen' h}`` and its integral. ``gen'`` maps symmetric matrices to symmetric matrices,
    so on packed matrices it is ``Gs = E gen' U`` (U duplicates, E picks the upper triangle),
    and ``expm([[Gs h, vech(Lbar) h], [0, 0]])`` holds ``e^{Gs h}`` and ``vech(Hc)``: a
    ``(d(d+1)/2 + 1)``-square exponential instead of Van Loan's ``2 d^2`` (`exact_tick`), equal
    to it to rounding (`tools/bench/zoh_design.py` times designs on both, "previous").
    """
    n, m = stage.B.shape
    d = n + m + 1
    iu, ju = np.triu_indices(d)
    ds = iu.size
    pos = np.empty((d, d), dtype=np.intp)
    pos[iu, ju] = pos[ju, iu] = np.arange(ds)
    rs = np.r_[0:n, d - 1]
    ia, ib = np.triu_indices(n + 1)
    if stage.noise_tensor.any():
        rows = moment_generator(augmented_drift(stage, m + 1), stage.noise_tensor).T[iu * d + ju]
        big = np.zeros((ds + 1, ds + 1))
        big[:ds, :ds] = (rows[:, iu * d + ju] + (iu != ju) * rows[:, ju * d + iu]) * h
        big[:ds, ds] = running_cost_matrix(stage, n, m, d, n)[iu, ju] * h
        E = expm(big)
        A2s = E[:ds, pos[rs[ia], rs[ib]]]                 # packed V (on x,1) -> packed H
        Hcs = E[:ds, ds].copy()
    else:
        A2s, Hcs = _noise_free_maps(stage, h, iu, ju, rs, ia, ib)
    # Full forms for the numpy reference: A2 vec(V) for symmetric V (off-diagonal pairs
    # split evenly between V[a, b] and V[b, a]).
    vpos = np.empty((n + 1, n + 1), dtype=np.intp)
    vpos[ia, ib] = vpos[ib, ia] = np.arange(ia.size)
    half = np.where(np.eye(n + 1, dtype=bool), 1.0, 0.5).ravel()
    A2 = np.ascontiguousarray(A2s[pos.ravel()][:, vpos.ravel()] * half)
    F = expm(augmented_drift(stage, m + 1) * h)[:n]
    return _TickData(A2, Hcs[pos], F, np.ascontiguousarray(A2s.T), Hcs)


def _noise_free_maps(stage: Stage, h: float, iu, ju, rs, ia, ib):
    """`_tick_data`'s packed value map and packed running cost for a stage without
    noise, from one 2d-square exponential instead of the (d(d+1)/2 + 1)-square one: with
    ``Phi = exp(Ahat h)`` the value before the tick is ``H = G' V G + Hc``, ``G = Phi[rs]`` (the
    rows of x and 1), so a packed ``V`` entry (a, b) maps to ``G_a G_b' + G_b G_a'`` (once on
    the diagonal); ``Hc = ∫ Phi(s)' Lb Phi(s) ds`` is Van Loan's."""
    n, m = stage.B.shape
    d = n + m + 1
    Ahat = augmented_drift(stage, m + 1)
    big = np.zeros((2 * d, 2 * d))
    big[:d, :d], big[:d, d:], big[d:, d:] = (-Ahat.T * h, running_cost_matrix(stage, n, m, d, n)
                                             * h, Ahat * h)
    E = expm(big)
    Phi = E[d:, d:]
    Hc = Phi.T @ E[:d, d:]
    G = Phi[rs]
    Ga, Gb = G[ia], G[ib]
    A2sT = Ga[:, iu] * Gb[:, ju] + Gb[:, iu] * Ga[:, ju]
    A2sT[ia == ib] *= 0.5
    return A2sT.T, (0.5 * (Hc + Hc.T))[iu, ju]


def _delayed_tick_data(td: _TickData, n: int, m: int) -> _TickData:
    """The tick data of a one-tick computation delay (``[design] delay_ticks = 1``), from the
    plain tick data `td` of the same stage.

    The controller's state is ``xi = [x; a]``: ``a`` is the command applied over the tick
    (decided one tick earlier), and the decision ``u`` is applied over the next tick. With
    ``z' = [x; a; u; 1]`` and ``w = [x; a; 1]`` (the plain tick's ``z`` with ``a`` held), a
    value after the tick over ``[x+; a+; 1]``, ``a+ = u``,

        x+'Pxx x+ + 2 x+'Pxa u + u'Paa u + 2 px'x+ + 2 pa'u + c

    is before it ``w'(mat(A2 vec [[Pxx, px], [px', c]]) + Hc) w + 2 (F w)'Pxa u + u'Paa u +
    2 pa'u``: the plain map on the ``x, 1`` blocks (running cost on the applied ``a``), and
    ``E x+ = F w`` for the cross term (u is known at the tick). ``E xi+ = F' z'`` with
    ``F' = [[F on w], [0, 0, I, 0]]``. So this is an ordinary `_TickData` with ``n' = n + m``
    states and ``d' = n + 2m + 1``, and `_stage_ticks_numpy` / the C kernel run unchanged.
    """
    nx, d, r = n + m, n + m + 1, n + m + 1          # states, plain d, V' side
    dd = nx + m + 1
    wi = np.r_[0:n + m, dd - 1]                      # w = [x; a; 1] inside z'
    vw = np.r_[0:n, nx]                              # [x; 1] inside [x; a; 1]
    us, as_ = np.arange(nx, nx + m), np.arange(n, nx)
    A2 = np.zeros((dd * dd, r * r))
    A2[np.ix_((wi[:, None] * dd + wi[None, :]).ravel(),
              (vw[:, None] * r + vw[None, :]).ravel())] = td.A2
    for k in range(m):
        u, a = us[k], as_[k]
        for i in range(n):                           # x+'Pxa u, both halves of V'
            A2[wi * dd + u, i * r + a] += td.F[i]
            A2[u * dd + wi, a * r + i] += td.F[i]
        A2[u * dd + us, a * r + as_] = 1.0           # u'Paa u
        A2[u * dd + dd - 1, a * r + nx] = 1.0        # 2 pa'u
        A2[(dd - 1) * dd + u, nx * r + a] = 1.0
    Hc = np.zeros((dd, dd))
    Hc[np.ix_(wi, wi)] = td.Hc
    F = np.zeros((nx, dd))
    F[:n, wi] = td.F
    F[n:, us] = np.eye(m)
    # Packed forms for the C kernel: packed V' -> packed sym(H'), as in `_tick_data`.
    iu, ju = np.triu_indices(dd)
    ia, ib = np.triu_indices(r)
    cols = A2[:, ia * r + ib] + (ia != ib) * A2[:, ib * r + ia]
    A2s = 0.5 * (cols[iu * dd + ju] + cols[ju * dd + iu])
    return _TickData(A2, Hc, F, np.ascontiguousarray(A2s.T), Hc[iu, ju].copy())


def _unapplied_tick(td: _TickData, V, N, W, mv, m: int, hold: np.ndarray):
    """The last tick of a delayed plan: its decision would be applied after the plan ends, so
    it moves no cost and no constraint (``Huu = 0``; the Riccati step would divide by it).
    The law outputs the safe command there (``K = L = 0``, ``k0 = -u_hold``); the value before
    the tick is the ``[x; a; 1]`` block of H. Same returns as `_stage_ticks_numpy`, one tick."""
    n, q = N.shape
    d = n + m + 1
    rs = np.r_[0:n, d - 1]
    H = (td.A2 @ V.ravel()).reshape(d, d)
    H = 0.5 * (H + H.T) + td.Hc
    Hl = N.T @ td.F
    Hl[:, -1] += mv
    Hlr = Hl[:, rs]
    return (np.zeros((1, m, n)), -hold[None, :].copy(), np.zeros((1, m, q)),
            _sym(H[np.ix_(rs, rs)]), Hlr[:, :n].T, W, Hlr[:, n])


def _padded_knot(knot: Knot, nx: int) -> Knot:
    """`knot` with its penalty and constraint rows over ``xi = [x; a]`` (zeros on ``a``):
    knots weigh and constrain the plant state only."""
    def pad(C):
        return np.hstack([C, np.zeros((C.shape[0], nx - C.shape[1]))])
    pen, con = knot.penalty, knot.constraint
    return replace(knot, penalty=None if pen is None else replace(pen, C=pad(pen.C)),
                   constraint=None if con is None else replace(con, C=pad(con.C)))


DELAYS = (0, 1)


def check_delay(problem: Problem, delay_ticks, discretization: str = "exact-zoh") -> int:
    """`delay_ticks` as an int, or a DesignError naming ``design.delay_ticks``: 0 or 1, and
    1 only for the exact zero-order-hold design of time-invariant stage data without bands."""
    if isinstance(delay_ticks, bool) or delay_ticks not in DELAYS:
        raise DesignError("design.delay_ticks", f"must be 0 or 1 (ticks between measuring x "
                                                f"and applying its command), got "
                                                f"{delay_ticks!r}")
    delay = int(delay_ticks)
    if not delay:
        return 0
    if discretization != "exact-zoh":
        raise DesignError("design.delay_ticks", f"a one-tick delay is designed by the exact "
                                                f"zero-order-hold design only, not with "
                                                f"discretization {discretization!r}")
    if problem.tick_regions or any(kn.constraint is not None and kn.constraint.is_band
                                   for kn in problem.knots):
        raise DesignError("design.delay_ticks", "a one-tick delay is not designed with band "
                                                "constraints (lower/upper, regions) yet")
    if any(st.varying is not None for st in problem.stages):
        raise DesignError("design.delay_ticks", "a one-tick delay is designed for "
                                                "time-invariant stage data only")
    from stospline.limits import MAX_NX
    if problem.n + problem.m > MAX_NX:
        raise DesignError("design.delay_ticks", f"the delayed law's state [x; a] has n + m = "
                                                f"{problem.n + problem.m} components; the "
                                                f"firmware takes at most {MAX_NX} "
                                                f"(STSP_MAX_NX)")
    return delay


def delayed_state_names(problem: Problem) -> list[str]:
    """Names of the controller state of a delayed design: the plant's, then the commands
    being applied (``u0_applied``, ...)."""
    return ([f"x{i}" for i in range(problem.n)]
            + [f"u{j}_applied" for j in range(problem.m)])


def _stage_key(stage: Stage, h: float) -> bytes:
    return b"".join(np.ascontiguousarray(a, float).tobytes() for a in
                    (stage.A, stage.B, stage.noise_tensor, stage.Q, stage.S, stage.R,
                     stage.q, stage.r, np.array([stage.rho, h]),
                     np.zeros(0) if stage.f is None else stage.f))


def _stage_ticks_numpy(td: _TickData, V, N, W, mv, T: int, m: int, huu=None):
    """The reference implementation of one stage's ticks (backward): gains K, k0, L per tick
    and the value V, N, W, mv before the first tick. ``huu`` (T, m, m), if given, receives
    each tick's ``H_uu`` (the curvature of the expected cost in the command held over the
    tick; `stospline.design.tick_qp`). Raises `numpy.linalg.LinAlgError`."""
    n, q = N.shape
    d = n + m + 1
    us, rs = np.arange(n, n + m), np.r_[0:n, d - 1]
    K = np.empty((T, m, n)); k0 = np.empty((T, m)); L = np.empty((T, m, q))
    for j in range(T - 1, -1, -1):
        H = (td.A2 @ V.ravel()).reshape(d, d)
        H = 0.5 * (H + H.T) + td.Hc
        Hl = N.T @ td.F                                  # (q, d)
        Hl[:, -1] += mv
        Huu = H[np.ix_(us, us)]
        Hur = H[np.ix_(us, rs)]
        Hlu = Hl[:, us]
        if huu is not None:
            huu[j] = Huu
        G = np.linalg.solve(Huu, np.hstack([Hur, Hlu.T]))
        Gr, Gl = G[:, :n + 1], G[:, n + 1:]
        K[j], k0[j], L[j] = Gr[:, :n], Gr[:, n], Gl
        V = _sym(H[np.ix_(rs, rs)] - Hur.T @ Gr)
        Hlr = Hl[:, rs] - Hlu @ Gr
        N, mv = Hlr[:, :n].T, Hlr[:, n]
        W = _sym(W + Hlu @ Gl)
    return K, k0, L, V, N, W, mv


def _stage_ticks_c(td: _TickData, V, N, W, mv, T: int, m: int):
    """`_stage_ticks_numpy` in C (`kernels.zoh_stage_ticks`); equal to it to rounding."""
    from stospline.design.kernels import zoh_stage_ticks
    return zoh_stage_ticks(td.A2sT, td.Hcs, td.F, V, N, W, mv, T, m)


def _varying_tick_data(stage: Stage, t: float, h: float) -> _TickData:
    """Tick data of time-varying stage data over ``[t, t + h]`` from the fourth-order Magnus
    map (`moments.varying_tick`; the numpy loop uses only A2, Hc and F)."""
    n, m = stage.B.shape
    d = n + m + 1
    Phi, cost_row = varying_tick(stage, m + 1, t, h)
    rs = np.r_[0:n, d - 1]
    idx = (rs[:, None] * d + rs[None, :]).ravel()
    ones = np.arange(d) * d + d - 1                   # vec positions of z_b * 1
    F = Phi[np.ix_(ones[:n], ones)]                   # E x+ = F z: the mean rows of Phi
    return _TickData(np.ascontiguousarray(Phi.T[:, idx]), _sym(cost_row.reshape(d, d)), F,
                     np.zeros((0, 0)), np.zeros(0))


def _varying_stage_ticks(stage: Stage, t_start: float, h: float, V, N, W, mv, T: int, m: int):
    """`_stage_ticks_numpy` with a fresh tick map at every tick (time-varying data): the
    numpy reference of the C loop `varying.zoh_ticks` (same order, another method)."""
    n, q = N.shape
    K = np.empty((T, m, n)); k0 = np.empty((T, m)); L = np.empty((T, m, q))
    for j in range(T - 1, -1, -1):
        td = _varying_tick_data(stage, t_start + j * h, h)
        Kj, k0j, Lj, V, N, W, mv = _stage_ticks_numpy(td, V, N, W, mv, 1, m)
        K[j], k0[j], L[j] = Kj[0], k0j[0], Lj[0]
    return K, k0, L, V, N, W, mv


KERNELS = ("c", "numpy")


def _pick_kernel(kernel: str | None):
    """The tick-loop implementation: `kernel`, else ``STOSPLINE_ZOH_KERNEL``, else "c"; a
    default "c" that cannot be built falls back to numpy with a warning."""
    explicit = kernel is not None
    kernel = kernel or os.environ.get("STOSPLINE_ZOH_KERNEL") or "c"
    if kernel not in KERNELS:
        raise ValueError(f"kernel must be one of {KERNELS}, got {kernel!r}")
    if kernel == "numpy":
        return _stage_ticks_numpy
    from stospline.design.kernels import KernelBuildError, load_kernels
    try:
        load_kernels()
    except KernelBuildError as exc:
        if explicit:
            raise
        from stospline.cache import FallbackWarning
        warnings.warn(f"{exc}; using the numpy tick loop (much slower)", FallbackWarning,
                      stacklevel=3)
        return _stage_ticks_numpy
    return _stage_ticks_c


def design_zoh(problem: Problem, tick_hz: int | None = None, *, noise: bool = True,
               mode: str = "stagewise", kernel: str | None = None,
               delay_ticks: int = 0) -> ZohDesign:
    """Solve the exact sampled-data design at `tick_hz` (default: the problem's).

    Parameters
    ----------
    problem : Problem
    tick_hz : int, optional
        Controller rate; must divide every stage length.
    noise : bool
        False designs as if the diffusion were absent (the paper's Remark 2).
    mode : {"stagewise", "joint"}
        See `multipliers`.
    kernel : {"c", "numpy"}, optional
        The per-tick loop: compiled C (`kernels`, the default) or the numpy reference
        (``STOSPLINE_ZOH_KERNEL=numpy`` sets the default). They agree to rounding.
    delay_ticks : {0, 1}
        1: the command computed from the state at tick j is applied at tick j+1 (a one-tick
        computation delay). The law is then over ``[x; a]``, ``a`` the command being applied
        (`_delayed_tick_data`): its gains have ``n + m`` columns.

    Returns
    -------
    ZohDesign
    """
    tick_hz = problem.tick_hz if tick_hz is None else int(tick_hz)
    try:
        counts = ticks_per_stage(problem, tick_hz)
    except ValueError as exc:
        raise DesignError("tick_hz", str(exc)) from None
    h = 1.0 / tick_hz
    delay = check_delay(problem, delay_ticks)
    n, m = problem.n, problem.m
    knots = problem.knots
    if delay:      # the law's state xi = [x; a]: from here on n counts its components
        n = n + m
        knots = tuple(_padded_knot(kn, n) for kn in knots)
        hold = (np.zeros(m) if problem.u_hold is None
                else np.asarray(problem.u_hold, dtype=float).astype(np.float32).astype(float))
    stage_ticks = _pick_kernel(kernel)
    _, group_of = latch_groups(problem, mode)
    cache: dict[bytes, _TickData] = {}
    V = np.zeros((n + 1, n + 1))          # [[P, p], [p', c]] after the current point
    N = W = mv = None                      # open multiplier group
    out: list[ZohStage | None] = [None] * len(problem.knots)
    bar = progress.start("design", int(np.sum(counts)))
    for k in range(len(problem.knots) - 1, -1, -1):
        knot, g = knots[k], group_of[k]
        stage = problem.stages[k] if noise else problem.stages[k].without_noise()
        PT, pT, cT = knot_terminal(knot, V[:n, :n], V[:n, n], V[n, n])
        V = np.block([[PT, pT[:, None]], [pT[None, :], np.array([[cT]])]])
        q = 0 if g is None else g.size
        if g is not None:
            if N is None or N.shape[1] != q:     # a new group (an unconstrained stage
                # after it leaves zero-width arrays behind)
                N, W, mv = np.zeros((n, q)), np.zeros((q, q)), np.zeros(q)
            if knot.n_constraints:
                o = g.offset_of(k)
                N = N.copy(); mv = mv.copy()
                N[:, o:o + knot.n_constraints] += knot.constraint.C.T
                mv[o:o + knot.n_constraints] -= knot.constraint.value
        else:
            N, W, mv = np.zeros((n, 0)), np.zeros((0, 0)), np.zeros(0)
        try:
            # A finite escape overflows to Inf/NaN: the check below reports it as an error,
            # so numpy's overflow warnings would only repeat it.
            with np.errstate(over="ignore", invalid="ignore"):
                if stage.varying is None:
                    key = _stage_key(stage, h)
                    td = cache.get(key)
                    if td is None:
                        td = _tick_data(stage, h)
                        if delay:
                            td = _delayed_tick_data(td, problem.n, m)
                        cache[key] = td
                    T = int(counts[k])
                    if delay and k == len(problem.knots) - 1:
                        last = _unapplied_tick(td, V, N, W, mv, m, hold)
                        V, N, W, mv = last[3:]
                        T -= 1
                    K, k0, L, V, N, W, mv = stage_ticks(td, V, N, W, mv, T, m)
                    if delay and k == len(problem.knots) - 1:
                        K, k0, L = (np.concatenate([a, b]) for a, b in zip((K, k0, L), last))
                else:
                    from stospline.design.varying import zoh_ticks   # time-varying data only
                    varying_ticks = (zoh_ticks if stage_ticks is _stage_ticks_c
                                     else _varying_stage_ticks)
                    K, k0, L, V, N, W, mv = varying_ticks(
                        stage, problem.times[k], h, V, N, W, mv, int(counts[k]), m)
        except np.linalg.LinAlgError:
            from stospline.strict import riccati_failure
            raise DesignError(*riccati_failure(problem, k)) from None
        if not (np.all(np.isfinite(V)) and np.all(np.isfinite(W))):
            raise DesignError(f"knots[{k}].t", f"the tick Riccati recursion of stage {k} has "
                                               f"no bounded solution in floating point")
        st = ZohStage(k, K, k0, L, P0=V[:n, :n].copy(), p0=V[:n, n].copy(), c0=float(V[n, n]),
                      N0=N, W0=W, m0=mv, Lambda=np.zeros((0, n)), lambda0=np.zeros(0))
        if g is not None and g.latch_stage == k:
            check_group(W, problem, g)
            st.Lambda, st.lambda0 = np.linalg.solve(W, N.T), np.linalg.solve(W, mv)
            NL = N @ st.Lambda
            V = V.copy()
            V[:n, :n] += 0.5 * (NL + NL.T)
            V[:n, n] += N @ st.lambda0
            V[n, :n] = V[:n, n]
            V[n, n] += mv @ st.lambda0
            N = W = mv = None
        out[k] = st
        progress.advance(int(counts[k]))
    progress.finish(bar)
    return ZohDesign(problem, tick_hz, out, noise, mode, delay)
