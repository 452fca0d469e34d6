"""Ticks of stages whose data vary in time, in C (``varying_kernel.c``): the exact ZOH
designer's backward recursion and the moment oracle's forward one.

Over a tick the moment equations' generator is interpolated through ``P`` Gauss–Legendre
points (the designer: 2, order 4; the oracle: 3, order 6) and the resulting linear ODE is
solved by its Taylor series to rounding, so a tick costs a few generator actions on one
``d x d`` matrix instead of an exponential of a ``d^2``-square map. The data at the Gauss
points are sampled for a chunk of ticks at once (`Stage.samples`, vectorised for data read
from a file) and handed to C; the recursion state passes from chunk to chunk.
"""
from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np

from stospline.expm import NonFiniteMatrix
from stospline.problem.model import Stage

__all__ = ["POINTS", "TickSamples", "Segments", "segment_operators", "tick_samples", "zoh_ticks",
           "oracle_ticks", "mean_maps"]

POINTS = 2            # Gauss points per tick (order 4), designer and oracle alike
MEAN_TERMS = 60        # `mean_maps`: Taylor terms at most (as the C kernel's TV_MAX_TERMS)
CHUNK = 512            # ticks sampled and handed to C at once (bounds the memory)

# How the C loops apply the diffusion (``varying_kernel.c``, noise_lists): "auto" picks the
# cheapest per tick; "pairs" (nonzero pairs), "columns" (Brownian column by column),
# "operator" (the packed na(na+1)/2 x n(n+1)/2 matrix of the diffusion operator, built from G
# at each point) and "segments" (that operator formed from the three of the point's segment,
# `segment_operators`; "operator" where there are none) force one, for tests and benchmarks.
# All give the same numbers to rounding.
NOISE_PATHS = {"auto": 0, "pairs": 1, "columns": 2, "operator": 3, "segments": 4}
NOISE_PATH = "auto"


def _gauss(P: int):
    """Gauss–Legendre nodes on [0, 1] and the coefficients of their Lagrange basis
    polynomials, forward (in s) and backward (in 1 - s): ``l_i(s) = sum_l coef[i, l] s^l``."""
    x, _ = np.polynomial.legendre.leggauss(P)
    nodes = 0.5 * (x + 1.0)

    def basis(pts):
        V = np.vander(pts, P, increasing=True)       # V[j, l] = pts_j^l
        return np.ascontiguousarray(np.linalg.inv(V).T)

    return nodes, basis(nodes), basis(1.0 - nodes)


@dataclass(frozen=True)
class TickSamples:
    """The data of `T` ticks at `P` points each, laid out for the C kernels: ``Ar`` (T, P, n,
    d) the rows ``[A, B, f]``, ``G`` (T, P, na, n, mz) the diffusion of the active
    multipliers ``act`` (indices into ``[x; u]``), ``Lb`` (T, P, d, d) the running cost. A
    field that is constant over the chunk is held once, shape (1, 1, ...), and flagged in
    ``same`` (Ar, G, Lb); ``ar_nz`` lists where Ar can be nonzero (row-major in n x d)."""
    Ar: np.ndarray
    G: np.ndarray
    Lb: np.ndarray
    act: np.ndarray
    same: np.ndarray
    ar_nz: np.ndarray      # positions in (n, d) where Ar is nonzero at some tick of the chunk
    segs: "Segments | None" = None   # the diffusion's operators per segment, if affine


@dataclass(frozen=True)
class Segments:
    """The noise of a chunk by segments between the noise's sample times (`segment_operators`):
    ``act`` the active multipliers, ``ends`` (S, 2, na, n, mz) the diffusion at the two ends
    of each segment the chunk's points fall in, ``ops`` (S, 3, R, C) and ``ops_t`` (S, 3, C,
    R) their three packed operators (``R = na(na+1)/2``, ``C = n(n+1)/2``; the oracle's
    layout and the designer's), ``idx`` (T P) the segment of each point and ``w`` (T P) its
    place in it, in [0, 1]."""
    act: np.ndarray
    ends: np.ndarray
    ops: np.ndarray
    ops_t: np.ndarray
    idx: np.ndarray
    w: np.ndarray

    @property
    def nbytes(self) -> int:
        return sum(a.nbytes for a in (self.ends, self.ops, self.ops_t, self.idx, self.w))


OPERATOR_MAX = 1 << 18     # doubles of one packed operator, at most (the C TV_MAX_OPERATOR)
SEGMENT_DOUBLES = 1 << 21  # doubles of a chunk's segment operators (each layout), at most
TERMS_GUESS = 8            # noisy series terms per tick, for the cost model (as the C kernel's)


def _segments_pay(GH: np.ndarray, R: int, C: int) -> bool:
    """Whether forming each point's operator from its segment's (``(K + 3) R C`` per point, K
    series terms) is cheaper than the way the C loops would otherwise apply the diffusion
    (``noise_lists``: nonzero pairs or Brownian columns), with the nonzero pattern of the
    segments' ends `GH` (ends, na, n, mz); always when the path is forced to "segments"."""
    if NOISE_PATH == "segments":
        return True
    _, na, n, mz = GH.shape
    nnz = (GH != 0.0).any(axis=0).sum(axis=(0, 1)).astype(float)    # per Brownian column
    pairs, dense = float(nnz @ nnz), float(na * n * (n + na) * mz)
    other = TERMS_GUESS * (pairs if pairs <= dense else 0.75 * dense)
    return (TERMS_GUESS + 3) * R * C < other


def _pair_operator(X: np.ndarray, Y: np.ndarray, rows, cols) -> np.ndarray:
    """The packed ``B(X, Y)[(p, q), (a, b)] = sum_k X_p[a, k] Y_q[b, k] + X_q[a, k] Y_p[b, k]``
    (p <= q, a <= b, row by row), X and Y (na, n, mz); ``B(G, G)`` is the C kernel's operator
    F of G (``build_operator``)."""
    na, n, mz = X.shape
    gram = (X.reshape(-1, mz) @ Y.reshape(-1, mz).T).reshape(na, n, na, n)   # [p, a, q, b]
    return (gram[rows[0][:, None], cols[0][None, :], rows[1][:, None], cols[1][None, :]]
            + gram[rows[1][:, None], cols[0][None, :], rows[0][:, None], cols[1][None, :]])


# Whether segments pay for a stage's noise at all (`_stage_pays`), per stage object (the entry
# holds the stage, so its id cannot be reused while kept) and path; the oldest dropped.
_PAYS: dict = {}
PAYS_KEPT = 64


def _stage_pays(stage: Stage, knots: np.ndarray) -> bool:
    """`_segments_pay` on the nonzero pattern of the noise at every knot of `stage` (an upper
    bound of any chunk's): sparse noise is told once per stage, without sampling its knots
    chunk by chunk."""
    key = id(stage)
    with _CACHE_LOCK:
        hit = _PAYS.get(key)
    if hit is not None and hit[0] is stage and hit[1] == NOISE_PATH:
        return hit[2]
    s = stage.samples(knots)
    GH = s["G"] if s["H"] is None else np.concatenate([s["G"], s["H"]], axis=1)
    GH = GH[:, GH.any(axis=(0, 2, 3))]
    na, n = GH.shape[1], stage.B.shape[0]
    R, C = na * (na + 1) // 2, n * (n + 1) // 2
    pays = 0 < na and R * C <= OPERATOR_MAX and _segments_pay(GH, R, C)
    with _CACHE_LOCK:
        while len(_PAYS) >= PAYS_KEPT:
            _PAYS.pop(next(iter(_PAYS)))
        _PAYS[key] = (stage, NOISE_PATH, pays)
    return pays


def segment_operators(stage: Stage, times: np.ndarray, T: int) -> Segments | None:
    """The noise at `times` (T ticks' points) by segments, when it is interpolated linearly
    between sample times (``stage.varying.noise_knots``).

    On a segment between sample times with end values G_L, G_R, ``G(w) = (1 - w) G_L + w
    G_R`` and, the operator F being quadratic in G, ``F(w) = (1 - w)^2 F(G_L) + w (1 - w)
    (B(G_L, G_R) + B(G_R, G_L)) + w^2 F(G_R)``: three operators per segment, built once
    (``3 mz R C``), then 3 R C to form a point's, instead of 2 mz R C to build it from G at
    every point of every tick; and G is not sampled at the points (the C loops interpolate
    it). The active multipliers are those nonzero at an end of a segment. None when the noise
    is not so interpolated, is zero, its operator is too large, the chunk spans more than T/2
    segments or their operators more than `SEGMENT_DOUBLES`, the diffusion is cheaper
    applied otherwise (`_segments_pay`: sparse noise), or the path is forced to another."""
    knots = getattr(stage.varying, "noise_knots", None)
    if (knots is None or knots.size < 2 or NOISE_PATH not in ("auto", "segments")
            or not _stage_pays(stage, knots)):
        return None
    seg = np.clip(np.searchsorted(knots, times, side="right") - 1, 0, knots.size - 2)
    used = np.unique(seg)
    if 2 * used.size > T:
        return None
    n = stage.B.shape[0]
    at = np.union1d(used, used + 1)
    s = stage.samples(knots[at])
    GH = s["G"] if s["H"] is None else np.concatenate([s["G"], s["H"]], axis=1)
    act = np.flatnonzero(GH.any(axis=(0, 2, 3))).astype(np.intc)
    na = act.size
    R, C = na * (na + 1) // 2, n * (n + 1) // 2
    if na == 0 or R * C > OPERATOR_MAX or 3 * used.size * R * C > SEGMENT_DOUBLES:
        return None
    GH = GH[:, act]
    if not _segments_pay(GH, R, C):
        return None
    rows, cols = np.triu_indices(na), np.triu_indices(n)
    own = [_pair_operator(g, g, rows, cols) for g in GH]
    ops = np.empty((used.size, 3, R, C))
    left = np.searchsorted(at, used)
    for j, e in enumerate(left):
        L, Rg = GH[e], GH[e + 1]
        ops[j, 0], ops[j, 2] = own[e], own[e + 1]
        ops[j, 1] = _pair_operator(L, Rg, rows, cols) + _pair_operator(Rg, L, rows, cols)
    ends = np.ascontiguousarray(np.stack([GH[left], GH[left + 1]], axis=1))
    w = np.clip((times - knots[seg]) / (knots[seg + 1] - knots[seg]), 0.0, 1.0)
    return Segments(act, ends, ops, np.ascontiguousarray(ops.swapaxes(2, 3)),
                    np.searchsorted(used, seg).astype(np.intc), np.ascontiguousarray(w))


def _constant(a) -> bool:
    """A stacked field from `Stage.samples` that is a broadcast constant."""
    return a is None or a.strides[0] == 0


def tick_samples(stage: Stage, t_first: float, h: float, T: int, nodes: np.ndarray,
                 segments: bool = True) -> TickSamples:
    """Sample `stage` at the `nodes` (fractions of a tick) of ticks ``t_first + j h``; with
    `segments`, the diffusion's `segment_operators` too when the noise varies."""
    n, m = stage.B.shape
    d = n + m + 1
    P = nodes.size
    times = (t_first + h * (np.arange(T)[:, None] + nodes[None, :])).ravel()
    segs = segment_operators(stage, times, T) if segments else None
    s = stage.samples(times, noise=segs is None)
    same = [all(_constant(s[k]) for k in keys) and not (segs is not None and keys[0] == "G")
            for keys in (("A", "B", "f"), ("G", "H"), ("Q", "S", "R", "q", "r", "rho"))]
    pick = [slice(0, 1) if c else slice(None) for c in same]
    first = {k: (None if v is None else v[pick[i]])
             for i, keys in enumerate((("A", "B", "f"), ("G", "H"),
                                        ("Q", "S", "R", "q", "r", "rho")))
             for k, v in s.items() if k in keys}
    TA = first["A"].shape[0]
    drift = [first["A"], np.broadcast_to(first["B"], (TA, n, m)),
             np.zeros((TA, n, 1)) if first["f"] is None
             else np.broadcast_to(first["f"], (TA, n))[:, :, None]]
    Ar = np.concatenate(drift, axis=2)
    if segs is None:
        # The diffusion of the multipliers that are nonzero somewhere in the chunk, gathered
        # from G (state multipliers) and H (input multipliers) without stacking them first.
        parts = [(first["G"], 0)] + ([(first["H"], n)] if first["H"] is not None else [])
        live = [(np.flatnonzero(g.any(axis=(0, 2, 3))), g, o) for g, o in parts]
        act = np.concatenate([rows + o for rows, _, o in live]).astype(np.intc)
        G = np.concatenate([g[:, rows] for rows, g, _ in live], axis=1)
    else:                   # not sampled: the C loops interpolate it from the segments' ends
        act = segs.act
        G = np.empty((0, 0) + segs.ends.shape[2:])
    TL = first["Q"].shape[0]
    Lb = np.zeros((TL, d, d))
    Lb[:, :n, :n], Lb[:, n:n + m, n:n + m] = first["Q"], first["R"]
    Lb[:, :n, n:n + m] = first["S"]
    Lb[:, n:n + m, :n] = np.swapaxes(first["S"], 1, 2)
    Lb[:, :n, -1] = Lb[:, -1, :n] = first["q"]
    Lb[:, n:n + m, -1] = Lb[:, -1, n:n + m] = first["r"]
    Lb[:, -1, -1] = first["rho"]

    def lay(a, const):
        shape = (1, 1) if const else (T, P)
        return np.ascontiguousarray(a.reshape(shape + a.shape[1:]))

    ar_nz = np.flatnonzero(np.any(Ar != 0.0, axis=0)).astype(np.intc)
    return TickSamples(lay(Ar, same[0]), G if segs is not None else lay(G, same[1]),
                       lay(Lb, same[2]), act, np.array(same, dtype=np.intc), ar_nz, segs)


# Samples of recent chunks: the oracle evaluates the design's own law and its float32 table
# on the same ticks. Keyed by the stage object's id (the entry holds the stage, so the id
# cannot be reused while cached), bounded in bytes.
_CACHE: dict = {}
_CACHE_LOCK = threading.Lock()       # the oracle's two evaluations may run in threads
CACHE_BYTES = 128 << 20


def cached_samples(stage: Stage, t_first: float, h: float, T: int, nodes: np.ndarray
                   ) -> TickSamples:
    """`tick_samples`, remembered for the next call with the same arguments."""
    key = (id(stage), float(t_first), float(h), int(T), nodes.tobytes(), NOISE_PATH)
    with _CACHE_LOCK:
        hit = _CACHE.get(key)
    if hit is not None and hit[0] is stage:
        return hit[1]
    smp = tick_samples(stage, t_first, h, T, nodes)
    size = smp.Ar.nbytes + smp.G.nbytes + smp.Lb.nbytes \
        + (0 if smp.segs is None else smp.segs.nbytes)
    with _CACHE_LOCK:
        while _CACHE and sum(v[2] for v in _CACHE.values()) + size > CACHE_BYTES:
            _CACHE.pop(next(iter(_CACHE)))              # the oldest entry
        if size <= CACHE_BYTES:
            _CACHE[key] = (stage, smp, size)
    return smp


def _chunks(T: int):
    return [(a, min(a + CHUNK, T)) for a in range(0, T, CHUNK)]


_ERR_NOT_PD, _ERR_SERIES = -1, -3


def _check(status: int, name: str, a: int, b: int) -> None:
    """A kernel status as the numpy paths report it: a series that does not converge means
    non-finite data or data whose products overflow (`NonFiniteMatrix`, a FloatingPointError
    the pipeline names the extreme input of); anything else is a bug."""
    if status == _ERR_SERIES:
        raise NonFiniteMatrix(f"{name}: the tick series did not converge at ticks {a}..{b} "
                              f"(non-finite or overflowing data)")
    if status != 0:
        raise RuntimeError(f"{name}: status {status} at ticks {a}..{b}")


def _ptr(ffi, a, kind="double[]"):
    """A C pointer into `a` (C-contiguous), or to a dummy element when `a` is empty."""
    return ffi.from_buffer(kind, a) if a.size else ffi.new(kind.replace("[]", "[1]"))


def _noise_path() -> int:
    return NOISE_PATHS[NOISE_PATH]


def _data_args(ffi, smp: TickSamples, adjoint: bool):
    """The kernels' data arguments; `adjoint`: the designer's (the operators transposed)."""
    sg = smp.segs
    segs = (0, ffi.NULL, ffi.NULL, ffi.NULL, ffi.NULL) if sg is None else (
        sg.ops.shape[0], _ptr(ffi, sg.ops_t if adjoint else sg.ops), _ptr(ffi, sg.ends),
        _ptr(ffi, sg.idx, "int[]"), _ptr(ffi, sg.w))
    return (smp.act.size, smp.G.shape[-1]), (
        _ptr(ffi, smp.act, "int[]"), _ptr(ffi, smp.Ar), _ptr(ffi, smp.G), _ptr(ffi, smp.Lb),
        _ptr(ffi, smp.same, "int[]"), _ptr(ffi, smp.ar_nz, "int[]"), smp.ar_nz.size, *segs)


def zoh_ticks(stage: Stage, t_start: float, h: float, V, N, W, mv, T: int, m: int):
    """`zoh._stage_ticks_numpy` for a time-varying stage: gains per tick and the value
    before the stage's first tick. Raises `numpy.linalg.LinAlgError` (Huu not positive
    definite) or `NonFiniteMatrix` (a series that does not converge: non-finite data)."""
    from stospline.design.kernels import load_kernels
    mod = load_kernels()
    ffi, lib = mod.ffi, mod.lib
    n, q = N.shape
    nodes, _, coef = _gauss(POINTS)
    V, N, W, mv = (np.array(a, dtype=np.float64, order="C") for a in (V, N, W, mv))
    K, k0, L = np.empty((T, m, n)), np.empty((T, m)), np.empty((T, m, q))
    bad = ffi.new("long *", -1)
    for a, b in reversed(_chunks(T)):
        smp = cached_samples(stage, t_start + a * h, h, b - a, nodes)
        (na, mz), data = _data_args(ffi, smp, True)
        work = np.empty(int(lib.stsp_tv_zoh_work_size(n, m, q, na, mz)))
        iwork = np.empty(int(lib.stsp_tv_iwork_size(n, m, na, mz)), dtype=np.intc)
        status = lib.stsp_tv_zoh_ticks(
            n, m, q, b - a, POINTS, na, mz, _ptr(ffi, coef), h, *data,
            *(_ptr(ffi, x) for x in (V, N, W, mv, K[a:b], k0[a:b], L[a:b], work)),
            _ptr(ffi, iwork, "int[]"), _noise_path(), bad)
        if status == _ERR_NOT_PD:
            raise np.linalg.LinAlgError(f"Huu is not positive definite at tick {a + bad[0]}")
        _check(status, "stsp_tv_zoh_ticks", a, b)
    return K, k0, L, V, N, W, mv


def oracle_ticks(stage: Stage, t_start: float, h: float, K, L, k0, M, J: float,
                 record: bool):
    """The oracle's ticks over a time-varying stage (``evaluate_table``'s loop): the second
    moment `M` of ``[x; v; 1]`` and the cost `J` after them and, when `record`, the mean and
    variance of x after each tick and of the command over it (else four None)."""
    from stospline.design.kernels import load_kernels
    mod = load_kernels()
    ffi, lib = mod.ffi, mod.lib
    T, m, n = K.shape
    n_latch = L.shape[2]
    nodes, coef, _ = _gauss(POINTS)
    K, L, k0 = (np.ascontiguousarray(a, dtype=np.float64) for a in (K, L, k0))
    M = np.array(M, dtype=np.float64, order="C")
    Jp = ffi.new("double *", float(J))
    rec = [np.empty((T, n)), np.empty((T, n)), np.empty((T, m)), np.empty((T, m))]
    for a, b in _chunks(T):
        smp = cached_samples(stage, t_start + a * h, h, b - a, nodes)
        (na, mz), data = _data_args(ffi, smp, False)
        work = np.empty(int(lib.stsp_tv_oracle_work_size(n, m, n_latch, na, mz)))
        iwork = np.empty(int(lib.stsp_tv_iwork_size(n, m, na, mz)), dtype=np.intc)
        out = [_ptr(ffi, x[a:b]) if record else ffi.NULL for x in rec]
        status = lib.stsp_tv_oracle_ticks(
            n, m, n_latch, b - a, _ptr(ffi, K[a:b]), _ptr(ffi, L[a:b]), _ptr(ffi, k0[a:b]),
            POINTS, na, mz, _ptr(ffi, coef), h, *data, _ptr(ffi, M), Jp,
            *out, _ptr(ffi, work), _ptr(ffi, iwork, "int[]"), _noise_path())
        _check(status, "stsp_tv_oracle_ticks", a, b)
    return (M, float(Jp[0]), *(rec if record else (None,) * 4))


def euler_oracle_ticks(stage: Stage, t_start: float, h: float, substeps: int, K, L, k0, M,
                       J: float, record: bool):
    """`oracle_ticks` for the Monte Carlo plant scheme (the oracle's "euler" propagator):
    `substeps` exponential Euler–Maruyama steps per tick, each with the data at its midpoint
    as the harness takes them (`montecarlo._plant_tick`), ``exp(Ahat dt)`` per step."""
    from stospline.design.kernels import load_kernels
    from stospline.expm import expm_many
    mod = load_kernels()
    ffi, lib = mod.ffi, mod.lib
    T, m, n = K.shape
    n_latch = L.shape[2]
    dt = h / substeps
    mid = (np.arange(substeps) + 0.5) / substeps        # step midpoints, fractions of a tick
    K, L, k0 = (np.ascontiguousarray(a, dtype=np.float64) for a in (K, L, k0))
    M = np.array(M, dtype=np.float64, order="C")
    Jp = ffi.new("double *", float(J))
    rec = [np.empty((T, n)), np.empty((T, n)), np.empty((T, m)), np.empty((T, m))]
    d = n + m + 1
    for a, b in _chunks(T):
        smp = tick_samples(stage, t_start + a * h, h, b - a, mid, segments=False)
        Ahat = np.zeros(smp.Ar.shape[:2] + (d, d))
        Ahat[..., :n, :] = smp.Ar
        Ad = expm_many(Ahat.reshape(-1, d, d) * dt)
        if smp.same[0]:                                 # one drift for the whole chunk
            Ad = np.repeat(Ad, (b - a) * substeps, axis=0)
        Ad = np.ascontiguousarray(Ad)
        na, mz = smp.act.size, smp.G.shape[-1]
        work = np.empty(int(lib.stsp_tv_euler_work_size(n, m, n_latch, na, mz)))
        iwork = np.empty(int(lib.stsp_tv_iwork_size(n, m, na, mz)), dtype=np.intc)
        out = [_ptr(ffi, x[a:b]) if record else ffi.NULL for x in rec]
        status = lib.stsp_tv_euler_oracle_ticks(
            n, m, n_latch, b - a, _ptr(ffi, K[a:b]), _ptr(ffi, L[a:b]), _ptr(ffi, k0[a:b]),
            substeps, na, mz, dt, _ptr(ffi, smp.act, "int[]"), _ptr(ffi, Ad),
            _ptr(ffi, smp.G), _ptr(ffi, smp.Lb), _ptr(ffi, smp.same, "int[]"), _ptr(ffi, M),
            Jp, *out, _ptr(ffi, work), _ptr(ffi, iwork, "int[]"))
        _check(status, "stsp_tv_euler_oracle_ticks", a, b)
    return (M, float(Jp[0]), *(rec if record else (None,) * 4))


def mean_maps(stage: Stage, t_start: float, h: float, T: int) -> np.ndarray:
    """The mean map of each of `T` ticks from `t_start` of a time-varying stage, as the oracle
    (`oracle_ticks`) and the designer discretise it: ``F`` (T, n, n + m + 1) with ``E x+ =
    F_j [x; u; 1]`` over tick j, the command held, for the generator interpolated through the
    `POINTS` Gauss points of the tick, solved to rounding by its Taylor series (the C
    kernel's MEAN series, here batched over the ticks).

    The data are sampled chunk by chunk as the oracle samples them (`cached_samples`: the
    same times, and the oracle's cached samples when it has run). Over a sub-step r in [0, 1]
    of a tick, ``dF/dr = hs (A(r) F + [0, B(r), f(r)])`` with ``[A, B, f](r) = sum_l Arl[l]
    r^l``; a chunk's sub-steps keep ``hs sum_l |Arl[l]| <= 1/2``, so a few tens of terms
    reach rounding. Raises `NonFiniteMatrix` when the series does not converge (non-finite
    or overflowing data)."""
    n, m = stage.B.shape
    d = n + m + 1
    nodes, coef, _ = _gauss(POINTS)
    out = np.empty((T, n, d))
    for a, b in _chunks(T):
        smp = cached_samples(stage, t_start + a * h, h, b - a, nodes)
        if smp.same[0]:             # one drift for the chunk, held once: a constant
            Arl = np.zeros((1, POINTS) + smp.Ar.shape[2:])
            Arl[:, 0] = smp.Ar[:, 0]
        else:                       # sum_i coef[i, l] Ar[t, i]: a polynomial in s per tick
            Arl = np.einsum("il,tiab->tlab", coef, smp.Ar)
        bound = np.abs(Arl).sum(axis=3).max(axis=2).sum(axis=1).max()
        need = 2.0 * h * bound
        if not np.isfinite(need) or need > 1 << 16:
            raise NonFiniteMatrix(f"mean_maps: the tick series does not converge at ticks "
                                  f"{a}..{b} (non-finite or overflowing data)")
        sub = 1 if need <= 1.0 else int(need) + 1
        F = np.zeros((Arl.shape[0], n, d))
        F[:, :, :n] = np.eye(n)
        for j in range(sub):
            F = _mean_substep(F, _shifted(Arl, j, sub), h / sub, n, a, b)
        out[a:b] = F                      # one map for every tick when the data are constant
    return out


def _shifted(Arl: np.ndarray, j: int, sub: int) -> np.ndarray:
    """The coefficients of `Arl` (in s) in the variable r of sub-step j of `sub`, ``s = (j +
    r) / sub``: ``sum_l Arl[l] ((j + r) / sub)^l = sum_e out[e] r^e``."""
    if sub == 1:
        return Arl
    P = Arl.shape[1]
    out = np.zeros_like(Arl)
    from math import comb
    for e in range(P):
        for l in range(e, P):
            out[:, e] += Arl[:, l] * (comb(l, e) * float(j) ** (l - e) / float(sub) ** l)
    return out


def _mean_substep(F: np.ndarray, Arl: np.ndarray, hs: float, n: int, a: int, b: int
                  ) -> np.ndarray:
    """``F(1)`` of ``dF/dr = hs Ar(r) [F; 0, I]`` from ``F(0) = F`` (batched over ticks):
    Taylor terms ``(k+1) c_{k+1} = hs sum_l Arl[l] [c_{k-l}; delta_{k-l,0} [0, I]]``."""
    P = Arl.shape[1]
    A, rest = Arl[..., :n], Arl[..., n:]          # the columns on x, and on [u; 1]
    terms = [F]
    total = F.copy()
    scale = np.abs(F).max()
    for k in range(MEAN_TERMS):
        nxt = np.zeros_like(F)
        for l in range(min(k, P - 1) + 1):
            nxt += A[:, l] @ terms[k - l]
            if k == l:                             # the identity rows below c_0
                nxt[..., n:] += rest[:, l]
        nxt *= hs / (k + 1)
        terms.append(nxt)
        total += nxt
        scale = max(scale, np.abs(total).max())
        # hs |Ar| <= 1/2: once P terms in a row are below rounding, so are all later ones.
        if k >= P - 1 and max(np.abs(t).max() for t in terms[-P:]) <= 2.0 ** -56 * scale:
            return total
    raise NonFiniteMatrix(f"mean_maps: the tick series did not converge at ticks {a}..{b} "
                          f"(non-finite or overflowing data)")
