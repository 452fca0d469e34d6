"""Gain tables: a design as the C controller evaluates it, one row per tick, quantized.

Layout (all row-major, float32, padded to ``n_latch`` multipliers with zeros)::

    K[tick][i][j]        (n_ticks, m, n)    feedback
    k0[tick][i]          (n_ticks, m)       feed-forward
    L[tick][i][c]        (n_ticks, m, n_latch)    gain of the latched multiplier v
    Lambda[stage][c][j]  (n_stages, n_latch, n)   latch map  v = Lambda x + lambda0
    lambda0[stage][c]    (n_stages, n_latch)
    u_min[i], u_max[i]   (m,)               actuator limits (+-FLT_MAX: unlimited)
    u_hold[i]            (m,)               the safe command of a refused step
    band_qp (optional)                      the band dual re-solved at the t0 latch (BandQP)
    spline (optional)                       the gains as cubic B-splines per stage
                                            (`stospline.table.spline.fit`); K, k0, L then hold
                                            their evaluation, tick by tick, as the firmware
                                            computes it, and are not written to the C

At tick ``j`` (time ``t0 + j / tick_hz``) the controller applies
``u = clip(-K x - k0 - L v, u_min, u_max)`` and holds it for one tick; at a stage's first
tick it first latches ``v`` from the state.
"""
from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np

from stospline import limits
from stospline.firmware_interface import ELEMENT_BYTES, FORMAT_VERSION, MAGIC, SCALAR_KIND

__all__ = ["GainTable", "TableShape", "BandQP", "build_table", "table_of", "TickGains",
           "table_crc32", "positive_zeros", "FORMAT_VERSION", "MAGIC", "SCALAR_FLOAT32", "F32_MAX", "BANDQP_MAX"]

BANDQP_MAX = limits.BANDQP_MAX  # rows the firmware's band solver takes (3^8 active sets)
SCALAR_FLOAT32 = SCALAR_KIND["float32"]
F32_MAX = float(np.finfo(np.float32).max)  # the firmware's "unlimited" (FLT_MAX)


def positive_zeros(a) -> np.ndarray:
    """`a` with every zero stored as +0.0, in its own floating dtype.

    Whether a computed zero comes out as +0.0 or -0.0 depends on the sign of round-off that
    the value no longer shows: the BLAS kernel OpenBLAS picks for the CPU, the thread count,
    the summation order. The sign is part of the bytes (the C literal, the CRC), so every
    float a table stores is written with +0.0. Adding +0.0 is exact for every other value
    (x + 0 = x in round-to-nearest) and maps -0.0 to +0.0 (IEEE 754, 6.3)."""
    a = np.asarray(a)
    return a + a.dtype.type(0) if a.dtype.kind == "f" else a


@dataclass(frozen=True)
class BandQP:
    """The band dual of a joint design, as the firmware solves it at the t0 latch
    (``stsp_bandqp.h``): multipliers ``lam`` maximising
    ``2 lam'e - lam'W lam - 2 sum(lam_i > 0 ? lam_i hi_i : lam_i lo_i)``, ``e = Nt x0 + mt``.
    Stored in float64 (the solver works in double precision). In a spline table W is not
    symmetric: the multipliers then solve the box LCP of `stospline.table.spline.band`."""
    Nt: np.ndarray   # (q, n)
    mt: np.ndarray   # (q,)
    W: np.ndarray    # (q, q), symmetric positive definite; a spline table's, re-solved for
                     # its gains (`stospline.table.spline.band`): a non-symmetric P-matrix
    lo: np.ndarray   # (q,) lower bounds (lo == hi: an equality row)
    hi: np.ndarray   # (q,)

    def __post_init__(self):
        for name in ("Nt", "mt", "W", "lo", "hi"):
            object.__setattr__(self, name,
                               positive_zeros(np.ascontiguousarray(getattr(self, name), float)))
        q = self.mt.shape[0]
        if not 1 <= q <= BANDQP_MAX:
            raise ValueError(f"the firmware's band solver takes 1..{BANDQP_MAX} rows, not {q}")

    @property
    def q(self) -> int:
        return int(self.mt.shape[0])

    def e(self, x0: np.ndarray) -> np.ndarray:
        return self.Nt @ np.asarray(x0, dtype=float) + self.mt


class TableShape:
    """Shape of a per-tick table (float32 or fixed point) from its ``stage_start``,
    ``stage_n_latch``, ``K`` and ``L`` arrays."""
    stage_start: np.ndarray
    stage_n_latch: np.ndarray
    K: np.ndarray
    L: np.ndarray

    @property
    def n_ticks(self) -> int:
        return int(self.stage_start[-1])

    @property
    def n_stages(self) -> int:
        return len(self.stage_n_latch)

    @property
    def dims(self) -> tuple[int, int, int]:
        """``(n, m, n_latch)``: states, inputs, latched multipliers (padded width)."""
        return self.K.shape[2], self.K.shape[1], self.L.shape[2]

    def stage_of_tick(self, j: int) -> int:
        return int(np.searchsorted(self.stage_start, j, side="right") - 1)


@dataclass(frozen=True)
class GainTable(TableShape):
    """Quantized, per-tick gains of one design (see the module docstring for the layout).

    ``u_min``/``u_max`` are optional: ``None`` (the default) means unlimited, stored as
    -FLT_MAX/FLT_MAX. ``u_hold`` (default zeros) is the command the firmware writes on every
    refused step; it must satisfy ``u_min <= u_hold <= u_max`` (the firmware refuses other
    tables).
    """
    name: str
    tick_hz: int
    t0: float
    stage_start: np.ndarray   # (n_stages + 1,) first tick of each stage, then n_ticks
    stage_n_latch: np.ndarray      # (n_stages,) multipliers latched on each stage
    K: np.ndarray
    k0: np.ndarray
    L: np.ndarray
    Lambda: np.ndarray
    lambda0: np.ndarray
    problem_sha256: str
    u_min: np.ndarray | None = None
    u_max: np.ndarray | None = None
    band_qp: BandQP | None = None
    u_hold: np.ndarray | None = None
    # 1: a law designed for a one-tick computation delay (`design.zoh`, ``[design]
    # delay_ticks``): its state is [x; a] (n = plant states + m), a the command being applied
    # now (the previous tick's output; u_hold at the first tick), and its output is applied at
    # the next tick. Not stored in the firmware's table: the caller's contract.
    delay_ticks: int = 0
    # A spline table (`stospline.table.spline.fit.SplineGains`): the firmware evaluates K, k0 and L
    # from it at every tick; the arrays K, k0, L above are that evaluation (bit for bit), so
    # the oracle, the fault oracle and the summaries read them as for a per-tick table.
    spline: object | None = None
    # A spline table of a design that latches the state: how its constraints were restored
    # for the design's x0 (`stospline.table.spline.restore.restore`: rows, active, rounds).
    restored: dict | None = field(default=None, compare=False)
    # A spline table: the relative tolerance its gains were fitted to (``design.spline_tolerance``),
    # to which the design fits a [measurement] sensor's filter gains as well (what it flashes:
    # `harness.estimator_run.flashed_filter`).
    spline_tolerance: float | None = field(default=None, compare=False)

    def __post_init__(self):
        for name in ("K", "k0", "L", "Lambda", "lambda0"):
            object.__setattr__(self, name, positive_zeros(getattr(self, name)))
        m = self.K.shape[1]
        for name, default in (("u_min", -F32_MAX), ("u_max", F32_MAX), ("u_hold", 0.0)):
            val = getattr(self, name)
            arr = (np.full(m, default, dtype=np.float32) if val is None
                   else positive_zeros(np.asarray(val, dtype=np.float32).reshape(-1)))
            if arr.shape != (m,):
                raise ValueError(f"{name} must have one entry per input ({m}), not {arr.shape}")
            if not np.all(np.isfinite(arr)):
                raise ValueError(f"{name} must be finite (use +-FLT_MAX for unlimited)")
            object.__setattr__(self, name, arr)
        if np.any(self.u_min > self.u_hold) or np.any(self.u_max < self.u_hold):
            raise ValueError("the safe command and the limits must satisfy "
                             "u_min <= u_hold <= u_max")

    def with_arrays(self, **arrays) -> "GainTable":
        """A copy with some arrays replaced (re-quantized to float32); for fault planting."""
        return replace(self, **{k: np.asarray(v, dtype=np.float32) for k, v in arrays.items()})

    def quantized(self) -> "GainTable":
        """The table as the firmware stores it: every gain rounded to float32."""
        return self.with_arrays(K=self.K, k0=self.k0, L=self.L, Lambda=self.Lambda,
                                lambda0=self.lambda0, u_min=self.u_min, u_max=self.u_max,
                                u_hold=self.u_hold)

    @property
    def limited(self) -> bool:
        """True when some input has a finite limit (not +-FLT_MAX)."""
        return bool(np.any(self.u_min > -F32_MAX) or np.any(self.u_max < F32_MAX))


def _to_float32(a: np.ndarray) -> np.ndarray:
    """Round to float32 (nearest, as a C compiler converts the literals), after flushing to
    zero the entries below 1e-12 of the array's largest: those are round-off of exact zeros
    (2e-18, say), which would otherwise make regenerated tables differ between machines."""
    a = np.asarray(a, dtype=float)
    scale = float(np.abs(a).max()) if a.size else 0.0
    return np.where(np.abs(a) < 1e-12 * scale, 0.0, a).astype(np.float32)


def build_table(problem, tick_hz: int, stages: list[tuple], *, quantize: bool = True,
                u_min=None, u_max=None, band_qp: BandQP | None = None,
                delay_ticks: int = 0) -> GainTable:
    """Assemble a table from per-stage gains ``(K, k0, L, Lambda, lambda0)`` with shapes
    (T_k, m, n), (T_k, m), (T_k, m, p_k), (p_k, n), (p_k,).

    ``quantize=False`` keeps float64 values (for checking a design before quantization).
    ``u_min``/``u_max`` (m,) are the actuator limits; ``None`` takes the problem's (its
    ``u_min``/``u_max`` keys), unlimited when the problem has none. The safe command is the
    problem's ``u_hold`` (zeros when it has none).

    When more multipliers are latched than there are states (joint or band designs with many
    knots), the table latches the state instead: ``L v = (L Lambda) x_latch + L lambda0``, so
    ``L <- L Lambda``, ``k0 <- k0 + L lambda0``, ``Lambda <- I``, ``lambda0 <- 0``. The same
    law, with n latched values and n multiply-accumulates per input instead of p.
    Not with ``band_qp``: the firmware then latches the multipliers themselves (the band
    dual's solution is not affine in the state), so the table keeps all p columns.

    ``delay_ticks = 1``: the gains act on ``[x; a]`` (``n + m`` columns; `GainTable`).
    """
    m = problem.m
    n = problem.n + m * int(delay_ticks)
    n_latch = max([g[2].shape[2] for g in stages] + [g[3].shape[0] for g in stages])
    if n_latch > n and band_qp is None:
        stages, n_latch = _latch_state(stages, n), n
    counts = [g[0].shape[0] for g in stages]
    start = np.concatenate([[0], np.cumsum(counts)]).astype(np.uint32)
    T = int(start[-1])
    K = np.zeros((T, m, n)); k0 = np.zeros((T, m)); L = np.zeros((T, m, n_latch))
    Lam = np.zeros((len(counts), n_latch, n)); lam0 = np.zeros((len(counts), n_latch))
    for k, (Kk, k0k, Lk, Lamk, lam0k) in enumerate(stages):
        sl = slice(int(start[k]), int(start[k + 1]))
        p = Lamk.shape[0]
        K[sl], k0[sl], L[sl, :, :Lk.shape[2]] = Kk, k0k, Lk
        Lam[k, :p], lam0[k, :p] = Lamk, lam0k
    cast = _to_float32 if quantize else np.asarray
    u_min = getattr(problem, "u_min", None) if u_min is None else u_min
    u_max = getattr(problem, "u_max", None) if u_max is None else u_max
    return GainTable(problem.name, int(tick_hz), problem.t0, start,
                     np.array([g[3].shape[0] for g in stages], dtype=np.uint16),
                     cast(K), cast(k0), cast(L), cast(Lam), cast(lam0), problem.source_sha256,
                     u_min, u_max, band_qp, getattr(problem, "u_hold", None), int(delay_ticks))


def _latch_state(stages: list[tuple], n: int) -> list[tuple]:
    """Rewrite per-stage gains so that the latched vector is the state at the latch tick."""
    out, cur = [], None
    for Kk, k0k, Lk, Lamk, lam0k in stages:
        if Lamk.shape[0]:
            cur = (Lamk, lam0k)
        latches = Lamk.shape[0] > 0
        if Lk.shape[2] and cur is not None:
            L2 = np.einsum("tip,pj->tij", Lk, cur[0])
            k02 = k0k + np.einsum("tip,p->ti", Lk, cur[1])
        else:
            L2, k02 = np.zeros(Kk.shape[:2] + (n,)), k0k
        out.append((Kk, k02, L2, np.eye(n) if latches else np.zeros((0, n)),
                    np.zeros(n if latches else 0)))
    return out


class TickGains(Protocol):
    """What `table_of` needs of a design: the problem, per-stage gains at the ticks, and the
    band dual the firmware re-solves (None without bands). Every designer provides it."""
    problem: object

    def tick_gains(self, tick_hz: int | None = None) -> tuple[int, list[tuple]]:
        """``(tick_hz, stages)``: the rate (None: the design's own) and per stage
        ``(K, k0, L, Lambda, lambda0)``, shapes (T_k, m, n), (T_k, m), (T_k, m, p_k),
        (p_k, n), (p_k,)."""

    def band_dual(self, *, exact: bool) -> tuple | None:
        """``(Nt, mt, W, lower, upper)`` of the band dual, or None."""


def table_of(design: TickGains, tick_hz: int | None = None, *, quantize: bool = True,
             on_target_qp: bool = True) -> GainTable:
    """The per-tick table of any design (continuous designs are sampled at the tick starts
    and held; zero-order-hold designs give their own tick gains), quantized to float32 (round
    to nearest, as a C compiler converts the literals) unless ``quantize=False``.

    With band constraints the table carries the band dual for the firmware's re-solve at the
    t0 latch when it fits (``on_target_qp=False``: the affine latch of the design's active set
    instead). ``quantize=False`` is the design's own law, in double precision, exact dual.

    Parameters
    ----------
    design : TickGains
        Any design (``Designed.design``, or `stospline.design` functions' results).
    tick_hz : int, optional
        The tick rate (default: the design's own; a zero-order-hold design has only that one).
    quantize : bool
        Round to float32 as the firmware stores the gains.
    on_target_qp : bool
        With bands: carry the band dual for the firmware's re-solve when it fits.

    Returns
    -------
    GainTable

    Examples
    --------
    >>> import stospline
    >>> d = stospline.design_problem(stospline.load_problem("examples/robot_corridor.toml"))
    >>> exact = stospline.table_of(d.design, quantize=False)    # the design's own law
    >>> exact.K.dtype, exact.n_ticks, d.table.K.dtype
    (dtype('float64'), 6000, dtype('float32'))
    """
    tick_hz, stages = design.tick_gains(tick_hz)
    dual = design.band_dual(exact=not quantize) if on_target_qp else None
    return build_table(design.problem, tick_hz, stages, quantize=quantize,
                       band_qp=None if dual is None else BandQP(*dual),
                       delay_ticks=getattr(design, "delay_ticks", 0))


def table_crc32(table: GainTable) -> int:
    """CRC-32 (IEEE 802.3, as zlib) over the table's canonical little-endian serialization.

    The firmware computes the same value in ``stsp_table_crc32``: the dimensions and tick rate
    as u32, ``stage_start`` as u32, ``stage_n_latch`` as u32, then K, k0, L, Lambda, lambda0 (these
    three only when n_latch > 0), u_min, u_max, u_hold as IEEE-754 binary32 bit patterns, each
    little-endian.
    A fixed-point table (`stospline.table.qformat.FixedPointTable`) adds its scalar kind as u32 after the
    tick rate, stores the arrays as little-endian int16 (Q15) or int32 (Q31), and ends with
    x_exp, u_exp and v_exp (when n_latch > 0) as one signed byte each. A spline table leaves
    out K, k0 and L and adds, after u_hold, its n_knots, n_entries and n_coef as u32, then
    knot_start (u32 each), knot (binary32), row_start (u32 each), col (u32 each), coef_start
    (u32 each) and coef (binary32). Then, with a band QP (float32
    tables only), its q and n as u32 and Nt, mt, W, lo, hi as binary64 bit patterns. Last, the
    32 bytes of the problem file's SHA-256 (zeros when unknown).
    """
    n, m, n_latch = table.dims
    arith = getattr(table, "arith", "float32")
    head = struct.pack("<6I", n, m, n_latch, table.n_stages, table.n_ticks, table.tick_hz)
    if arith != "float32":
        head += struct.pack("<I", table.scalar_kind)
    parts = [head, np.asarray(table.stage_start, "<u4").tobytes(),
             np.asarray(table.stage_n_latch, "<u4").tobytes()]
    arrays = [table.K, table.k0, table.L, table.Lambda, table.lambda0, table.u_min, table.u_max,
              table.u_hold]
    if arith == "float32":
        parts += [positive_zeros(np.asarray(a, "<f4")).tobytes() for a in arrays]
    else:
        dtype = f"<i{ELEMENT_BYTES[arith]}"
        parts += [np.asarray(a).astype(dtype).tobytes() for a in arrays]
        parts += [np.asarray(e).astype("i1").tobytes()
                  for e in (table.x_exp, table.u_exp, table.v_exp)]
    b = getattr(table, "band_qp", None)
    if getattr(table, "spline", None) is not None:
        parts[3:6] = []                # K, k0, L: the firmware evaluates them from the spline
        parts += _spline_crc_parts(table.spline)
    if b is not None:
        parts.append(struct.pack("<2I", b.q, b.Nt.shape[1]))
        parts += [positive_zeros(np.asarray(a, "<f8")).tobytes()
                  for a in (b.Nt, b.mt, b.W, b.lo, b.hi)]
    parts.append(bytes.fromhex(table.problem_sha256 or "0" * 64))
    crc = 0
    for part in parts:
        crc = zlib.crc32(part, crc)
    return crc & 0xFFFFFFFF


def _spline_crc_parts(sp) -> list[bytes]:
    """A spline's part of the CRC serialization (`table_crc32`): float32
    (`stospline.table.spline.fit`) or fixed point (`stospline.table.spline.fixed_point`: n_entries, n_coef as
    u32, span_log2, row_start, col, shift, coef_start as u32 each, coef as little-endian int16
    or int32, after the scale exponents)."""
    u32 = lambda a: np.asarray(a).astype("<u4").tobytes()  # noqa: E731
    f32 = lambda a: positive_zeros(np.asarray(a, "<f4")).tobytes()  # noqa: E731
    if hasattr(sp, "span_log2"):
        coef = np.asarray(sp.coef)
        return [struct.pack("<2I", sp.col.size, coef.size), u32(sp.span_log2),
                u32(sp.row_start), u32(sp.col), u32(sp.shift), u32(sp.coef_start),
                coef.astype(f"<i{coef.dtype.itemsize}").tobytes()]
    return [struct.pack("<3I", sp.knot.size, sp.col.size, sp.coef.size),
            u32(sp.knot_start), f32(sp.knot), u32(sp.row_start), u32(sp.col),
            u32(sp.coef_start), f32(sp.coef)]
