"""Regions met at every controller tick (``[[regions]]`` with ``every = "tick"``): by constraint
generation while few rows are active, else by the sparse QP on the tick grid.

A band at every tick of a long interval is a QP with thousands of rows whose dual matrix
``W(t0)`` is nearly singular (neighbouring ticks constrain almost the same output). Instead:
design with the problem's own knots plus a small working set of band knots, compute the
exact expected output at every tick of the law as tabulated (the moment oracle on the
double-precision table), add the most violated tick of each run of violating ticks, and
repeat until no tick violates. While the working set has at most BANDQP_MAX rows, the table
carries their band dual and the firmware re-solves it from the measured start. Once it needs
more, the table would latch the affine map of the active set anyway, and each added row would
cost a stage and worsen ``W``'s conditioning (an arc of contact costs a row per tick): the design
then switches to `stospline.design.tick_qp`, which poses every row at every tick in one sparse
QP with no stage or conditioning limit, and gives the same optimum. Each iterate of constraint
generation is the exact optimum of a relaxation of the every-tick problem (a subset of its
constraints), so the first iterate that meets them all is the every-tick optimum; the cost
rises strictly with each cut, and there are finitely many ticks, so the loop ends. ``docs/theory/math-notes.md`` ("Regions at every tick").

Between ticks the command is held, so the mean follows the plant's free response plus the
held input; `between_ticks` measures how far it leaves the band there (enforced only with a
region's ``between_ticks = true``, by the tick-grid QP).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from stospline.design.bands import BandDesign, design_bands
from stospline.design.continuous import DesignError
from stospline.design.tick_qp import TickQPDesign, design_tick_qp
from stospline.limits import BANDQP_MAX, MAX_STAGES
from stospline.problem.model import Constraint, Problem, TickRegion
from stospline.problem.regions import with_bands
from stospline.oracle.evaluate import evaluate_table
from stospline.table.format import table_of

__all__ = ["EveryTick", "design_every_tick", "tick_grid", "every_tick_check", "tick_violation",
           "between_ticks", "active_ticks", "MAX_ITERATIONS", "TOLERANCE"]

MAX_ITERATIONS = 60
# A tick violates when it is beyond its band by more than this times max(1, |bounds|): the
# design meets its working set to ~1e-13 of that scale, so this is far above rounding.
TOLERANCE = 1e-9


@dataclass
class EveryTick:
    """The every-tick design: the band design on the final working set (or the tick-grid QP's
    design), and how it got there."""
    design: BandDesign | TickQPDesign
    problem: Problem                # the input problem plus the working set's band knots (the
                                    # input problem itself for the tick-grid QP)
    iterations: int
    working_set: list[tuple[int, int, int]]     # (tick, region index, row) of each added row
    history: list[dict] = field(default_factory=list)   # per iteration: J0, worst, rows added
    seconds: float = 0.0
    dropped: int = 0           # rows cut in some round that the optimum left inside their bands
    method: str = "constraint-generation"      # or "tick-qp"

    def summary(self) -> dict:
        return {"method": self.method, "iterations": self.iterations,
                "working_set_rows": len(self.working_set),
                "dropped_rows": self.dropped,
                "working_set": [{"tick": j, "region": r, "row": i}
                                for j, r, i in self.working_set]}


def _scale(reg: TickRegion) -> float:
    return max(1.0, float(np.abs(np.concatenate([reg.lower, reg.upper])).max()))


def tick_violation(problem: Problem, path_mean: np.ndarray) -> list[np.ndarray]:
    """Per tick region, ``(ticks, p)``: how far each row of ``E{C x}`` is beyond its band at
    each of the region's ticks (negative: inside), from the mean state at every tick."""
    out = []
    for reg in problem.tick_regions:
        y = path_mean[reg.ticks(problem.t0, problem.tick_hz)] @ reg.C.T
        out.append(np.maximum(y - reg.upper, reg.lower - y))
    return out


def _cuts(problem: Problem, path_mean: np.ndarray) -> list[tuple[int, int, int, float]]:
    """``(tick, region, row, violation)``: the worst tick of every run of consecutive ticks
    at which a row violates (a run is one contact of the unconstrained mean with the band)."""
    cuts = []
    for r, (reg, v) in enumerate(zip(problem.tick_regions, tick_violation(problem, path_mean))):
        ticks = reg.ticks(problem.t0, problem.tick_hz)
        bad = v > TOLERANCE * _scale(reg)
        for i in range(v.shape[1]):
            idx = np.flatnonzero(bad[:, i])
            for run in np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1):
                if run.size:
                    w = run[int(np.argmax(v[run, i]))]
                    cuts.append((int(ticks[w]), r, i, float(v[w, i])))
    return cuts


def _independent(problem: Problem, rows: list, cuts: list) -> list[tuple[int, int, int]]:
    """The cuts to add: those whose row is linearly independent of the rows already
    constrained at its tick (the file's knot constraint there, the working set, the cuts
    taken before it). A dependent row cannot be a knot row (W would be singular); if it
    violates, a row it depends on violates too, or the bands there contradict each other."""
    t0, hz = problem.t0, problem.tick_hz
    at_knot = {int(round((kn.t - t0) * hz)): kn.constraint.C for kn in problem.knots
               if kn.constraint is not None}
    taken = list(rows)
    out = []
    for j, r, i, _ in sorted(cuts, key=_worst_first(cuts)):
        if (j, r, i) in taken:
            continue
        C = [problem.tick_regions[rr].C[ii] for jj, rr, ii in taken if jj == j]
        if j in at_knot:
            C = list(at_knot[j]) + C
        cand = np.array(C + [problem.tick_regions[r].C[i]])
        norms = np.linalg.norm(cand, axis=1, keepdims=True)
        if not np.all(norms > 0):       # a zero row (refused when read, but not when built)
            continue
        sv = np.linalg.svd(cand / norms, compute_uv=False)
        if sv[-1] > 1e-8 * sv[0]:
            taken.append((j, r, i))
            out.append((j, r, i))
    return out


def _worst_first(cuts: list):
    """Sort key of the cuts: the worst first, violations equal to 1e-9 of the worst counting
    as equal, then by tick, region and row. Rows that tie in exact arithmetic (the two legs'
    walls at a corner the knot holds on a diagonal) differ in the last bits, which the oracle's
    summation order and the machine decide; the key makes the choice theirs no longer."""
    quantum = 1e-9 * max((c[3] for c in cuts), default=0.0)
    if quantum <= 0.0:
        return lambda c: (0.0, c[0], c[1], c[2])
    return lambda c: (-np.floor(c[3] / quantum), c[0], c[1], c[2])


def active_ticks(problem: Problem, design: BandDesign) -> list[tuple[int, int]]:
    """``(tick, side)`` of every band row the design holds at a bound (side -1 lower, +1
    upper), over the knots without a penalty (the band knots a region added); for the
    tick-grid QP, over the regions' rows."""
    if isinstance(design, TickQPDesign):
        return design.active_ticks()
    return sorted((round((problem.knots[k].t - problem.t0) * problem.tick_hz), int(a))
                  for (k, _), a in zip(design.rows, design.solution.active)
                  if a != 0 and problem.knots[k].penalty is None)


def _slack(problem: Problem, work: Problem, design: BandDesign,
           rows: list[tuple[int, int, int]]) -> set[tuple[int, int, int]]:
    """The working-set rows that the design leaves inactive (inside their bands)."""
    t0, hz = problem.t0, problem.tick_hz
    file_rows = {int(round((kn.t - t0) * hz)): kn.n_constraints for kn in problem.knots}
    by_tick: dict[int, list] = {}
    for j, r, i in sorted(rows):                   # the order `_bands` stacks them in
        by_tick.setdefault(j, []).append((j, r, i))
    out = set()
    for (k, i), a in zip(design.rows, design.solution.active):
        j = int(round((work.knots[k].t - t0) * hz))
        w = i - file_rows.get(j, 0)
        if a == 0 and w >= 0:
            out.add(by_tick[j][w])
    return out


def _check_fixed(problem: Problem) -> None:
    """Refuse a region row that a knot's equality rows fix outside its band at that tick
    (e.g. a speed band that excludes the rest the last knot demands): no design meets it,
    and the loop would only find that out after filling the stages."""
    t0, hz = problem.t0, problem.tick_hz
    for kn in problem.knots:
        if kn.constraint is None:
            continue
        lo, hi = kn.constraint.bounds
        E, value = kn.constraint.C[lo == hi], lo[lo == hi]
        if not E.shape[0]:
            continue
        j = int(round((kn.t - t0) * hz))
        for reg in problem.tick_regions:
            if j not in reg.ticks(t0, hz):
                continue
            for i, row in enumerate(reg.C):
                c = np.linalg.lstsq(E.T, row, rcond=None)[0]
                if np.linalg.norm(row - E.T @ c) > 1e-9 * np.linalg.norm(row):
                    continue
                y = float(c @ value)
                tol = TOLERANCE * _scale(reg)
                if y > reg.upper[i] + tol or y < reg.lower[i] - tol:
                    raise DesignError(f"regions[{reg.index}]",
                                      f"row {i} must lie in [{reg.lower[i]:g}, "
                                      f"{reg.upper[i]:g}] at t = {kn.t:g}, where the knot's "
                                      f"equality constraints fix it at {y:g}: the bands "
                                      f"cannot all be met")


def _bands(problem: Problem, rows: list[tuple[int, int, int]]) -> dict[int, Constraint]:
    """The working set as one band constraint per tick (rows in a fixed order)."""
    by_tick: dict[int, list] = {}
    for j, r, i in sorted(rows):
        by_tick.setdefault(j, []).append((r, i))
    out = {}
    for j, pairs in by_tick.items():
        regs = [problem.tick_regions[r] for r, _ in pairs]
        out[j] = Constraint(np.array([g.C[i] for g, (_, i) in zip(regs, pairs)]), None,
                            np.array([g.lower[i] for g, (_, i) in zip(regs, pairs)]),
                            np.array([g.upper[i] for g, (_, i) in zip(regs, pairs)]))
    return out


def design_every_tick(problem: Problem, *, noise: bool = True,
                      max_iterations: int = MAX_ITERATIONS,
                      band_rows: int | None = BANDQP_MAX) -> EveryTick:
    """The joint exact-zero-order-hold band design whose expected outputs meet every tick
    region at every tick (to `TOLERANCE` of the bounds' scale), by constraint generation.

    Once the working set needs more than BANDQP_MAX rows, the design is the tick-grid QP's
    (`tick_grid`; module docstring); ``band_rows=None`` keeps generating constraints (the
    reference the tests compare the QP with) up to the firmware's MAX_STAGES. Raises
    DesignError naming ``regions[i]`` when the loop does not settle within `max_iterations`,
    needs more stages than the firmware takes, or the QP has no solution."""
    start = time.perf_counter()
    _check_fixed(problem)
    if any(reg.between for reg in problem.tick_regions):    # rows between ticks: the QP's
        return tick_grid(problem, noise=noise, start=start)
    rows: list[tuple[int, int, int]] = []
    new: list[tuple[int, int, int]] = []
    history = []
    for it in range(1, max_iterations + 1):
        work = with_bands(problem, _bands(problem, rows))
        if band_rows is not None and len(rows) > band_rows:
            return tick_grid(problem, noise=noise, iterations=it - 1, history=history,
                             start=start)
        if len(work.knots) > MAX_STAGES:
            r = rows[-1][1]
            raise DesignError(f"regions[{problem.tick_regions[r].index}]",
                              f"every = \"tick\" needs {len(work.knots)} stages (the file's "
                              f"knots and a band knot at each tick where the expected output "
                              f"touches a region; an arc of contact costs one per tick), "
                              f"more than the firmware's {MAX_STAGES} (STSP_MAX_STAGES)")
        try:
            design = design_bands(work, discretization="exact-zoh", noise=noise)
        except DesignError as exc:
            if not rows:
                raise
            # The knots it names are band knots the loop added: name the region instead.
            j, r, i = new[0]
            raise DesignError(f"regions[{problem.tick_regions[r].index}]",
                              f"row {i} violates its band at t = "
                              f"{problem.t0 + j / problem.tick_hz:g}, and with it as a "
                              f"constraint there the design fails ({exc.field}: "
                              f"{exc.reason})") from None
        exact = table_of(design, quantize=False)
        path = evaluate_table(work, exact, path=True).path_mean
        cuts = _cuts(problem, path)
        new = _independent(problem, rows, cuts)
        history.append({"iteration": it, "J0": design.J0, "rows": len(rows),
                        "worst": max((c[3] for c in cuts), default=0.0), "added": len(new)})
        if not cuts:
            slack = _slack(problem, work, design, rows)
            if slack:
                # Rows the optimum leaves inside their bands (cut in an earlier round, then
                # overtaken) are dropped: the same optimum with fewer stages and rows. Checked
                # again at every tick; kept if that check fails.
                kept = [x for x in rows if x not in slack]
                work2 = with_bands(problem, _bands(problem, kept))
                design2 = design_bands(work2, discretization="exact-zoh", noise=noise)
                path2 = evaluate_table(work2, table_of(design2, quantize=False),
                                       path=True).path_mean
                if not _cuts(problem, path2):
                    history.append({"iteration": it + 1, "J0": design2.J0, "rows": len(kept),
                                    "worst": 0.0, "added": -len(slack)})
                    return EveryTick(design2, work2, it + 1, sorted(kept), history,
                                     time.perf_counter() - start, dropped=len(slack))
            return EveryTick(design, work, it, sorted(rows), history,
                             time.perf_counter() - start)
        if not new:
            j, r, i, v = max(cuts, key=lambda c: c[3])
            raise DesignError(f"regions[{problem.tick_regions[r].index}]",
                              f"row {i} is {v:.3g} beyond its band at t = "
                              f"{problem.t0 + j / problem.tick_hz:g} although the constraints "
                              f"at that tick already fix it (it is one of them, or a "
                              f"combination of them): the bands there cannot all be met")
        rows += new
    worst = max(_cuts(problem, path), key=lambda c: c[3])
    raise DesignError(f"regions[{problem.tick_regions[worst[1]].index}]",
                      f"every = \"tick\": still violated after {max_iterations} rounds of "
                      f"constraint generation ({len(rows)} band rows, worst {worst[3]:.3g} at "
                      f"tick {worst[0]}): use a grid (every = seconds)")


def tick_grid(problem: Problem, *, noise: bool = True, iterations: int = 0,
              history: list | None = None, start: float | None = None,
              design: TickQPDesign | None = None) -> EveryTick:
    """The every-tick design as the sparse QP on the tick grid (`design_tick_qp`; `design`
    if given, e.g. one with its rows tightened), checked at every tick by the oracle on its
    law in double precision."""
    start = time.perf_counter() if start is None else start
    if design is None:
        design = design_tick_qp(problem, noise=noise)
    path = evaluate_table(problem, table_of(design, quantize=False), path=True).path_mean
    cuts = _cuts(problem, path)
    if cuts:      # the KKT loop met every row to TOLERANCE: the oracle must agree
        j, r, i, v = max(cuts, key=lambda c: c[3])
        raise DesignError(f"regions[{problem.tick_regions[r].index}]",
                          f"the tick-grid design leaves row {i} {v:.3g} beyond its band at "
                          f"t = {problem.t0 + j / problem.tick_hz:g} on the oracle")
    if any(reg.between for reg in problem.tick_regions):
        u_mean = np.array([-(K @ x) - k for K, k, x in
                           zip(design.K, design.kstar + design.delta, path[:-1])])
        for reg, gap in zip(problem.tick_regions, between_ticks(problem, path, u_mean)):
            if reg.between and gap["worst"] > TOLERANCE * _scale(reg):
                raise DesignError(f"regions[{reg.index}].between_ticks",
                                  f"the tick-grid design leaves row {gap['row']} "
                                  f"{gap['worst']:.3g} beyond its band at t = {gap['t']:g} "
                                  f"between ticks (exact polynomial extremum)")
    work = [(t.tick, next(k for k, g in enumerate(problem.tick_regions) if g.index == t.index),
             t.row) for t, a in zip(design.rows, design.active)
            if t.kind == "region" and a != 0]
    history = list(history or []) + [{"iteration": iterations + 1, "J0": design.J0,
                                      "rows": len(work), "worst": 0.0, "added": 0,
                                      "tick_qp_rounds": design.rounds}]
    return EveryTick(design, problem, iterations + 1, sorted(work), history,
                     time.perf_counter() - start, method="tick-qp")


def every_tick_check(d, *, where: bool = False, sensor_path: np.ndarray | None = None) -> dict:
    """The every-tick regions of design `d` (`stospline.pipeline.Designed`) checked by the
    oracle: the worst violation at any tick of each
    region (negative: inside by that much) for the design's law in double precision and for
    the float32 table, and the worst over all of [a, b] with the mean between ticks (the
    command held). ``where``: also the time of that worst (not in the summary: along an arc
    of contact many times tie, and which one wins differs in the last bits).

    `sensor_path`: with a [measurement] sensor, the true state's mean at every tick of the loop
    the firmware runs (`harness.estimator_run.sensor_path_mean`: the float32 table on the
    estimate of the flashed filter); the worst at any tick for it too. The regions bound the
    mean only, and the filter is unbiased, so the law's mean path is the full-state one; the
    float32 predictor's rounding moves it by float32 precision."""
    p = d.problem
    exact = evaluate_table(p, table_of(d.design, quantize=False), path=True)
    implemented = evaluate_table(p, d.table, path=True)
    sensor = sensor_path
    regions = []
    for i, (reg, law, imp, gap) in enumerate(zip(
            p.tick_regions, tick_violation(p, exact.path_mean),
            tick_violation(p, implemented.path_mean),
            between_ticks(p, exact.path_mean, exact.path_u_mean))):
        extra = {} if sensor is None else {
            "worst_at_ticks_sensor_loop": float(tick_violation(p, sensor)[i].max())}
        regions.append({"region": reg.index, "ticks": int(reg.ticks(p.t0, p.tick_hz).size),
                        "worst_at_ticks_design": float(law.max()),
                        "worst_at_ticks_implemented": float(imp.max()),
                        "worst_over_interval": gap["worst"],
                        "between_ticks_enforced": bool(reg.between),
                        "over_interval_exact": gap["exact"], **extra,
                        **({"worst_over_interval_t": gap["t"]} if where else {})})
    return {**d.every_tick.summary(), "regions": regions}


def between_ticks(problem: Problem, path_mean: np.ndarray, u_mean: np.ndarray,
                  points: int = 64) -> list[dict]:
    """Per tick region, ``worst``: the largest excursion of ``E{C x(t)}`` beyond its band over
    all t in [a, b] (ticks and the times between them; negative: inside by that much), with
    the command held over each tick, and ``t``, ``row`` where it occurs. For a time-invariant
    stage whose A is nilpotent (an integrator chain) the mean is a polynomial in time over a
    tick and its extrema are found exactly; otherwise it is sampled at `points` + 1 points per
    tick (data frozen at the tick's midpoint). ``exact`` says which. (t0 itself counts:
    the mean there is x0.)"""
    h = 1.0 / problem.tick_hz
    t0 = problem.t0
    bounds = np.array([t0] + [kn.t for kn in problem.knots])
    out = []
    for reg in problem.tick_regions:
        a, b_end = reg.t
        # Every tick interval [t_j, t_j+1] that meets (a, b); b may end a piece of one.
        ticks = np.arange(int(round((a - t0) * problem.tick_hz)),
                          int(np.ceil((b_end - t0) * problem.tick_hz - 1e-9)))
        worst, where, exact = -math.inf, None, True
        for j in ticks:
            t = t0 + j * h
            st = problem.stages[min(int(np.searchsorted(bounds, t + 0.5 * h)) - 1,
                                    len(problem.stages) - 1)]
            data = st.at(t + 0.5 * h)
            A, B = data.A, data.B
            f = np.zeros(len(A)) if data.f is None else data.f
            x, b = path_mean[j], B @ u_mean[j] + f
            n = len(A)
            nil = st.varying is None and not np.any(np.linalg.matrix_power(A, n))
            if nil:
                # x(s) = sum_k s^k/k! A^k x + s^(k+1)/(k+1)! A^k b: degree <= n in s.
                coef = np.zeros((n + 1, n))
                Ak = np.eye(n)
                for k in range(n):
                    coef[k] += Ak @ x / math.factorial(k)
                    coef[k + 1] += Ak @ b / math.factorial(k + 1)
                    Ak = Ak @ A
                ycoef = coef @ reg.C.T                 # (degree + 1, p), ascending powers
                for i in range(ycoef.shape[1]):
                    poly = np.polynomial.Polynomial(ycoef[:, i])
                    # The piece's ends (ticks, or a/b inside the tick) and its extrema.
                    lo_s, hi_s = max(0.0, a - t), min(h, b_end - t)
                    s = [lo_s, hi_s] + [r.real for r in poly.deriv().roots()
                                        if abs(r.imag) < 1e-12 and lo_s < r.real < hi_s]
                    for si in s:
                        y = poly(si)
                        v = max(y - reg.upper[i], reg.lower[i] - y)
                        if v > worst:
                            worst, where = v, (t + si, i)
            else:
                exact = False
                from scipy.linalg import expm
                M = np.zeros((n + 1, n + 1))
                M[:n, :n], M[:n, n] = A, b
                lo_s, hi_s = max(0.0, a - t), min(h, b_end - t)
                for s in np.linspace(lo_s, hi_s, points + 1):
                    xs = (expm(M * s) @ np.append(x, 1.0))[:n]
                    y = reg.C @ xs
                    v = np.maximum(y - reg.upper, reg.lower - y)
                    if v.max() > worst:
                        worst, where = float(v.max()), (t + s, int(np.argmax(v)))
        out.append({"region": reg.index, "worst": worst, "t": None if where is None else
                    where[0], "row": None if where is None else where[1], "exact": exact})
    return out
