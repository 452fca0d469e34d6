"""The latch maps re-solved for a law as implemented: with gains that differ from the design's
(a spline's evaluation), the design's ``Lambda, lambda0`` no longer make the expected outputs
meet the knot constraints; these do, exactly (in float64).

From the latch tick of a group (multipliers ``v`` for the constrained knots up to the next
latch), the mean obeys ``m_{j+1} = F [m_j; u_j; 1]``, ``u_j = -K_j m_j - k0_j - L_j v`` (the
command's mean: the law is affine and the noise has zero mean), so ``m(t) = Phi x + psi +
Gamma v`` at every tick. The constraints ``C2_k m(t_k) = zeta_k`` at the group's knots are
square in ``v``: ``G = C2 Gamma``, ``Lambda = -G^-1 C2 Phi``, ``lambda0 = G^-1 (zeta - C2 psi)``.

The groups are read off the table (a latch at every stage with ``stage_n_latch > 0``,
covering the constrained knots up to the next latch), which is what
`stospline.design.latch.latch_groups` makes of both modes. The tick's mean map ``F`` is the
oracle's: for time-invariant data one exponential per stage, computed here (as
``design.zoh._tick_data``'s ``F``); for time-varying data one map per tick, of the generator
interpolated through the tick's Gauss points as the designer and the oracle discretise it
(`stospline.design.varying.mean_maps`, handed in by the caller as ``varying_maps``: the table
layer imports no designer). A law designed for a one-tick
delay has the state ``xi = [x; p]`` (p the command being applied): its ``F`` maps ``[x; p; u;
1]`` (`delayed_map`), the latch maps act on ``xi`` and the constraints on its x.

`round_latch` stores the exact maps in float32, chosen on the float32 grid so that the law as
stored meets the constraints at the design's planned start (x0 and the planned means at the
later latches) far below the float32 floor that rounding each map to nearest leaves.
"""
from __future__ import annotations

import math

import numpy as np

from stospline.errors import DesignError
from stospline.expm import expm
from stospline.table.kernels import affine_compose, affine_compose_gains

__all__ = ["resolve_latch", "round_latch", "latch_grid", "start_state", "latch_groups_of_table",
           "mean_tick_map", "delayed_map", "stage_mean_maps", "mean_maps_by_stage"]

FIELD = "design.table"


def mean_tick_map(stage, h: float) -> np.ndarray:
    """``F`` (n, n + m + 1) with ``E x+ = F [x; u; 1]`` over one tick of constant data,
    the command held: the drift ``[[A, B, f], [0, 0, 0]]`` exponentiated."""
    n, m = stage.B.shape
    drift = np.zeros((n + m + 1, n + m + 1))
    drift[:n, :n] = stage.A
    drift[:n, n:n + m] = stage.B
    if stage.f is not None:
        drift[:n, -1] = stage.f
    return expm(drift * h)[:n]


def latch_groups_of_table(problem, table) -> list[tuple[int, list[int]]]:
    """``(latch stage, constrained knots)`` of every latch of `table`, the knots in order:
    their constraints' rows are the latched vector's, in that order.

    Raises DesignError (field ``design.table``) when the latched widths do not match the
    constraints: a table that latches the state (more multipliers than states), or a table
    of another problem.
    """
    n_latch = np.asarray(table.stage_n_latch, dtype=int)
    latches = [s for s in range(table.n_stages) if n_latch[s] > 0]
    groups, covered = [], set()
    for i, s in enumerate(latches):
        end = latches[i + 1] if i + 1 < len(latches) else table.n_stages
        knots = [k for k in range(s, end) if problem.knots[k].n_constraints]
        width = sum(problem.knots[k].n_constraints for k in knots)
        if width != n_latch[s]:
            raise DesignError(FIELD, f"stage {s} latches {n_latch[s]} values but its group's "
                                     f"constraints have {width} rows (a table that latches "
                                     f"the state, or of another problem): not re-solvable")
        groups.append((s, knots))
        covered.update(knots)
    missed = [k for k, kn in enumerate(problem.knots) if kn.n_constraints and k not in covered]
    if missed:
        raise DesignError(FIELD, f"no latch of the table covers knot {missed[0]}'s constraint")
    return groups


def _refuse_unsupported(problem, table, *, band: bool = False) -> None:
    """What the re-solve cannot do exactly is refused, naming the reason. ``band=True``: the
    caller re-solves the band dual (`stospline.table.spline.band`), not an affine latch."""
    why = None
    if getattr(table, "arith", "float32") != "float32" or not np.issubdtype(table.K.dtype,
                                                                             np.floating):
        why = "a fixed-point table"
    elif not band and (getattr(table, "band_qp", None) is not None or any(
            kn.constraint is not None and kn.constraint.is_band for kn in problem.knots)):
        why = "a band table (the firmware re-solves the band dual, not an affine latch)"
    elif len(table.stage_start) != len(problem.knots) + 1 or not np.array_equal(
            np.diff(np.asarray(table.stage_start, dtype=np.int64)),
            np.rint(np.diff(problem.times) * table.tick_hz).astype(np.int64)):
        why = "the table's stages do not match the problem's at its tick rate"
    if why is not None:
        raise DesignError(FIELD, f"the latch maps cannot be re-solved exactly for {why}")


def _affine_product(P: np.ndarray) -> np.ndarray:
    """The composition ``P[-1] o ... o P[0]`` of affine blocks ``P[j] = [A_j | C_j]`` (n, d),
    each the map ``[m; c] -> [A_j m + C_j c; c]`` (c the constants ``[v; 1]``): tick by tick
    in C (`stospline.table.kernels.affine_compose`, the sums left to right: the same bits on
    every machine; 3x faster on a 6 000-tick stage, `tools/bench/table_kernel.py`), else by
    pairwise products in numpy (`_affine_product_numpy`)."""
    out = affine_compose(P)
    return _affine_product_numpy(P) if out is None else out


def _affine_product_numpy(P: np.ndarray) -> np.ndarray:
    """`_affine_product` by pairwise products: a dozen batched matmuls instead of one Python
    step per tick. Each level is written into a new array, the odd block last, unpaired until
    the next level."""
    n, d = P.shape[1:]
    while P.shape[0] > 1:
        k = P.shape[0]
        half, later = k // 2, P[1::2]
        out = np.empty((k - half, n, d))
        np.matmul(later[:, :, :n], P[0:k - 1:2], out=out[:half])
        out[:half, :, n:] += later[:, :, n:]
        if k % 2:
            out[half] = P[k - 1]
        P = out
    return P[0]


def _gain_columns(table, s: int, width: int, spline) -> tuple[np.ndarray, np.ndarray,
                                                                np.ndarray]:
    """Stage s's gains that can be nonzero, as ``(kind, input, operand)`` per column, in the
    order K (input-major), L (the first `width` multipliers), k0: kind 0, 1, 2 index the
    table's K, L, k0; the operand of k0 is 0. All of them, or only the entries `spline`
    stores (the others are exactly zero, and skipping them halves the stage's products)."""
    n, m, _ = table.dims
    if spline is None:
        kind = np.r_[np.zeros(m * n, int), np.ones(m * width, int), np.full(m, 2)]
        inputs = np.r_[np.repeat(np.arange(m), n), np.repeat(np.arange(m), width),
                       np.arange(m)]
        operand = np.r_[np.tile(np.arange(n), m), np.tile(np.arange(width), m),
                        np.zeros(m, int)]
        return kind, inputs, operand
    inputs, cols = spline.entries(s)
    cols = cols.astype(int)
    kind = np.where(cols < n, 0, np.where(cols > n, 1, 2))
    operand = np.where(cols < n, cols, np.where(cols > n, cols - n - 1, 0))
    used = (kind != 1) | (operand < width)
    order = np.lexsort((operand[used], inputs[used], kind[used]))
    return kind[used][order], inputs[used][order], operand[used][order]


def delayed_map(F: np.ndarray, m: int) -> np.ndarray:
    """The mean map of a tick of a law designed for a one-tick delay, from the plant's `F`
    (..., n, n + m + 1): its state is ``xi = [x; p]``, p the command applied over the tick
    (decided one tick earlier), and its command u is applied over the next one, so ``E xi+ =
    [[Ad, Bd, 0, fd], [0, 0, I, 0]] [x; p; u; 1]`` (``design.zoh._delayed_tick_data``'s F)."""
    n = F.shape[-2]
    out = np.zeros(F.shape[:-2] + (n + m, n + 2 * m + 1))
    out[..., :n, :n + m] = F[..., :n + m]
    out[..., :n, -1] = F[..., -1]
    out[..., n:, n + m:n + 2 * m] = np.eye(m)
    return out


def stage_mean_maps(stage, table, s: int, h: float, varying_maps=None) -> np.ndarray:
    """The mean maps of stage s's ticks, (1, n, n + m + 1) for time-invariant data (every
    tick's) or (T, n, n + m + 1) one per tick, over the law's state (n the table's: with a
    delay ``[x; p]``, `delayed_map`). Time-varying data: the oracle's own discretisation,
    ``varying_maps(stage, t_start, h, T)`` (`stospline.design.varying.mean_maps`)."""
    a, b = int(table.stage_start[s]), int(table.stage_start[s + 1])
    if stage.varying is None:
        F = mean_tick_map(stage, h)[None]
    elif varying_maps is None:
        raise DesignError(FIELD, f"the latch maps cannot be re-solved for stage {s}'s "
                                 f"time-varying data without the per-tick mean maps")
    else:
        F = varying_maps(stage, table.t0 + a * h, h, b - a)
    if getattr(table, "delay_ticks", 0):
        F = delayed_map(F, table.dims[1])
    return F


def mean_maps_by_stage(problem, table, h: float, varying_maps=None) -> list[np.ndarray]:
    """`stage_mean_maps` of every stage of `table`, in order. Stages with the same
    time-invariant data (A, B, f) share one exponential (and one array: read only)."""
    out, seen = [], {}
    for s in range(table.n_stages):
        stage = problem.stages[s]
        key = None
        if stage.varying is None:
            key = (stage.A.tobytes(), stage.B.tobytes(),
                   None if stage.f is None else np.asarray(stage.f, float).tobytes())
        if key is None or key not in seen:
            F = stage_mean_maps(stage, table, s, h, varying_maps)
            if key is not None:
                seen[key] = F
        else:
            F = seen[key]
        out.append(F)
    return out


def _stage_map(stage, table, s: int, width: int, h: float, spline=None, varying_maps=None,
               F=None) -> np.ndarray:
    """The mean over stage s as an affine block (n, n + width + 1): ``m_end = A m_start + C
    [v; 1]`` under the table's gains (its first `width` multiplier columns). `F`: the
    stage's `stage_mean_maps`, when the caller has them (`mean_maps_by_stage`, whose stages
    with the same data share one array)."""
    n, m, _ = table.dims
    a, b = int(table.stage_start[s]), int(table.stage_start[s + 1])
    if F is None:
        F = stage_mean_maps(stage, table, s, h, varying_maps)
    if F.shape[0] > 1:
        return _affine_product(_varying_ticks(F, table, a, b, width))
    F = F[0]
    Bd, d = F[:, n:n + m], n + width + 1
    # Per tick P = [Ad | 0 | fd] - Bd [K | L | k0] (u = -K m - L v - k0): the base [Ad | 0 |
    # fd], plus, for the gain of input i on operand j, -Bd[:, i] times the gain in column j.
    kind, inputs, operand = _gain_columns(table, s, width, spline)
    T, sources = b - a, (table.K[a:b], table.L[a:b], table.k0[a:b, :, None])
    gains = np.empty((T, kind.size))
    for k, g in enumerate(sources):
        mine = kind == k
        gains[:, np.flatnonzero(mine)] = g.reshape(T, -1)[:, inputs[mine] * g.shape[2]
                                                          + operand[mine]]
    column = np.where(kind == 0, operand, np.where(kind == 1, n + operand, d - 1))
    base = np.zeros((n, d))
    base[:, :n] = F[:, :n]
    base[:, -1] = F[:, -1]
    vec = -Bd[:, inputs].T
    out = affine_compose_gains(base, column, vec, gains)
    return _affine_product_numpy(_tick_blocks(base, column, vec, gains)) if out is None \
        else out


def _tick_blocks(base: np.ndarray, column: np.ndarray, vec: np.ndarray, gains: np.ndarray
                 ) -> np.ndarray:
    """The blocks (T, n, d) of `kernels.affine_compose_gains`: ``base`` plus, gain k in turn,
    ``gains[:, k] vec[k]`` in column ``column[k]`` (a product, then a sum: the kernel's
    bits)."""
    T = gains.shape[0]
    P = np.broadcast_to(base, (T, *base.shape)).copy()
    for k in range(gains.shape[1]):
        P[:, :, column[k]] += gains[:, k, None] * vec[k][None, :]
    return P


def _varying_ticks(F: np.ndarray, table, a: int, b: int, width: int) -> np.ndarray:
    """The affine blocks (T, n, n + width + 1) of ticks a..b-1, one mean map per tick (`F`,
    (T, n, n + m + 1)): ``[Ad | 0 | fd] - Bd [K | L | k0]``, batched."""
    n, m, _ = table.dims
    gains = np.concatenate([table.K[a:b], table.L[a:b, :, :width], table.k0[a:b, :, None]],
                           axis=2).astype(float)
    P = -np.matmul(F[:, :, n:n + m], gains)
    P[:, :, :n] += F[:, :, :n]
    P[:, :, -1] += F[:, :, -1]
    return P


def _groups(problem, table, spline, varying_maps):
    """Per latch group: ``(latch, width, knots, blocks, CW, zeta)``: the stage blocks
    (`_stage_map`) of the stages it governs (from its latch to the next one), and the
    constraint rows ``C2 W`` over ``[x; v; 1]`` at the latch with their values. Stages
    before the first latch, if any, come first as a group with latch None."""
    n = table.dims[0]
    h = 1.0 / table.tick_hz
    groups = latch_groups_of_table(problem, table)
    maps = mean_maps_by_stage(problem, table, h, varying_maps)
    out = []
    if groups and groups[0][0] > 0:          # before the first latch v = 0 (width 0)
        out.append((None, 0, [], [_stage_map(problem.stages[s], table, s, 0, h, spline,
                                             F=maps[s])
                                  for s in range(groups[0][0])],
                    None, None))
    for g, (latch, knots) in enumerate(groups):
        width = int(table.stage_n_latch[latch])
        end = groups[g + 1][0] if g + 1 < len(groups) else table.n_stages
        W = np.eye(n, n + width + 1)             # m = W [x; v; 1], from the latch tick
        rows, zeta, blocks = [], [], []
        for s in range(latch, end):
            P = _stage_map(problem.stages[s], table, s, width, h, spline, F=maps[s])
            blocks.append(P)
            if s > knots[-1]:
                continue
            W = P[:, :n] @ W
            W[:, n:] += P[:, n:]
            if s in knots:               # C2 on the plant's state, the first of the law's
                con = problem.knots[s].constraint
                rows.append(con.C @ W[:con.C.shape[1]])
                zeta.append(con.value)
        out.append((latch, width, knots, blocks, np.vstack(rows), np.concatenate(zeta)))
    return out


def resolve_latch(problem, table, spline=None, varying_maps=None, *, rounded: bool = False
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The latch maps that make `table`'s law meet every knot constraint in expectation.

    Parameters
    ----------
    problem : Problem
        The problem the table was designed for (plant, knots, constraints).
    table : GainTable
        The law as implemented: its K, k0 and L (float32 or float64) are taken as they are;
        its own Lambda and lambda0 are ignored where the table latches.
    spline : SplineGains, optional
        The spline whose evaluation `table`'s K, k0, L are (`stospline.table.spline.fit.evaluate`):
        the entries it does not store are then taken as zero, unread.
    varying_maps : callable, optional
        ``varying_maps(stage, t_start, h, T)``: the per-tick mean maps of time-varying stage
        data (`stospline.design.varying.mean_maps`); needed only for such data.
    rounded : bool
        Return the maps rounded to float32 by `round_latch` (at the design's start), instead
        of the exact float64 ones.

    Returns
    -------
    Lambda, lambda0 : ndarray
        float64 (float32 when `rounded`), the table's shapes (n_stages, n_latch, n) and
        (n_stages, n_latch): re-solved rows at the latching stages, the table's values
        elsewhere.

    Raises
    ------
    DesignError
        (field ``design.table``) For what is not re-solved exactly: fixed-point or band
        tables, tables that latch the state, or gains under which the multipliers do not
        move the constraints (a singular ``C2 Gamma``).

    Notes
    -----
    As the oracle (`stospline.oracle.evaluate.evaluate_table`), this assumes no command is
    clipped by the table's limits.
    """
    _refuse_unsupported(problem, table)
    n = table.dims[0]
    Lam = np.array(table.Lambda, dtype=float)
    lam0 = np.array(table.lambda0, dtype=float)
    groups = _groups(problem, table, spline, varying_maps)
    for latch, width, _, _, CW, zeta in groups:
        if latch is None:
            continue
        G = CW[:, n:n + width]
        if np.linalg.cond(G) > 1e12:
            raise DesignError(FIELD, f"the multipliers latched at stage {latch} hardly move "
                                     f"their constraints under these gains (cond(C2 Gamma) = "
                                     f"{np.linalg.cond(G):.2g})")
        Lam[latch, :width] = -np.linalg.solve(G, CW[:, :n])
        lam0[latch, :width] = np.linalg.solve(G, zeta - CW[:, -1])
    if rounded:
        return round_latch(problem, table, groups, Lam, lam0)
    return Lam, lam0


# The rounding of the latch maps (`round_latch`): per latched row, the Lambda entries that
# move its multiplier at the planned start (at most FLIP_ENTRIES, `_latch_options`) may leave
# their nearest float32, lambda0 take the grid points next to its target; the best options
# of each row (smallest error of its multiplier at the planned start) enter the joint choice
# over the group's rows, at most JOINT_MAX combinations.
FLIP_ENTRIES = 4
FINE_STEPS = 128
JOINT_MAX = 4096
# The numbers the rounding's choices read (the planned state, the exact multipliers at it,
# C2 Gamma) are first rounded to SNAP_BITS bits of their scale (`_snap`): the choices are then
# exact functions of digits that the design's last bits (1e-14 relative) do not reach,
# computed without BLAS (whose summation order varies between machines and thread counts)
# from there on; the float32 neighbours of Lambda are those of its exact values.
SNAP_BITS = 28


def _snap(a: np.ndarray, scale: float | np.ndarray) -> np.ndarray:
    """`a` rounded to a multiple of 2^-SNAP_BITS of the binade of `scale` (its largest
    magnitude, or the scale it is compared at): the digits the choices read. `scale` an
    array (a's shape): each entry at its own; unchanged where a scale is not positive."""
    a = np.asarray(a, dtype=float)
    if np.ndim(scale):
        scale = np.asarray(scale, dtype=float)
        quantum = np.ldexp(1.0, np.frexp(scale)[1] - SNAP_BITS)
        return np.where(scale > 0, np.rint(a / quantum) * quantum, a) + 0.0
    if not scale > 0:
        return a + 0.0
    quantum = np.float64(math.ldexp(1.0, math.frexp(scale)[1] - SNAP_BITS))
    return np.rint(a / quantum) * quantum + 0.0


def _dot(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``A @ x`` over the last axis, summed left to right by elementwise operations (no BLAS,
    no reduction whose order could depend on the machine: the same bits everywhere)."""
    P = np.asarray(A * x, dtype=float)
    if P.shape[-1] == 0:
        return np.zeros(P.shape[:-1])
    acc = P[..., 0].copy()
    for j in range(1, P.shape[-1]):
        acc += P[..., j]
    return acc


def start_state(problem, table) -> np.ndarray:
    """The law's state at t0 as the oracle starts it: ``x0``, with a delay ``[x0; u_hold]``."""
    x0 = np.asarray(problem.x0, dtype=float)
    if getattr(table, "delay_ticks", 0):
        x0 = np.concatenate([x0, np.asarray(table.u_hold, dtype=float)[:table.dims[1]]])
    return x0


def latch_grid(lam0: np.ndarray, Lam: np.ndarray, m: np.ndarray) -> np.ndarray:
    """The grid of each latched row's ``lambda0`` (width,): the float32 spacing in the binade
    of the row's largest term at the planned state m, ``max(|lambda0_i|, |Lambda_ij m_j|)``
    (the scale of the multiplier it latches). A ``lambda0`` far below it (an exact zero the
    re-solve leaves at 1e-10, whose digits move with the design's last bits) keeps none of
    those digits, as the spline's coefficients on the grid of their entry's peak."""
    peak = np.maximum(np.abs(lam0), np.abs(Lam * m).max(axis=1, initial=0.0))
    return np.ldexp(1.0, np.frexp(np.where(peak > 0, peak, 1.0))[1] - 24)


def _sum_columns(P: np.ndarray) -> np.ndarray:
    """``P``'s rows (n, N) summed left to right (row 0 first), elementwise: `_dot`'s sums."""
    acc = P[0].copy()
    for j in range(1, P.shape[0]):
        acc += P[j]
    return acc


def _option_template(coarse: int, fine: bool) -> np.ndarray:
    """The steps of a row's candidates in `_latch_options`' order, (coarse + 2, size): the
    coarse entries' (-1, 0, 1 each, the first fastest), lambda0's (the grid point below,
    at or above its nearest) and the fine entry's (0 without one); the first the slowest
    axis, then lambda0's, then the fine entry's."""
    digits = (np.arange(3 ** coarse)[:, None] // 3 ** np.arange(coarse)) % 3 - 1
    reps = 9 if fine else 3
    steps = np.repeat(digits, reps, axis=0).T
    shift = np.tile(np.repeat([-1.0, 0.0, 1.0], reps // 3), 3 ** coarse)
    fine_k = np.tile([-1.0, 0.0, 1.0], 3 ** (coarse + 1)) if fine else np.zeros(shift.size)
    return np.vstack([steps, shift, fine_k]).astype(float)


_TEMPLATES = {(c, f): _option_template(c, f) for c in range(FLIP_ENTRIES + 1)
              for f in (False, True)}


def _latch_options(v: np.ndarray, Lam: np.ndarray, m: np.ndarray, q: np.ndarray, keep: int
                   ) -> tuple[list[np.ndarray], np.ndarray, np.ndarray, np.ndarray]:
    """Each latched row's `keep` best candidates, best first: ``(e, rows, z, start)``, the
    rows' candidates one after the other (row i's from ``start[i]``), ``e`` split per row:
    the Lambda rows (float32 values), the lambda0 values and ``e``, the error of the multiplier
    latched at m, ``lambda0_32 + Lambda_32 m - v_i``, in units of the row's grid ``q_i``;
    ``v_i = lambda0 + Lambda m`` is the exact multiplier at m (snapped), `Lam` the exact
    rows (width, n).

    The entries that move the multiplier at m (a nonzero planned state; their effect: one
    float32 step times ``|m_j|``), at most FLIP_ENTRIES: the finest that can still move it by
    half a grid step within FINE_STEPS steps may move by k float32 steps, ``|k|`` at most
    FINE_STEPS and ``max(1, q / its effect)`` (its term moves by at most one grid step q),
    the three k nearest the one that cancels the rest of the error; the others, the largest
    effect first (ties by index), take their nearest float32 or either neighbour; lambda0
    the three grid points next to its target ``lambda0 + (Lambda - Lambda_32) m``.

    Every row's candidates are the columns of one matrix (n, N), a row's contiguous and in
    the order of `_option_template`; each number is computed by the elementwise operations
    of a row on its own, the sums over the entries left to right as `_dot`'s (the same bits
    as one row at a time); ties keep that order (a stable sort)."""
    width, n = Lam.shape
    near32 = Lam.astype(np.float32)
    near = near32.astype(float)
    ulp = np.spacing(np.abs(near32)).astype(float)
    effect = np.where(Lam != 0, ulp * np.abs(m), 0.0)
    # The movers of each row, the largest effect first, ties by index (a stable sort): the
    # first n_movers of its order; the finest entry that can still cancel half a grid step
    # within FINE_STEPS steps, the last of the first n_able (the able ones are a prefix).
    order = np.argsort(-effect, axis=1, kind="stable").tolist()
    moves = effect > 0
    n_movers = moves.sum(axis=1).tolist()
    n_able = (moves & (effect * FINE_STEPS >= q[:, None] / 2)).sum(axis=1).tolist()
    slots, fine, parts = [], [], []
    for i in range(width):
        movers = order[i][:n_movers[i]]
        f = movers[n_able[i] - 1] if n_able[i] else -1
        coarse = [j for j in movers if j != f][:FLIP_ENTRIES - (f >= 0)]
        slots.append(coarse)
        fine.append(f)
        parts.append(_TEMPLATES[len(coarse), f >= 0])
    sizes = [p.shape[1] for p in parts]
    ends = np.cumsum(sizes).tolist()
    spans = [(e - size, e) for e, size in zip(ends, sizes)]
    steps = np.concatenate([p[-2:] for p in parts], axis=1)   # lambda0's, the fine entry's
    cand = np.repeat(near.T, sizes, axis=1)                    # (n, N), a row's contiguous
    for i, (a, b) in enumerate(spans):
        for k, j in enumerate(slots[i]):
            cand[j, a:b] += parts[i][k] * ulp[i, j]
    row = np.repeat(np.arange(width), sizes)
    vr, qr, mc = v[row], q[row], m[:, None]
    target = vr - _sum_columns(cand * mc)
    z = (np.rint(target / qr) + steps[0]) * qr
    if any(f >= 0 for f in fine):
        per_step = np.array([ulp[i, f] * m[f] if f >= 0 else 1.0 for i, f in enumerate(fine)])
        most = np.minimum(float(FINE_STEPS), np.maximum(1.0, np.floor(q / np.abs(per_step))))
        k = np.clip(np.rint(-(z - target) / per_step[row]) + steps[1], -most[row], most[row])
        for i, (a, b) in enumerate(spans):
            if fine[i] >= 0:
                cand[fine[i], a:b] += k[a:b] * ulp[i, fine[i]]
    cand = cand.astype(np.float32).astype(float)       # float32 values, as stored
    e = (z + _sum_columns(cand * mc) - vr) / qr
    # Each row's best first, ties in the row's order (a stable sort).
    if len(set(sizes)) == 1:
        best = np.argsort(np.abs(e).reshape(width, -1), axis=1, kind="stable")[:, :keep]
        pick = (best + np.arange(0, e.size, sizes[0])[:, None]).ravel()
    else:
        pick = np.concatenate([a + np.argsort(np.abs(e[a:b]), kind="stable")[:keep]
                               for a, b in spans])
    e = e[pick]
    at = np.cumsum([0] + [min(keep, size) for size in sizes]).tolist()
    return ([e[a:b] for a, b in zip(at[:-1], at[1:])], cand[:, pick].T, z[pick],
            np.array(at[:-1]))


def _row_keep(width: int) -> int:
    """How many of each row's best options enter the joint choice: as many as keep the
    combinations within JOINT_MAX (all of them for one or two rows)."""
    k = int(np.floor(JOINT_MAX ** (1.0 / width) * (1 + 1e-12)))
    return max(1, k)


def _choose(G: np.ndarray, q: np.ndarray, errors: list[np.ndarray]) -> np.ndarray:
    """The index of each row's option (errors[i], in units of q_i) whose combination makes
    the group's constraints' worst error ``max |G (q e)|`` smallest; ties to the first
    (each row's options are best first, so the product order is deterministic)."""
    # On the grid of the rows' options (axis i: row i's), the constraints' errors summed
    # left to right, row by row: the products and sums of `_dot` over the combinations
    # (row-major, as the grid's ravel), without building them.
    # The constraints' axis first: the worst error is then the elementwise maximum of
    # contiguous slabs (exact in any order).
    width = len(errors)
    acc = None
    for i, e in enumerate(errors):
        shape = [G.shape[0]] + [1] * width
        shape[1 + i] = e.size
        term = (G[:, i][:, None] * (e * q[i])[None, :]).reshape(shape)
        acc = term if acc is None else acc + term
    worst = np.abs(acc, out=acc).max(axis=0)
    return np.array(np.unravel_index(int(np.argmin(worst)), worst.shape))


def round_latch(problem, table, groups, Lam: np.ndarray, lam0: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """The exact latch maps rounded to float32, chosen on the float32 grid to meet the
    design's constraints at its planned start.

    Group by group, in order: the state m planned at the latch (x0 at the first; the mean
    under the law as stored, earlier groups rounded, at later ones) is where the design
    meets its constraints. Each Lambda entry takes its nearest float32 or a neighbour (the
    finest that moves the multiplier, a few float32 steps), each lambda0 a point of its
    row's grid (`latch_grid`) next to its target ``lambda0 + (Lambda - Lambda_32) m`` (the
    rounding of Lambda compensated at m), so that
    each latched multiplier at m misses its exact value by a fraction of a grid step; of
    these, the combination of the group's rows that makes the worst constraint error at m,
    ``max |C2 Gamma (v_32(m) - v(m))|``, smallest (`_latch_options`, `_choose`). No term
    ``Lambda_ij m_j`` moves by more than one grid step of its row (or one float32 step of
    its entry), so the residual at other starts moves by about that. Entries of exactly
    zero stay zero. The choices read their inputs rounded to SNAP_BITS bits (`_snap`), so
    that they do not flip with the design's last bits."""
    n = table.dims[0]
    # Round-off of exact zeros (below 1e-12 of the array's largest) is flushed first, as in
    # a per-tick table (`format._to_float32`); rows outside the groups (padding, stages
    # without a latch) are then rounded to nearest, as ever.
    Lam, lam0 = (np.where(np.abs(a) < 1e-12 * np.abs(a).max(initial=0.0), 0.0, a)
                 for a in (np.asarray(Lam, dtype=float), np.asarray(lam0, dtype=float)))
    L32 = Lam.astype(np.float32).astype(float)
    l032 = lam0.astype(np.float32).astype(float)
    m = start_state(problem, table)
    for latch, width, _, blocks, CW, _ in groups:
        if latch is None:                        # stages before the first latch: v = 0
            for P in blocks:
                m = P[:, :n] @ m + P[:, -1]
            continue
        Li, li = Lam[latch, :width], lam0[latch, :width]
        q = latch_grid(li, Li, m)
        ms = _snap(m, np.abs(m).max(initial=0.0))
        # The exact multipliers at m, on their rows' scales (the grids' binades).
        v = _snap(li + _dot(Li, ms), q * 2.0 ** 24)
        errors, rows, z, start = _latch_options(v, Li, ms, q, _row_keep(width))
        G = CW[:, n:n + width]
        pick = start + _choose(_snap(G, np.abs(G).max()), q, errors)
        L32[latch, :width] = rows[pick]
        l032[latch, :width] = z[pick]
        v = l032[latch, :width] + L32[latch, :width] @ m
        for P in blocks:                         # the planned mean to the next latch
            m = P[:, :n] @ m + P[:, n:n + width] @ v + P[:, -1]
    return L32.astype(np.float32), l032.astype(np.float32)
