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

The table latches the state at t0: ``d = d_c + D x0`` is affine in ``x0`` for the optimal
active set, so ``k0_j = k*_j + d_c,j`` and ``L_j = D_j`` with ``v = x(t0)``. Exact for the design's
``x0`` and every start with the same active set (as a band design with more rows than the
firmware's band solver takes).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from stospline.design.stage_values import knot_terminal
from stospline.design.zoh import _stage_ticks_numpy, _tick_data
from stospline.errors import DesignError
from stospline.problem.model import Problem, ticks_per_stage

__all__ = ["TickRow", "TickQPDesign", "design_tick_qp"]

# Exact corrections of the interior-point guess of the active set, and its iterations.
MAX_ROUNDS = 50
IPM_MAX_ITERATIONS = 80
# The interior point stops at a mean complementarity s'z / rows below this (times the bounds'
# scale): tight enough that the rows it calls active are the optimum's but for a few at the
# ends of arcs (robot at 1 kHz: none to 3 corrections left for the exact loop).
IPM_MU = 1e-17
# A row is beyond its band when it is out by more than this times max(1, |bounds|): the exact
# KKT solve meets its active rows to ~1e-13 of that scale.
TOLERANCE = 1e-9


@dataclass(frozen=True)
class TickRow:
    """One constraint row on the mean at a tick: ``lower <= c' E{x_tick} <= upper``."""
    tick: int
    kind: str            # "knot" or "region"
    index: int           # the knot's index, or the region's place in the file's [[regions]]
    row: int
    c: np.ndarray
    lower: float
    upper: float


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
                            "active_region_rows": int(sum(1 for r, a in zip(self.rows,
                                                          self.active)
                                                          if r.kind == "region" and a != 0)),
                            "arcs": self.arcs()}}
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
            raise DesignError(f"stages[{k}]", "a region at every tick is designed on the tick "
                                              "grid for time-invariant stage data only")
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


def _rows(problem: Problem, tick_hz: int) -> list[TickRow]:
    """Every constraint row, ordered by tick: the knots' rows, then the regions'."""
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
    rows.sort(key=lambda r: (r.tick, r.kind != "knot", r.index, r.row))
    return rows


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
        self.E = sparse.csr_matrix((np.concatenate(v_i), (np.concatenate(r_i),
                                                          np.concatenate(c_i))),
                                   shape=(self.n_eq, self.nv))
        self.C = sparse.csr_matrix((vv, (rr, cc)), shape=(q, self.nv))
        self.lo = np.array([r.lower for r in rows])
        self.hi = np.array([r.upper for r in rows])
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


def _interior_point(g: _Grid, x0, eq: np.ndarray) -> tuple[np.ndarray, int]:
    """A guess of the active set (+1 upper, -1 lower per constraint row) from a primal-dual
    interior-point method (Mehrotra's predictor-corrector) on the QP. Each iteration solves
    one sparse system of the KKT matrix's pattern, ``[[P + C' diag(z/s) C, E'], [E, 0]]``
    (banded in time), and their number hardly grows with the ticks (about 30), where ADMM's
    grew with the horizon (OSQP: 2 700 iterations at 1 kHz, 12 100 at 2 kHz on the robot).
    The rows with a bound (``lower < upper``) are ``G w <= h``, ``G = [C; -C]``; the knots'
    equalities join ``E``. The exact KKT loop corrects the guess."""
    from scipy import sparse
    from scipy.sparse.linalg import splu
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
        return guess, 0

    def solve(wdiag, r1, r2):
        M = sparse.bmat([[P + G.T @ sparse.diags(wdiag) @ G, E.T], [E, None]], format="csc")
        return splu(M).solve(np.concatenate([r1, r2]))

    # Start: the equality-constrained optimum, slacks pushed inside.
    z0 = solve(np.zeros(ni), np.zeros(nv), b)
    w, y = z0[:nv], z0[nv:]
    scale = max(1.0, float(np.abs(h).max()))
    s = np.maximum(h - G @ w, 1e-2 * scale)
    z = np.ones(ni)
    it = 0
    for it in range(1, IPM_MAX_ITERATIONS + 1):
        rd = P @ w + E.T @ y + G.T @ z
        re = E @ w - b
        ri = G @ w + s - h
        mu = float(s @ z) / ni
        if (mu < IPM_MU * scale and np.abs(ri).max() < 1e-10 * scale
                and np.abs(re).max() < 1e-10 * scale):
            break
        wd = z / s
        M = sparse.bmat([[P + G.T @ sparse.diags(wd) @ G, E.T], [E, None]], format="csc")
        lu = splu(M)

        def step(rc):
            r1 = -rd + G.T @ ((rc - z * ri) / s)
            sol = lu.solve(np.concatenate([r1, -re]))
            dw, dy = sol[:nv], sol[nv:]
            ds = -ri - G @ dw
            dz = (-rc - z * ds) / s
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
    # Active where the multiplier outweighs the slack.
    zu, zl = np.zeros(len(ineq)), np.zeros(len(ineq))
    su, sl = np.ones(len(ineq)), np.ones(len(ineq))
    k = int(fu.sum())
    zu[fu], su[fu] = z[:k], s[:k]
    zl[fl], sl[fl] = z[k:], s[k:]
    guess[ineq] = np.where(zu > su, 1, np.where(zl > sl, -1, 0))
    return guess, it


def _independent_rows(rows: list[TickRow], active: np.ndarray) -> np.ndarray:
    """Drop from `active` each row that depends on the rows taken before it at its tick
    (equal bounds first): its value is then fixed by them, and the KKT matrix would be
    singular."""
    out = active.copy()
    taken: dict[int, list[np.ndarray]] = {}
    order = sorted(np.flatnonzero(active), key=lambda i: (rows[i].tick,
                                                          rows[i].lower != rows[i].upper, i))
    for i in order:
        c = rows[i].c / np.linalg.norm(rows[i].c)
        have = taken.setdefault(rows[i].tick, [])
        if have:
            basis = np.array(have).T
            c_out = c - basis @ np.linalg.lstsq(basis, c, rcond=None)[0]
        else:
            c_out = c
        if np.linalg.norm(c_out) > 1e-8:
            have.append(c)
        else:
            out[i] = 0
    return out


def _kkt(g: _Grid, active: np.ndarray):
    """LU of the KKT matrix of the equality rows and the active rows (at their bounds)."""
    from scipy import sparse
    from scipy.sparse.linalg import splu
    idx = np.flatnonzero(active)
    Ea = sparse.vstack([g.E, g.C[idx]], format="csc")
    k = Ea.shape[0]
    M = sparse.bmat([[g.P, Ea.T], [Ea, None]], format="csc")
    try:
        return splu(M), idx, k
    except RuntimeError:
        raise DesignError("regions", "the active constraint rows of the tick-grid QP are "
                                     "linearly dependent (contradictory bands?)") from None


def _solve(lu, g: _Grid, idx, k, active, rhs_eq):
    bound = np.where(active[idx] > 0, g.hi[idx], g.lo[idx])
    z = lu.solve(np.concatenate([np.zeros(g.nv), rhs_eq, bound]))
    return z[:g.nv], z[g.nv:]


def design_tick_qp(problem: Problem, *, noise: bool = True,
                   tick_hz: int | None = None) -> TickQPDesign:
    """The joint exact-zero-order-hold design meeting the knots' constraints and every tick
    region at every tick, as one sparse QP on the tick grid (module docstring).

    Raises DesignError (naming ``regions`` or a stage) when the QP has no solution, its
    active set does not settle in `MAX_ROUNDS` corrections, or a stage's data vary in
    time."""
    start = time.perf_counter()
    tick_hz = problem.tick_hz if tick_hz is None else int(tick_hz)
    K, ks, H, F, stage_of, V0 = _backward(problem, tick_hz, noise)
    rows = _rows(problem, tick_hz)
    g = _Grid(problem, K, ks, H, F, stage_of, rows)
    x0 = np.asarray(problem.x0, float)
    eq = g.lo == g.hi
    scale = np.maximum(1.0, np.maximum(np.abs(g.lo), np.abs(g.hi)))
    active, iters = _interior_point(g, x0, eq)
    rounds = 0
    for rounds in range(1, MAX_ROUNDS + 1):
        active = _independent_rows(rows, active)
        lu, idx, k = _kkt(g, active)
        w, y = _solve(lu, g, idx, k, active, g.rhs(x0))
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
        active = np.where(add, np.where(val > g.hi, 1, -1), active)
        active[wrong] = 0
    else:
        raise DesignError("regions", f"the tick-grid QP's active set did not settle in "
                                     f"{MAX_ROUNDS} corrections of the interior-point guess")
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
                        np.asarray(val), rounds, iters, time.perf_counter() - start,
                        noise_aware=noise,
                        stats={"variables": g.nv, "rows": len(rows),
                               "equalities": g.n_eq})
