"""Design-time benchmark and accuracy check of the exact zero-order-hold designer.

Usage: .venv/bin/python tools/bench/zoh_design.py [--repeat 5]

Every time is the median of `--repeat` runs (3 for the runs that take seconds) measured with
``time.perf_counter`` after one warm-up run (which also builds the cached C kernel), on one
core: BLAS threads are pinned to 1 before numpy is imported. Figures are in docs/evidence/performance.md.

Problems
--------
robot   examples/robot_corridor.toml: n = 4, m = 2, 2 stages over 6 s, 6000 ticks at 1 kHz.
chain12 built by `chain12()` below (seeded): four 3-state blocks (position, velocity,
        first-order actuator) coupled by springs, n = 12, m = 4, multiplicative noise on the
        four velocities (two Brownian components), 20 stages of 0.5 s (knots every 0.5 s),
        10 000 ticks at 1 kHz. Every 5th knot constrains the four expected positions, the
        others penalise them; every stage has its own input weight R, so all 20 stages have
        distinct data (no tick-map reuse: the worst case).

Accuracy
--------
The exact-ZOH design has no tolerance parameter: the tick maps are matrix exponentials
(`scipy.linalg.expm`, double precision) and the recursion is exact algebra, so its error is
rounding. It is measured against a reference computed entirely in extended precision
(x87 long double, eps 1.1e-19): the same mathematics (packed adjoint moment map, backward
tick recursion, knot jumps and latches) with the tick maps from a Taylor series with scaling
and squaring instead of expm, and every solve by Cholesky in long double. Reported: the
relative error of the predicted optimal cost J0 and the largest error of the gains K, k0, L
over all ticks, each relative to that gain's largest magnitude. Documented tolerance (also the
pass mark printed): J0 and gains within 1e-12 relative of the reference. For the robot, the
exact oracle (forward moment propagation of the designed law, `oracle.evaluate_table`) is also
compared with the predicted J0, and the continuous-time design (DOP853, rtol 1e-12 - its
default) with a much tighter one (rtol 3e-14, atol 1e-18).

Baseline
--------
"scipy baseline": a straightforward implementation of the SAME exact-ZOH quantities. Per
distinct stage data, the tick maps are obtained by integrating the moment equations over one
tick with `scipy.integrate.solve_ivp` instead of a matrix exponential: the adjoint moment ODE
``dY/ds = gen' Y`` on full d^2 vectors for the (n+1)^2 columns that act on the value, the
running-cost integral ``dy/ds = gen' y + vec(Lbar)``, and the mean map ``dX/ds = Ahat X``; then
the per-tick recursion is the plain numpy loop (`design_zoh._stage_ticks_numpy`, the
reference implementation kept in the package). Knot jumps and latches are the designer's own.
Its setting is the fastest of rtol in {1e-6, 1e-8, 1e-10, 1e-12, 1e-13} (atol = rtol/100)
with RK45 or DOP853 whose J0 and gain errors against the same reference are within a factor
2 of ours (equal accuracy up to the run-to-run variation of rounding); if none is, the most
accurate one is used and the speed-up is a lower bound. Its errors are measured with the
recursion in C (the two loops agree to ~1e-14) and its time with the numpy loop. At 1 kHz
one tick is so short that every tolerance gives tick maps exact to rounding; the baseline's
cost is the per-tick Python loop plus the integration.

"previous": a reference implementation timed for comparison: the Van Loan 2d^2-square
exponential per distinct stage (`moments.exact_tick`) and the numpy tick loop.
"""
from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse                                     # noqa: E402
import time                                         # noqa: E402
from pathlib import Path                            # noqa: E402

import numpy as np                                  # noqa: E402
from scipy.integrate import solve_ivp               # noqa: E402

from stospline.design import zoh as dz              # noqa: E402
from stospline.design import tick_reference                # noqa: E402
from stospline.design.continuous import design_continuous   # noqa: E402
from stospline.design.stage_values import knot_terminal      # noqa: E402
from stospline.design.kernels import load_kernels          # noqa: E402
from stospline.design.moments import (augmented_drift, moment_generator,  # noqa: E402
                               running_cost_matrix)
from stospline.design.latch import latch_groups      # noqa: E402
from stospline.oracle.evaluate import evaluate_table         # noqa: E402
from stospline.problem import load_problem, parse_problem   # noqa: E402
from stospline.problem.model import ticks_per_stage        # noqa: E402
from stospline.table.format import table_of                # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
LD = np.longdouble
TOL = 1e-12
EQUAL = 2.0      # "equal accuracy": errors within this factor of ours (rounding varies so much)


def chain12(seed: int = 7, hz: int = 1000):
    """The 12-state, 4-input, 20-stage benchmark problem (see the module docstring)."""
    rng = np.random.default_rng(seed)
    n, m = 12, 4
    A, B = np.zeros((n, n)), np.zeros((n, m))
    for b in range(4):
        i = 3 * b
        A[i, i + 1] = 1.0                              # position' = velocity
        A[i + 1, i + 2] = 1.0                          # velocity' = actuator - damping
        A[i + 1, i + 1] = -rng.uniform(0.1, 0.5)
        a = rng.uniform(2.0, 5.0)                      # actuator' = a (u - actuator)
        A[i + 2, i + 2], B[i + 2, b] = -a, a
        if b:                                          # spring to the previous block
            k = rng.uniform(0.2, 1.0)
            A[i + 1, i - 3] += k; A[i + 1, i] -= k
            A[i - 2, i] += k; A[i - 2, i - 3] -= k
    noise = []
    for b in range(4):
        G = np.zeros((n, 2))
        G[3 * b + 1, b % 2] = rng.uniform(0.2, 0.5)
        noise.append({"state": 3 * b + 1, "G": G.tolist()})
    C = np.zeros((4, n))
    C[np.arange(4), 3 * np.arange(4)] = 1.0
    knots = []
    for k in range(20):
        target = rng.normal(size=4).tolist()
        if k % 5 == 4:
            knots.append({"t": 0.5 * (k + 1), "constraint": {"C": C.tolist(), "value": target}})
        else:
            knots.append({"t": 0.5 * (k + 1), "penalty": {"C": C.tolist(), "target": target,
                                                          "weight": 10.0}})
    return parse_problem({
        "name": "chain12", "x0": rng.normal(size=n).tolist(), "tick_hz": hz,
        "dynamics": {"A": A.tolist(), "B": B.tolist(), "noise": noise},
        "cost": {"R": (0.1 * np.eye(m)).tolist(), "Q": (0.01 * np.eye(n)).tolist()},
        "stages": [{"cost": {"R": (0.1 * (1 + 0.05 * k) * np.eye(m)).tolist()}}
                   for k in range(20)],
        "knots": knots})


def median_time(fn, repeat: int) -> float:
    fn()                                               # warm-up
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return float(np.median(times))


# ---- extended-precision reference ------------------------------------------------------

def van_loan_tick_data(stage, h):
    """The tick data as the package computed them before the packed exponential."""
    A2, Hc, F = tick_reference.van_loan_tick_data(stage, h)
    return dz._TickData(np.ascontiguousarray(A2), Hc, F, np.zeros((0, 0)), np.zeros(0))


def previous(problem, hz, mode="stagewise"):
    real = dz._tick_data
    dz._tick_data = van_loan_tick_data
    try:
        return dz.design_zoh(problem, hz, mode=mode, kernel="numpy")
    finally:
        dz._tick_data = real


def _ld_expm(M):
    """exp(M) in long double: Taylor series after scaling to norm <= 1/8, then squaring."""
    nrm = float(np.abs(M).sum(axis=1).max())
    s = max(0, int(np.ceil(np.log2(nrm / 0.125)))) if nrm > 0 else 0
    A = M / LD(2.0) ** s
    E = np.eye(M.shape[0], dtype=LD)
    term = E.copy()
    for k in range(1, 40):
        term = term @ A / LD(k)
        E = E + term
        if np.abs(term).max() <= np.finfo(LD).eps * np.abs(E).max() * 1e-3:
            break
    for _ in range(s):
        E = E @ E
    return E


def _ld_cho_solve(A, B):
    """Solve A X = B for symmetric positive definite A (long double, Cholesky)."""
    k = A.shape[0]
    Lc = np.zeros((k, k), dtype=LD)
    for i in range(k):
        for j in range(i + 1):
            s = A[i, j] - Lc[i, :j] @ Lc[j, :j]
            Lc[i, j] = np.sqrt(s) if i == j else s / Lc[j, j]
    Y = np.array(B, dtype=LD)
    for i in range(k):
        Y[i] = (Y[i] - Lc[i, :i] @ Y[:i]) / Lc[i, i]
    for i in range(k - 1, -1, -1):
        Y[i] = (Y[i] - Lc[i + 1:, i] @ Y[i + 1:]) / Lc[i, i]
    return Y


def _ld_tick_data(stage, h):
    n, m = stage.B.shape
    d = n + m + 1
    Ahat = augmented_drift(stage, m + 1).astype(LD)
    GH = stage.noise_tensor.astype(LD)
    noise_t = np.zeros((d, d, d, d), dtype=LD)      # Pi(H)_ij = tr(Gbar_i' H Gbar_j)
    noise_t[:n + m, :n + m, :n, :n] = np.einsum("iak,jbk->ijab", GH, GH)
    eye = np.eye(d, dtype=LD)
    gen_t = noise_t.reshape(d * d, d * d) + np.kron(Ahat.T, eye) + np.kron(eye, Ahat.T)
    iu, ju = np.triu_indices(d)
    ds = iu.size
    pos = np.empty((d, d), dtype=np.intp)
    pos[iu, ju] = pos[ju, iu] = np.arange(ds)
    rows = gen_t[iu * d + ju]
    big = np.zeros((ds + 1, ds + 1), dtype=LD)
    big[:ds, :ds] = (rows[:, iu * d + ju] + (iu != ju) * rows[:, ju * d + iu]) * LD(h)
    big[:ds, ds] = running_cost_matrix(stage, n, m, d, n).astype(LD)[iu, ju] * LD(h)
    E = _ld_expm(big)
    rs = np.r_[0:n, d - 1]
    ia, ib = np.triu_indices(n + 1)
    F = _ld_expm(Ahat * LD(h))[:n]
    return E[:ds, pos[rs[ia], rs[ib]]], E[:ds, ds], F, pos


def reference_design(problem, hz: int, mode: str):
    """J0 and per-stage (K, k0, L) of the exact ZOH design, all in long double."""
    counts = ticks_per_stage(problem, hz)
    h = 1.0 / hz
    n, m = problem.n, problem.m
    d = n + m + 1
    us, rs = np.arange(n, n + m), np.r_[0:n, d - 1]
    ia, ib = np.triu_indices(n + 1)
    _, group_of = latch_groups(problem, mode)
    cache = {}
    V = np.zeros((n + 1, n + 1), dtype=LD)
    N = W = mv = None
    gains = [None] * len(problem.knots)
    for k in range(len(problem.knots) - 1, -1, -1):
        knot, g, stage = problem.knots[k], group_of[k], problem.stages[k]
        PT, pT, cT = knot_terminal(knot, V[:n, :n], V[:n, n], V[n, n])
        V = np.zeros((n + 1, n + 1), dtype=LD)
        V[:n, :n], V[:n, n], V[n, :n], V[n, n] = PT, pT, pT, cT
        q = 0 if g is None else g.size
        if g is not None:
            if N is None or N.shape[1] != q:
                N, W, mv = (np.zeros(s, dtype=LD) for s in ((n, q), (q, q), (q,)))
            if knot.n_constraints:
                o = g.offset_of(k)
                N[:, o:o + knot.n_constraints] += knot.constraint.C.T
                mv[o:o + knot.n_constraints] -= knot.constraint.value
        else:
            N, W, mv = (np.zeros(s, dtype=LD) for s in ((n, 0), (0, 0), (0,)))
        key = dz._stage_key(stage, h)
        if key not in cache:
            cache[key] = _ld_tick_data(stage, h)
        A2s, hcs, F, pos = cache[key]
        T = int(counts[k])
        K, k0, L = (np.empty(s, dtype=LD) for s in ((T, m, n), (T, m), (T, m, q)))
        for j in range(T - 1, -1, -1):
            H = (A2s @ V[ia, ib] + hcs)[pos]
            Hl = N.T @ F
            Hl[:, -1] += mv
            Hur, Hlu = H[np.ix_(us, rs)], Hl[:, us]
            G = _ld_cho_solve(H[np.ix_(us, us)], np.hstack([Hur, Hlu.T]))
            Gr, Gl = G[:, :n + 1], G[:, n + 1:]
            K[j], k0[j], L[j] = Gr[:, :n], Gr[:, n], Gl
            V = H[np.ix_(rs, rs)] - Hur.T @ Gr
            V = (V + V.T) / 2
            Hlr = Hl[:, rs] - Hlu @ Gr
            N, mv = Hlr[:, :n].T.copy(), Hlr[:, n].copy()
            W = W + Hlu @ Gl
            W = (W + W.T) / 2
        gains[k] = (K, k0, L)
        if g is not None and g.latch_stage == k:
            lam = _ld_cho_solve(W, np.hstack([N.T, mv[:, None]]))
            Lam, lam0 = lam[:, :n], lam[:, n]
            NL = N @ Lam
            V[:n, :n] += (NL + NL.T) / 2
            V[:n, n] += N @ lam0
            V[n, :n] = V[:n, n]
            V[n, n] += mv @ lam0
            N = W = mv = None
    x0 = problem.x0.astype(LD)
    J0 = x0 @ V[:n, :n] @ x0 + 2 * V[:n, n] @ x0 + V[n, n]   # the latch is folded into V
    return J0, gains


def errors(design, ref):
    """(relative J0 error, largest relative gain error) of a design against the reference."""
    J0, gains = ref
    e_j = float(abs(LD(design.J0) - J0) / abs(J0))
    e_g = 0.0
    for st, (K, k0, L) in zip(design.stages, gains):
        for a, b in ((st.K, K), (st.k0, k0), (st.L, L)):
            if b.size:
                scale = float(np.abs(b).max()) or 1.0
                e_g = max(e_g, float(np.abs(a.astype(LD) - b).max()) / scale)
    return e_j, e_g


# ---- the solve_ivp baseline ------------------------------------------------------------

def ivp_tick_data(stage, h, rtol, method):
    """Tick data by integrating the moment equations over one tick with solve_ivp."""
    n, m = stage.B.shape
    d = n + m + 1
    D = d * d
    Ahat = augmented_drift(stage, m + 1)
    gen_t = moment_generator(Ahat, stage.noise_tensor).T
    rs = np.r_[0:n, d - 1]
    idx = (rs[:, None] * d + rs[None, :]).ravel()
    lbar = running_cost_matrix(stage, n, m, d, n).ravel()
    cols = idx.size + 1
    y0 = np.zeros((D, cols))
    y0[idx, np.arange(idx.size)] = 1.0
    forcing = np.zeros((D, cols))
    forcing[:, -1] = lbar

    def rhs(_s, y):
        return (gen_t @ y.reshape(D, cols) + forcing).ravel()

    sol = solve_ivp(rhs, (0.0, h), y0.ravel(), method=method, rtol=rtol, atol=rtol / 100)
    Y = sol.y[:, -1].reshape(D, cols)
    A2, Hc = Y[:, :-1], Y[:, -1].reshape(d, d)
    Hc = 0.5 * (Hc + Hc.T)
    solF = solve_ivp(lambda _s, y: (Ahat @ y.reshape(d, d)).ravel(), (0.0, h),
                     np.eye(d).ravel(), method=method, rtol=rtol, atol=rtol / 100)
    F = solF.y[:, -1].reshape(d, d)[:n]
    # Packed forms, so the same tick maps can also drive the C recursion (for its errors).
    iu, ju = np.triu_indices(d)
    ia, ib = np.triu_indices(n + 1)
    A4 = A2.reshape(d, d, n + 1, n + 1)
    Hs = 0.5 * (A4 + A4.transpose(1, 0, 2, 3))[iu, ju]          # (ds, n+1, n+1)
    A2s = Hs[:, ia, ib] + (ia != ib) * Hs[:, ib, ia]
    return dz._TickData(np.ascontiguousarray(A2), Hc, F, np.ascontiguousarray(A2s.T),
                        Hc[iu, ju].copy())


class _SwapTickData:
    """Run `design_zoh` with solve_ivp tick maps (its outer loop is unchanged); `maps`:
    precomputed maps by stage key, else each is integrated when the designer asks."""

    def __init__(self, rtol, method, maps=None):
        self.rtol, self.method, self.maps, self.real = rtol, method, maps, dz._tick_data

    def __enter__(self):
        if self.maps is not None:
            dz._tick_data = lambda stage, h: self.maps[dz._stage_key(stage, h)]
        else:
            dz._tick_data = lambda stage, h: ivp_tick_data(stage, h, self.rtol, self.method)

    def __exit__(self, *exc):
        dz._tick_data = self.real


def baseline(problem, hz, mode, rtol, method, kernel="numpy", maps=None):
    with _SwapTickData(rtol, method, maps):
        return dz.design_zoh(problem, hz, mode=mode, kernel=kernel)


def compare_baseline(name, problem, hz, mode, ours_time, ours_err, ref, repeat):
    print(f"\n-- {name}: exact ZOH at {hz} Hz ({mode}) against the solve_ivp baseline")
    print(f"   {'tick maps':<22}{'J0 rel. error':>15}{'gain rel. error':>17}"
          f"{'tick maps [s]':>15}")
    print(f"   {'ours: packed expm':<22}{ours_err[0]:>15.1e}{ours_err[1]:>17.1e}")
    h = 1.0 / hz
    distinct = {dz._stage_key(s, h): s for s in problem.stages}
    rows = []
    for method in ("RK45", "DOP853"):
        for rtol in (1e-6, 1e-8, 1e-10, 1e-12, 1e-13):
            t = time.perf_counter()
            maps = {key: ivp_tick_data(st, h, rtol, method) for key, st in distinct.items()}
            t_maps = time.perf_counter() - t
            err = errors(baseline(problem, hz, mode, rtol, method, kernel="c", maps=maps), ref)
            rows.append((method, rtol, err, t_maps))
            print(f"   {f'{method} rtol {rtol:.0e}':<22}{err[0]:>15.1e}{err[1]:>17.1e}"
                  f"{t_maps:>15.3f}")
    ok = [r for r in rows if r[2][0] <= EQUAL * ours_err[0] and r[2][1] <= EQUAL * ours_err[1]]
    if ok:
        method, rtol, err, _ = min(ok, key=lambda r: r[3])
        note = "reaches our accuracy"
    else:
        method, rtol, err, _ = min(rows, key=lambda r: max(r[2]))
        note = (f"no setting reaches our accuracy; its best is {max(err) / max(ours_err):.0f}x "
                f"less accurate, so the speed-up is a lower bound")
    t_base = median_time(lambda: baseline(problem, hz, mode, rtol, method), repeat)
    print(f"   baseline = {method} rtol {rtol:.0e} + numpy tick loop ({note})")
    print(f"   baseline {t_base:.3f} s, ours {ours_time * 1e3:.1f} ms: "
          f"speed-up {t_base / ours_time:.0f}x")
    return t_base


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    rep, slow = args.repeat, max(1, min(args.repeat, 3))
    t_start = time.perf_counter()
    t = time.perf_counter()
    load_kernels()
    print(f"C kernel ready ({time.perf_counter() - t:.2f} s: build, or load from the cffi cache)")
    robot = load_problem(ROOT / "examples" / "robot_corridor.toml")
    chain = chain12()

    print("\n== Design times (median; one core)")
    times = {}
    for mode in ("stagewise", "joint"):
        times["robot", mode] = median_time(lambda: dz.design_zoh(robot, 1000, mode=mode), rep)
        print(f"robot   exact ZOH 1 kHz {mode:<9}  C kernel    "
              f"{times['robot', mode] * 1e3:8.1f} ms")
    t_np = median_time(lambda: dz.design_zoh(robot, 1000, kernel="numpy"), slow)
    print(f"robot   exact ZOH 1 kHz stagewise  numpy loop  {t_np * 1e3:8.1f} ms "
          f"(the reference loop; C is {t_np / times['robot', 'stagewise']:.0f}x faster)")
    t_prev = median_time(lambda: previous(robot, 1000), slow)
    print(f"robot   exact ZOH 1 kHz stagewise  previous    {t_prev * 1e3:8.1f} ms")
    t_cont = median_time(lambda: design_continuous(robot), slow)
    print(f"robot   continuous (DOP853 rtol 1e-12)          {t_cont * 1e3:8.1f} ms")
    for mode in ("stagewise", "joint"):
        times["chain12", mode] = median_time(lambda: dz.design_zoh(chain, 1000, mode=mode), slow)
        print(f"chain12 exact ZOH 1 kHz {mode:<9}  C kernel    "
              f"{times['chain12', mode] * 1e3:8.1f} ms")
    t_maps = median_time(lambda: [dz._tick_data(s, 1e-3) for s in chain.stages], slow)
    t_vl = median_time(lambda: [van_loan_tick_data(s, 1e-3) for s in chain.stages], 1)
    print(f"chain12   of which tick maps of the 20 stages   {t_maps * 1e3:8.1f} ms "
          f"(packed expm; Van Loan 2d^2 exponential: {t_vl * 1e3:.0f} ms)")
    t = time.perf_counter()
    previous(chain, 1000)
    print(f"chain12 exact ZOH 1 kHz stagewise  previous    "
          f"{(time.perf_counter() - t) * 1e3:8.1f} ms (one run)")

    print(f"\n== Accuracy against the long-double reference (tolerance {TOL:g} relative)")
    refs, errs = {}, {}
    for name, prob, mode in (("robot", robot, "stagewise"), ("robot", robot, "joint"),
                             ("chain12", chain, "stagewise")):
        refs[name, mode] = reference_design(prob, 1000, mode)
        errs[name, mode] = errors(dz.design_zoh(prob, 1000, mode=mode), refs[name, mode])
        e_j, e_g = errs[name, mode]
        verdict = "ok" if max(e_j, e_g) <= TOL else "ABOVE TOLERANCE"
        print(f"{name:<8}{mode:<10} J0 {float(refs[name, mode][0]):.12f}  "
              f"J0 rel. error {e_j:.1e}  gains rel. error {e_g:.1e}  {verdict}")
    z = dz.design_zoh(robot, 1000)
    oracle = evaluate_table(robot, table_of(z, quantize=False), path=False)
    print(f"robot   predicted J0 vs exact oracle of the designed law: "
          f"{abs(oracle.J - z.J0) / z.J0:.1e} relative")
    cont, tight = design_continuous(robot), design_continuous(robot, rtol=3e-14, atol=1e-18)
    tgrid = np.linspace(0.0, 3.0, 601)
    gerr = max(float(np.abs(a - b).max() / np.abs(b).max())
               for k in range(2) for a, b in zip(cont.gains(k, tgrid + 3 * k),
                                                 tight.gains(k, tgrid + 3 * k)) if b.size)
    print(f"robot   continuous design rtol 1e-12 vs rtol 3e-14: J0 rel. error "
          f"{abs(cont.J0 - tight.J0) / tight.J0:.1e}, gains rel. error {gerr:.1e}")

    print("\n== Speed-up against the straightforward solve_ivp baseline, at equal accuracy")
    compare_baseline("robot", robot, 1000, "stagewise", times["robot", "stagewise"],
                     errs["robot", "stagewise"], refs["robot", "stagewise"], slow)
    compare_baseline("chain12", chain, 1000, "stagewise", times["chain12", "stagewise"],
                     errs["chain12", "stagewise"], refs["chain12", "stagewise"], 1)
    print(f"\n(total {time.perf_counter() - t_start:.0f} s)")


if __name__ == "__main__":
    main()
