"""The joint design with regions at every tick as one sparse QP on the tick grid.

Without constraints, the exact zero-order-hold tick recursion (`stospline.design.zoh`) gives
the optimal feedback ``K_j``, feed-forward ``k*_j``, the value ``V_0`` at t0 and, at every
tick, ``H_j``: the curvature of the expected cost in the command held over the tick. For any
law ``u_j = -K_j x_j - k*_j - d_j`` with a deterministic offset ``d_j``, completing the square
tick by tick gives exactly

    J(d) = [x0; 1]' V_0 [x0; 1] + sum_j d_j' H_j d_j

(the expected cost of ``u - u*`` is that of its mean, which is ``-d_j``), and the means obey
``m_{j+1} = F_x m_j + F_u (-K_j m_j - k*_j - d_j) + F_1``. Every constraint of the joint
design (the knots' equalities and bands, the regions at every tick) bounds ``C m_j`` at some
tick, and with fixed ``K`` no law does better (``K`` does not depend on the constraints). So the
design is the QP in ``(m, d)``: block-diagonal Hessian, banded constraints. It has no dual
Gramian ``W(t0)`` to invert, so it stays well conditioned at any tick rate, and its size grows
linearly in the ticks. A primal-dual interior-point method (sparse LU of the banded KKT matrix,
about 17 iterations at any rate) finds the active set; the KKT system of that set is then
solved exactly and the set corrected until every row is inside its band and every
multiplier has its sign.

Why our own interior point and not OSQP (the QP solver in the lock) for the guess, with the
same exact corrections on top (``tools/bench/tick_qp_osqp.py``, robot_monotone,
docs/evidence/performance.md): OSQP's ADMM iterations grow with the ticks (200, 8 275 and
25 550 at 100 Hz, 1 kHz and 2 kHz, against 15-17 here), so the design takes 1x, 11x and 23x
the time (52 s against 4.8 s at 1 kHz); from 2 kHz its guess leads to another active set of
degenerate rows (the design differs in the last bits); and where the corrections do not settle,
the fallback needs the interior point's feasible iterate and its duality gap, which OSQP does
not give.

The table latches the state at t0: ``d = d_c + D x0`` is affine in ``x0`` for the optimal
active set, so ``k0_j = k*_j + d_c,j`` and ``L_j = D_j`` with ``v = x(t0)``. Exact for the design's
``x0`` and every start with the same active set (as a band design with more rows than the
firmware's band solver takes).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from stospline.design.stage_values import check_rows, knot_terminal
from stospline.design.zoh import _stage_ticks_numpy, _tick_data
from stospline.errors import DesignError
from stospline.problem.model import Problem, ticks_per_stage

__all__ = ["TickRow", "TickQPDesign", "design_tick_qp"]

# Exact corrections of the interior-point guess of the active set, and its iterations.
MAX_ROUNDS = 50
IPM_MAX_ITERATIONS = 80
KKT_REGULARIZATION = 1e-13
# Relative excess over the interior point's lower bound at which a feasible KKT point is
# certified optimal when the multipliers of degenerate rows have the wrong sign.
OPTIMALITY = 1e-10
# A row is a combination of others when it is within this (relative) of their span.
DEPENDENT = 1e-9
# The interior point stops at a mean complementarity s'z / rows below this (times the bounds'
# scale): tight enough that the rows it calls active are the optimum's but for a few at the
# ends of arcs (robot at 1 kHz: none to 3 corrections left for the exact loop).
IPM_MU = 1e-17
# A row is beyond its band when it is out by more than this times max(1, |bounds|): the exact
# KKT solve meets its active rows to ~1e-13 of that scale.
TOLERANCE = 1e-9


@dataclass(frozen=True)
class TickRow:
    """One constraint row: ``lower <= c' m_tick + cd' d_tick + offset <= upper``. A knot's or
    a region's row at a tick has ``cd`` None and no offset; a "between" row bounds one
    Bernstein coefficient (`bernstein`) of a region row's mean over the tick that starts at
    `tick` (`_between_rows`)."""
    tick: int
    kind: str            # "knot", "region" or "between"
    index: int           # the knot's index, or the region's place in the file's [[regions]]
    row: int
    c: np.ndarray
    lower: float
    upper: float
    cd: np.ndarray | None = None
    offset: float = 0.0
    bernstein: int = -1


@dataclass
class TickQPDesign:
    """The every-tick joint design as a tick-grid QP (`design_tick_qp`)."""
    problem: Problem
    tick_hz: int
    K: np.ndarray          # (T, m, n) feedback
    kstar: np.ndarray      # (T, m) unconstrained feed-forward
    H: np.ndarray          # (T, m, m) cost curvature of each tick's command
    delta: np.ndarray      # (T, m) offset of the optimum, at the design's x0
    D: np.ndarray          # (T, m, n) its sensitivity to x0 (fixed active set)
    V0: np.ndarray         # (n+1, n+1) unconstrained value at t0, on [x; 1]
    J0: float
    rows: list[TickRow]
    active: np.ndarray     # per row: -1 at lower, +1 at upper, 0 inside (equalities: +-1)
    multipliers: np.ndarray
    expected: np.ndarray   # c' E{x_tick} of each row at the optimum
    rounds: int = 0
    ipm_iterations: int = 0
    seconds: float = 0.0
    # Bound on J0 - optimum: 0 for an exact KKT point, else the interior point's duality gap.
    optimality_gap: float = 0.0
    noise_aware: bool = True
    mode: str = "joint"
    delay_ticks: int = 0
    stats: dict = field(default_factory=dict)

    def offset_from(self, x0: np.ndarray) -> np.ndarray:
        """``d`` of the tabulated law started from `x0` (the optimum's active set kept)."""
        return self.delta + self.D @ (np.asarray(x0, float) - self.problem.x0)

    def cost_from(self, x0: np.ndarray) -> float:
        """Expected cost of the tabulated law from `x0`: the optimum while the active set
        stays optimal there (as the affine latch of a band design)."""
        z = np.append(np.asarray(x0, float), 1.0)
        d = self.offset_from(x0)
        return float(z @ self.V0 @ z + np.einsum("ti,tij,tj->", d, self.H, d))

    def tick_gains(self, tick_hz: int | None = None) -> tuple[int, list[tuple]]:
        """Per stage ``(K, k0, L, Lambda, lambda0)`` (`stospline.table.format.TickGains`): the
        state is latched at t0 (``Lambda = I``) and held for every later stage."""
        if tick_hz is not None and int(tick_hz) != self.tick_hz:
            raise ValueError(f"a tick-grid design has only its own rate {self.tick_hz} Hz")
        n = self.problem.n
        k0 = self.kstar + self.delta - np.einsum("tij,j->ti", self.D, self.problem.x0)
        start = np.concatenate([[0], np.cumsum(ticks_per_stage(self.problem, self.tick_hz))])
        stages = []
        for k in range(len(start) - 1):
            sl = slice(int(start[k]), int(start[k + 1]))
            first = k == 0
            stages.append((self.K[sl], k0[sl], self.D[sl],
                           np.eye(n) if first else np.zeros((0, n)),
                           np.zeros(n if first else 0)))
        return self.tick_hz, stages

    def band_dual(self, *, exact: bool = False) -> None:
        """None: the firmware latches the affine map of the active set."""
        return None

    def arcs(self) -> list[dict]:
        """The active rows of the regions as arcs: runs of consecutive ticks at which the
        same row of the same region sits at the same bound."""
        out: list[dict] = []
        for r, a in zip(self.rows, self.active):
            if r.kind != "region" or a == 0:
                continue
            side = "upper" if a > 0 else "lower"
            last = out[-1] if out else None
            if (last is not None and last["region"] == r.index and last["row"] == r.row
                    and last["at"] == side and last["ticks"][1] == r.tick - 1):
                last["ticks"][1] = r.tick
                last["count"] += 1
            else:
                out.append({"region": r.index, "row": r.row, "at": side,
                            "ticks": [r.tick, r.tick], "count": 1})
        return out

    def active_ticks(self) -> list[tuple[int, int]]:
        """``(tick, side)`` of every region row held at a bound."""
        return sorted((r.tick, int(a)) for r, a in zip(self.rows, self.active)
                      if r.kind == "region" and a != 0)

    def summary_terms(self) -> dict:
        return {"tick_qp": {"rows": len(self.rows),
                            "active_region_rows": len(self.active_ticks()),
                            "arcs": self.arcs(),
                            "optimality_gap": self.optimality_gap}}
        # (Not the interior point's iterations or the corrections: they can differ in the
        # last bits between machines, and the summary is regenerated byte for byte.)


def _backward(problem: Problem, tick_hz: int, noise: bool):
    """The unconstrained tick recursion: K, k*, H per tick and V at t0."""
    n, m = problem.n, problem.m
    counts = ticks_per_stage(problem, tick_hz)
    h = 1.0 / tick_hz
    T = int(np.sum(counts))
    K = np.empty((T, m, n)); ks = np.empty((T, m)); H = np.empty((T, m, m))
    F = np.empty((len(counts), n, n + m + 1))
    start = np.concatenate([[0], np.cumsum(counts)]).astype(int)
    V = np.zeros((n + 1, n + 1))
    cache: dict = {}
    empty = (np.zeros((n, 0)), np.zeros((0, 0)), np.zeros(0))
    for k in range(len(problem.knots) - 1, -1, -1):
        stage = problem.stages[k] if noise else problem.stages[k].without_noise()
        if stage.varying is not None:
            idx = problem.tick_regions[0].index if problem.tick_regions else 0
            raise DesignError(f"regions[{idx}]", f"designed on the tick grid here (more than "
                                                 f"8 rows bind, or between_ticks), which "
                                                 f"takes time-invariant stage data only; "
                                                 f"stage {k}'s vary in time")
        PT, pT, cT = knot_terminal(problem.knots[k], V[:n, :n], V[:n, n], V[n, n])
        V = np.block([[PT, pT[:, None]], [pT[None, :], np.array([[cT]])]])
        key = id(stage)
        td = cache.get(key)
        if td is None:
            td = cache[key] = _tick_data(stage, h)
        sl = slice(start[k], start[k + 1])
        try:
            K[sl], ks[sl], _, V, *_ = _stage_ticks_numpy(td, V, *empty, int(counts[k]), m,
                                                         huu=H[sl])
        except np.linalg.LinAlgError:
            from stospline.strict import riccati_failure
            raise DesignError(*riccati_failure(problem, k)) from None
        F[k] = td.F
        if not np.all(np.isfinite(V)):
            raise DesignError(f"knots[{k}].t", f"the tick Riccati recursion of stage {k} has "
                                               f"no bounded solution in floating point")
    stage_of = np.repeat(np.arange(len(counts)), counts)
    return K, ks, H, F, stage_of, V


def _rows(problem: Problem, tick_hz: int, K, ks, stage_of) -> list[TickRow]:
    """Every constraint row, ordered by tick: the knots' rows, then the regions' (and their
    rows between ticks)."""
    t0 = problem.t0
    rows = []
    for k, kn in enumerate(problem.knots):
        if kn.constraint is None:
            continue
        j = int(round((kn.t - t0) * tick_hz))
        lo, hi = kn.constraint.bounds
        for i, c in enumerate(kn.constraint.C):
            rows.append(TickRow(j, "knot", k, i, np.asarray(c, float), float(lo[i]),
                                float(hi[i])))
    for reg in problem.tick_regions:
        for j in reg.ticks(t0, tick_hz):
            for i, c in enumerate(reg.C):
                rows.append(TickRow(int(j), "region", reg.index, i, np.asarray(c, float),
                                    float(reg.lower[i]), float(reg.upper[i])))
        if reg.between:
            rows += _between_rows(problem, tick_hz, reg, K, ks, stage_of)
    rows.sort(key=lambda r: (r.tick, ("knot", "region", "between").index(r.kind), r.index,
                             r.row, r.bernstein))
    return rows


def _tightened(r: TickRow, tighten) -> TickRow:
    if r.kind == "between" or r.lower == r.upper:
        return r
    up, down = tighten(r)
    return replace(r, lower=r.lower + down, upper=r.upper - up)


def _between_rows(problem: Problem, tick_hz: int, reg, K, ks, stage_of) -> list[TickRow]:
    """A region's rows between ticks. Over a tick the command is held, and for an integrator
    chain (``A`` nilpotent, data constant) the mean is a polynomial of degree D <= n in the
    time s since the tick:

        E{c'x(s)} = sum_k s^k/k! c'A^k m_j + s^(k+1)/(k+1)! c'A^k (B u_j + f),
        u_j = -K_j m_j - k*_j - d_j,

    linear in ``(m_j, d_j)``. On a piece ``[alpha, beta]`` of the tick, with
    ``s = alpha + (beta - alpha) sigma``, a polynomial lies between its smallest and largest
    Bernstein coefficients over sigma in [0, 1], and its end coefficients are its values at
    the ends. So bounding the interior coefficients (and the end one where the piece ends
    inside a tick, at b) keeps it inside the band at every time of the piece: sufficient, and
    close (a quadratic's middle coefficient exceeds its extremum by at most a quarter of its
    range over the tick); the values at the ticks are the tick rows. A degree-1 mean (a
    velocity of a double integrator) needs no interior row."""
    t0, h = problem.t0, 1.0 / tick_hz
    bounds = np.array([t0] + [kn.t for kn in problem.knots])
    a, b = reg.t
    first = int(round((a - t0) * tick_hz))
    last = int(np.ceil((b - t0) * tick_hz - 1e-9))
    field = f"regions[{reg.index}].between_ticks"
    cache: dict = {}
    out = []
    for j in range(first, last):
        k = int(stage_of[min(j, len(stage_of) - 1)])
        st = problem.stages[k]
        if k not in cache:
            n = st.A.shape[0]
            if st.varying is not None or np.any(np.linalg.matrix_power(st.A, n)):
                raise DesignError(field, f"the mean is a polynomial over a tick only for an "
                                         f"integrator chain (A nilpotent, data constant in "
                                         f"time); stage {k} (t = {bounds[k]:g} to "
                                         f"{bounds[k + 1]:g}) is not one")
            f = np.zeros(n) if st.f is None else np.asarray(st.f, float)
            cache[k] = (st.A, st.B, f)
        A, B, f = cache[k]
        n, m = B.shape
        alpha = 0.0
        beta = min(h, b - (t0 + j * h))
        if beta <= 1e-12 * h:
            continue
        for i, c in enumerate(reg.C):
            P = _power_coefficients(c, A, B, f, K[j], ks[j])        # (n+1, n+m+1)
            nz = np.flatnonzero(np.abs(P).max(axis=1) > 1e-12 * max(1.0, np.abs(P).max()))
            D = int(nz.max()) if nz.size else 0
            Bz = _bernstein(P[:D + 1], alpha, beta)
            ends = beta < h * (1 - 1e-9)                     # the piece ends inside a tick
            for q in range(1, D + (1 if ends else 0)):
                out.append(TickRow(j, "between", reg.index, i, Bz[q, :n],
                                   float(reg.lower[i]), float(reg.upper[i]),
                                   cd=Bz[q, n:n + m], offset=float(Bz[q, -1]), bernstein=q))
    return out


def _power_coefficients(c, A, B, f, Kj, ksj) -> np.ndarray:
    """Rows k = 0..n: the coefficient of s^k in ``c'E{x(s)}`` over a tick, as a linear form
    in ``[m_j; d_j; 1]`` (the command ``-K_j m_j - k*_j - d_j`` held)."""
    n, m = B.shape
    P = np.zeros((n + 1, n + m + 1))
    cA = np.asarray(c, float)                # c'A^k
    fact = 1.0
    for k in range(n + 1):
        if k:
            fact *= k
        P[k, :n] += cA / fact
        if k < n:
            u = cA @ B / (fact * (k + 1))       # s^(k+1)/(k+1)! c'A^k B u
            P[k + 1, :n] -= u @ Kj
            P[k + 1, n:n + m] -= u
            P[k + 1, -1] += -u @ ksj + cA @ f / (fact * (k + 1))
        cA = cA @ A
    return P


def _bernstein(P: np.ndarray, alpha: float, beta: float) -> np.ndarray:
    """Bernstein coefficients over [alpha, beta] of the polynomial with power coefficients
    `P` (rows: s^0 .. s^D, each a linear form)."""
    from math import comb
    D = P.shape[0] - 1
    L = beta - alpha
    # Power coefficients in sigma, s = alpha + L sigma.
    Q = np.zeros_like(P)
    for k in range(D + 1):
        for i in range(k + 1):
            Q[i] += comb(k, i) * alpha ** (k - i) * L ** i * P[k]
    out = np.zeros_like(P)
    for i in range(D + 1):
        for k in range(i + 1):
            out[i] += comb(i, k) / comb(D, k) * Q[k]
    return out


class _Grid:
    """The QP's sparse data: variables ``[m_0 .. m_T, d_0 .. d_{T-1}]``."""

    def __init__(self, problem, K, ks, H, F, stage_of, rows):
        from scipy import sparse
        n, m = problem.n, problem.m
        T = len(K)
        self.n, self.m, self.T = n, m, T
        self.nv = (T + 1) * n + T * m
        off_d = (T + 1) * n
        Fx, Fu, F1 = F[stage_of, :, :n], F[stage_of, :, n:n + m], F[stage_of, :, -1]
        Acl = Fx - np.einsum("tik,tkj->tij", Fu, K)
        self.Acl, self.Fu = Acl, Fu            # the mean map of each tick
        # Equality rows: m_0 = x0, then m_{j+1} - Acl_j m_j + Fu_j d_j = -Fu_j k*_j + F1_j.
        j, a, b = np.meshgrid(np.arange(T), np.arange(n), np.arange(n), indexing="ij")
        ju, au, bu = np.meshgrid(np.arange(T), np.arange(n), np.arange(m), indexing="ij")
        row = n + np.arange(T)[:, None] * n + np.arange(n)[None, :]        # (T, n)
        r_i = [np.arange(n), row.ravel(), (n + j * n + a).ravel(), (n + ju * n + au).ravel()]
        c_i = [np.arange(n), row.ravel(), (j * n + b).ravel(),         # row = (j+1) n + a
               (off_d + ju * m + bu).ravel()]
        v_i = [np.ones(n), np.ones(T * n), -Acl.ravel(), Fu.ravel()]
        self.n_eq = (T + 1) * n
        self.dyn_rhs = np.concatenate([np.zeros(n),
                                       (-np.einsum("tij,tj->ti", Fu, ks) + F1).ravel()])
        # Constraint rows.
        q = len(rows)
        rr = np.repeat(np.arange(q), n)
        cc = np.concatenate([r.tick * n + np.arange(n) for r in rows]) if q else np.zeros(0, int)
        vv = np.concatenate([r.c for r in rows]) if q else np.zeros(0)
        between = [(i, r) for i, r in enumerate(rows) if r.cd is not None]
        if between:         # the rows between ticks also weigh that tick's offset d_j
            rr = np.concatenate([rr, np.repeat([i for i, _ in between], m)])
            cc = np.concatenate([cc] + [off_d + r.tick * m + np.arange(m) for _, r in between])
            vv = np.concatenate([vv] + [r.cd for _, r in between])
        self.E = sparse.csr_matrix((np.concatenate(v_i), (np.concatenate(r_i),
                                                          np.concatenate(c_i))),
                                   shape=(self.n_eq, self.nv))
        self.C = sparse.csr_matrix((vv, (rr, cc)), shape=(q, self.nv))
        self.offset = np.array([r.offset for r in rows])
        self.lo = np.array([r.lower for r in rows]) - self.offset
        self.hi = np.array([r.upper for r in rows]) - self.offset
        pd = np.arange(T * m).reshape(T, m) + off_d
        self.P = sparse.csc_matrix((2 * H.ravel(), (np.repeat(pd, m, axis=1).ravel(),
                                                     np.tile(pd, (1, m)).ravel())),
                                   shape=(self.nv, self.nv))
        self.off_d = off_d

    def rhs(self, x0):
        b = self.dyn_rhs.copy()
        b[:self.n] = x0
        return b

    def offsets(self, w) -> np.ndarray:
        return w[self.off_d:].reshape(self.T, self.m)


def _interior_point(g: _Grid, x0, eq: np.ndarray) -> tuple:
    """A guess of the active set (+1 upper, -1 lower per constraint row) from a primal-dual
    interior-point method (Mehrotra's predictor-corrector) on the QP, its iterations, and a
    lower bound on the optimal objective. Each iteration solves one sparse augmented system
    ``[[P, E', G'], [E, 0, 0], [G, 0, -(S/Z + delta)]]`` (banded in time), and their number
    hardly grows with the ticks (15-17 on the robot from 100 Hz to 5 kHz,
    `tools/bench/tick_qp.py`), where ADMM's grew with the horizon.
    The rows with a bound (``lower < upper``) are ``G w <= h``, ``G = [C; -C]``; the knots'
    equalities join ``E``. The exact KKT loop corrects the guess."""
    from scipy import sparse
    ineq = np.flatnonzero(~eq)
    Ci = g.C[ineq]
    E = sparse.vstack([g.E, g.C[np.flatnonzero(eq)]], format="csr")
    b = np.concatenate([g.rhs(x0), g.lo[eq]])
    up, lo = g.hi[ineq], g.lo[ineq]
    fu, fl = np.isfinite(up), np.isfinite(lo)
    G = sparse.vstack([Ci[np.flatnonzero(fu)], -Ci[np.flatnonzero(fl)]], format="csr")
    h = np.concatenate([up[fu], -lo[fl]])
    nv, ne, ni = g.nv, E.shape[0], G.shape[0]
    P = g.P.tocsr()
    guess = np.zeros(len(g.lo), dtype=int)
    guess[eq] = 1
    if ni == 0:
        return guess, 0, -np.inf, None

    # Start: the equality-constrained optimum, slacks pushed inside.
    try:
        start_lu = _lu(sparse.bmat([[P, E.T], [E, None]], format="csc"))
    except RuntimeError:                 # SuperLU: "Factor is exactly singular"
        raise DesignError("regions", "the tick-grid QP's equality rows (knot constraints and "
                                     "the region rows they fix) are linearly dependent: "
                                     "remove redundant rows") from None
    z0 = start_lu.solve(np.concatenate([np.zeros(nv), b]))
    w, y = z0[:nv], z0[nv:]
    scale = max(1.0, float(np.abs(h).max()))
    s = np.maximum(h - G @ w, 1e-2 * scale)
    z = np.ones(ni)
    it = 0
    best = None
    for it in range(1, IPM_MAX_ITERATIONS + 1):
        rd = P @ w + E.T @ y + G.T @ z
        re = E @ w - b
        ri = G @ w + s - h
        mu = float(s @ z) / ni
        resid = max(float(np.abs(rd).max()), float(np.abs(re).max()) / scale,
                    float(np.abs(ri).max()) / scale)
        if resid < 1e-8 and (best is None or mu < best[0]):
            best = (mu, s, z, 0.5 * float(w @ (P @ w)) - float(s @ z), w)
        if mu < IPM_MU * scale and resid < 1e-10:
            break
        if best is not None and resid > 1e-6:
            # Degenerate rows (dependent ones at a bound along an arc) drive z/s to where
            # the Newton systems lose their accuracy: keep the last accurate iterate.
            break
        # The augmented Newton system: the inequality rows keep their own block
        # -(s/z + delta), so rows that depend on others and reach their bound (z/s -> inf)
        # stay solvable, as in the KKT matrix of the exact solve.
        M = sparse.bmat([[P, E.T, G.T], [E, None, None],
                         [G, None, -sparse.diags(s / z + KKT_REGULARIZATION)]], format="csc")
        lu = _lu(M)

        def step(rc):
            sol = lu.solve(np.concatenate([-rd, -re, rc / z - ri]))
            dw, dy, dz = sol[:nv], sol[nv:nv + ne], sol[nv + ne:]
            ds = -ri - G @ dw
            return dw, dy, ds, dz

        def longest(v, dv):
            neg = dv < 0
            return min(1.0, float(np.min(-v[neg] / dv[neg]))) if neg.any() else 1.0

        dw, dy, ds, dz = step(s * z)                       # predictor (affine)
        a_aff = min(longest(s, ds), longest(z, dz))
        mu_aff = float((s + a_aff * ds) @ (z + a_aff * dz)) / ni
        sigma = (mu_aff / mu) ** 3
        dw, dy, ds, dz = step(s * z + ds * dz - sigma * mu)   # corrector
        a = 0.99 * min(longest(s, ds), longest(z, dz))
        w, y, s, z = w + a * dw, y + a * dy, s + a * ds, z + a * dz
        if a < 1e-10:       # stalled at rounding: the guess is as good as it gets
            break
    lower, primal = -np.inf, None
    if best is not None:
        _, s, z, lower, primal = best
    # Active where the multiplier outweighs the slack.
    zu, zl = np.zeros(len(ineq)), np.zeros(len(ineq))
    su, sl = np.ones(len(ineq)), np.ones(len(ineq))
    k = int(fu.sum())
    zu[fu], su[fu] = z[:k], s[:k]
    zl[fl], sl[fl] = z[k:], s[k:]
    guess[ineq] = np.where(zu > su, 1, np.where(zl > sl, -1, 0))
    # ``lower``: the objective of the iterate less its complementarity gap, a lower bound on
    # the optimum's (to the iterate's residuals, < 1e-8); ``primal``: that iterate's w.
    return guess, it, lower, primal


def _orth(vectors: list[np.ndarray], dim: int) -> np.ndarray:
    """An orthonormal basis (columns) of the span of `vectors` (unit-normalised first)."""
    if not vectors:
        return np.zeros((dim, 0))
    A = np.array([v / np.linalg.norm(v) for v in vectors]).T
    u, sv, _ = np.linalg.svd(A, full_matrices=False)
    return u[:, sv > DEPENDENT * sv[0]]


def _outside(basis: np.ndarray, v: np.ndarray) -> bool:
    """`v` is not (to `DEPENDENT`) in the span of the orthonormal columns of `basis`."""
    v = v / np.linalg.norm(v)
    return bool(np.linalg.norm(v - basis @ (basis.T @ v)) > DEPENDENT)


def _independent_rows(g: _Grid, rows: list[TickRow], active: np.ndarray) -> np.ndarray:
    """Drop from `active` each row that is a combination of the rows before it (in time;
    equal bounds first at a tick) and of x0: its value is then fixed by them, and the KKT
    matrix would be singular. Along an arc where a position stays at its bound between ticks
    too, its values at the ticks and the middle Bernstein coefficients fix zero speed and zero
    command, so every other row there is implied.

    A forward sweep finds them exactly, in O(ticks n^3): ``V_j``, the functionals ``c`` of the
    mean ``m_j`` whose value ``c'm_j`` is a combination of the rows so far and x0 (``V_0`` is
    all of R^n). A row at tick j is dependent iff ``c`` is in ``V_j`` (then the row is
    dropped, else ``V_j`` grows by it). In the coordinates ``(m_j, d_j)`` of tick j,
    ``S_j = V_j x {0} + span(rows between ticks j and j+1 taken)``, and since
    ``m_{j+1} = Acl_j m_j - Fu_j d_j + const``, ``V_{j+1} = {c : (Acl_j'c, -Fu_j'c) in S_j}``
    (the d-part of a combination can only come from rows of that tick)."""
    out = active.copy()
    n, m = g.n, g.m
    by_tick: dict[int, list[int]] = {}
    for i in sorted(np.flatnonzero(active), key=lambda i: (rows[i].tick, rows[i].cd is not None,
                                                           rows[i].lower != rows[i].upper, i)):
        by_tick.setdefault(rows[i].tick, []).append(i)
    V = np.eye(n)                              # m_0 = x0: every functional is fixed
    for j in range(g.T + 1):
        for i in by_tick.get(j, []):
            if rows[i].cd is None:
                if _outside(V, rows[i].c):
                    V = _orth(list(V.T) + [rows[i].c], n)
                else:
                    out[i] = 0
        if j == g.T:
            break
        # S_j, with the d-part scaled by the tick's input gain (|Fu| ~ h^2 for a position):
        # dependence does not depend on the scale of d, the tolerance does.
        sd = max(float(np.abs(g.Fu[j]).max()), 1e-300)
        S = [np.concatenate([v, np.zeros(m)]) for v in V.T]
        for i in by_tick.get(j, []):
            if rows[i].cd is not None:
                v = np.concatenate([rows[i].c, rows[i].cd / sd])
                if not S or _outside(_orth(S, n + m), v):
                    S.append(v)
                else:
                    out[i] = 0
        Sb = _orth(S, n + m)
        # V_{j+1}: the null space of (I - Sb Sb') [Acl_j'; -Fu_j' / sd] (n + m x n).
        Mj = np.vstack([g.Acl[j].T, -g.Fu[j].T / sd])
        R = Mj - Sb @ (Sb.T @ Mj)
        _, sv, vt = np.linalg.svd(R)
        scale = max(float(np.abs(Mj).max()), 1e-300)
        rank = int(np.sum(sv > DEPENDENT * scale))
        V = vt[rank:].T
    return out


def _lu(M):
    """SuperLU of the sparse matrix M. SuperLU reports running out of memory (or past its
    32-bit sizes) as MemoryError, SystemError or a RuntimeError from its malloc: that is a
    BudgetError naming tick_hz (one line, exit status 2), not a traceback; any other
    RuntimeError (a singular matrix) is the caller's."""
    from scipy.sparse.linalg import splu
    from stospline.errors import BudgetError
    try:
        return splu(M)
    except (MemoryError, SystemError, RuntimeError) as exc:
        text = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        if isinstance(exc, RuntimeError) and "malloc" not in text.lower():
            raise
        raise BudgetError("tick_hz", f"the tick-grid QP's sparse LU ({M.shape[0]} rows, "
                                     f"{M.nnz} nonzeros) ran out of memory ({text}): lower "
                                     f"tick_hz or shorten the regions at every tick") from None


def _kkt(g: _Grid, active: np.ndarray):
    """LU of the KKT matrix of the equality rows and the active rows (at their bounds)."""
    from scipy import sparse
    idx = np.flatnonzero(active)
    Ea = sparse.vstack([g.E, g.C[idx]], format="csc")
    # The active rows' block is regularised by -KKT_REGULARIZATION: rows that depend on others
    # through the dynamics (along an arc where a position stays at its bound, its values at the
    # ticks and the middle coefficients between them fix more than the commands can) then share
    # their multiplier instead of making the matrix singular, and the correction loop drops
    # the ones whose share has the wrong sign. Independent rows move by ~1e-14.
    reg = sparse.diags(np.concatenate([np.zeros(g.n_eq), np.full(idx.size,
                                                                 -KKT_REGULARIZATION)]))
    M = sparse.bmat([[g.P, Ea.T], [Ea, reg]], format="csc")
    try:
        return _Refined(_lu(M), sparse.bmat([[g.P, Ea.T], [Ea, None]], format="csr")), idx
    except RuntimeError:
        raise DesignError("regions", "the active constraint rows of the tick-grid QP are "
                                     "linearly dependent (contradictory bands?)") from None


class _Refined:
    """Solves with the regularised LU, then two steps of iterative refinement against the
    unregularised KKT matrix: what the regularisation moved (~1e-13 of the multipliers) comes
    back out, so that a table entry whose exact value is 0 lands below the float32 flush
    (`stospline.table.format`) on every machine."""

    def __init__(self, lu, exact):
        self.lu, self.exact = lu, exact

    def solve(self, b: np.ndarray) -> np.ndarray:
        z = self.lu.solve(b)
        for _ in range(2):
            z = z + self.lu.solve(b - self.exact @ z)
        return z


def _solve(lu, g: _Grid, idx, active, rhs_eq):
    bound = np.where(active[idx] > 0, g.hi[idx], g.lo[idx])
    z = lu.solve(np.concatenate([np.zeros(g.nv), rhs_eq, bound]))
    return z[:g.nv], z[g.nv:]


def design_tick_qp(problem: Problem, *, noise: bool = True,
                   tick_hz: int | None = None, tighten=None) -> TickQPDesign:
    """The joint exact-zero-order-hold design meeting the knots' constraints and every tick
    region at every tick, as one sparse QP on the tick grid (module docstring).

    `tighten`, optional: a function of a band row (`TickRow` of kind "knot" or "region"
    whose bounds differ) returning ``(up, down)`` >= 0, how far its mean may rise and fall
    elsewhere (`stospline.oracle.over_box`); the QP then keeps it within ``[lower + down,
    upper - up]``.

    Raises DesignError (naming ``regions`` or a stage) when the QP has no solution, its
    active set does not settle in `MAX_ROUNDS` corrections, or a stage's data vary in
    time."""
    start = time.perf_counter()
    for k, kn in enumerate(problem.knots):
        # Dependent equality rows make the QP's equality block singular: named, as for the
        # other designs (`check_latch`), before any factorisation.
        if kn.constraint is not None and not kn.constraint.is_band:
            check_rows(kn.constraint.C, k)
    tick_hz = problem.tick_hz if tick_hz is None else int(tick_hz)
    K, ks, H, F, stage_of, V0 = _backward(problem, tick_hz, noise)
    rows = _rows(problem, tick_hz, K, ks, stage_of)
    if tighten is not None:
        rows = [_tightened(r, tighten) for r in rows]
    g = _Grid(problem, K, ks, H, F, stage_of, rows)
    x0 = np.asarray(problem.x0, float)
    eq = g.lo == g.hi
    scale = np.maximum(1.0, np.maximum(np.abs(g.lo + g.offset), np.abs(g.hi + g.offset)))
    active, iters, lower, primal = _interior_point(g, x0, eq)
    guess = active.copy()
    gap = 0.0
    rounds = 0
    for rounds in range(1, MAX_ROUNDS + 1):
        active = _independent_rows(g, rows, active)
        lu, idx = _kkt(g, active)
        w, y = _solve(lu, g, idx, active, g.rhs(x0))
        mult = np.zeros(len(rows))
        mult[idx] = y[g.n_eq:]
        val = g.C @ w
        beyond = np.maximum(val - g.hi, g.lo - val) > TOLERANCE * scale
        # Sign: an upper row's multiplier is >= 0, a lower row's <= 0 (P w + E'y = 0).
        ytol = 1e-10 * max(1.0, float(np.abs(mult).max()) if mult.size else 0.0)
        wrong = (~eq) & (active != 0) & (active * mult < -ytol)
        add = beyond & (active == 0)
        if not add.any() and not wrong.any():
            break
        # Degenerate rows (an arc held between ticks: the rows at its bound are dependent
        # through the dynamics) need not have multipliers of the right sign on the subset
        # kept; the interior point's nonnegative ones certify instead: a feasible point whose
        # objective is within OPTIMALITY of the lower bound is the optimum to that much.
        if not add.any() and 0.5 * float(w @ (g.P @ w)) <= lower + OPTIMALITY * abs(lower):
            gap = max(0.0, 0.5 * float(w @ (g.P @ w)) - lower)
            break
        active = np.where(add, np.where(val > g.hi, 1, -1), active)
        active[wrong] = 0
    else:
        # Degenerate rows can keep the corrections from settling (a band that a knot's
        # equality touches between ticks leaves no strictly feasible point there). The
        # interior point's own iterate is feasible to its residuals (< 1e-8; the oracle checks
        # every row again) and optimal to its duality gap, which the design reports; the
        # affine map in x0 is that of its active-set guess.
        if primal is None:
            raise DesignError("regions", f"the tick-grid QP's active set did not settle in "
                                         f"{MAX_ROUNDS} corrections, and the interior point "
                                         f"did not reach a feasible iterate")
        w = primal
        active = _independent_rows(g, rows, guess)
        lu, idx = _kkt(g, active)
        mult = np.zeros(len(rows))
        val = g.C @ w
        gap = max(0.0, 0.5 * float(w @ (g.P @ w)) - lower)
    # The affine map of the active set: d(x0) = d_c + D x0 (one solve per state component).
    delta = g.offsets(w)
    D = np.empty((g.T, g.m, g.n))
    for i in range(g.n):
        e = np.zeros(len(g.dyn_rhs)); e[i] = 1.0
        z = lu.solve(np.concatenate([np.zeros(g.nv), e, np.zeros(len(idx))]))
        D[:, :, i] = g.offsets(z[:g.nv])
    z = np.append(x0, 1.0)
    J0 = float(z @ V0 @ z + np.einsum("ti,tij,tj->", delta, H, delta))
    return TickQPDesign(problem, tick_hz, K, ks, H, delta, D, V0, J0, rows, active, mult,
                        np.asarray(val) + g.offset, rounds, iters, time.perf_counter() - start,
                        optimality_gap=gap,
                        noise_aware=noise,
                        stats={"variables": g.nv, "rows": len(rows),
                               "equalities": g.n_eq})
