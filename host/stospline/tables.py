"""Gain tables: a design as the C controller evaluates it, one row per tick, quantized.

Layout (all row-major, float32, padded to ``n_latch`` multipliers with zeros)::

    K[tick][i][j]        (n_ticks, m, n)    feedback
    k0[tick][i]          (n_ticks, m)       feed-forward
    L[tick][i][c]        (n_ticks, m, P)    gain of the latched multiplier v
    Lambda[stage][c][j]  (n_stages, P, n)   latch map  v = Lambda x + lambda0
    lambda0[stage][c]    (n_stages, P)

At tick ``j`` (time ``t0 + j / tick_hz``) the controller applies ``u = -K x - k0 - L v``
and holds it for one tick; at a stage's first tick it first latches ``v`` from the state.
"""
from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, replace

import numpy as np

from .design import ContinuousDesign

__all__ = ["GainTable", "sample_design", "table_crc32", "FORMAT_VERSION", "SCALAR_FLOAT32"]

FORMAT_VERSION = 1
SCALAR_FLOAT32 = 1
MAGIC = 0x53545350  # "STSP"


@dataclass(frozen=True)
class GainTable:
    """Quantized, per-tick gains of one design (see the module docstring for the layout)."""
    name: str
    tick_hz: int
    t0: float
    stage_start: np.ndarray   # (n_stages + 1,) first tick of each stage, then n_ticks
    stage_np: np.ndarray      # (n_stages,) multipliers latched on each stage
    K: np.ndarray
    k0: np.ndarray
    L: np.ndarray
    Lambda: np.ndarray
    lambda0: np.ndarray
    problem_sha256: str

    @property
    def n_ticks(self) -> int:
        return int(self.stage_start[-1])

    @property
    def n_stages(self) -> int:
        return len(self.stage_np)

    @property
    def dims(self) -> tuple[int, int, int]:
        """``(n, m, P)``: states, inputs, latched multipliers (padded width)."""
        return self.K.shape[2], self.K.shape[1], self.L.shape[2]

    def stage_of_tick(self, j: int) -> int:
        return int(np.searchsorted(self.stage_start, j, side="right") - 1)

    def with_arrays(self, **arrays) -> "GainTable":
        """A copy with some arrays replaced (re-quantized to float32); for fault planting."""
        return replace(self, **{k: np.asarray(v, dtype=np.float32) for k, v in arrays.items()})


def sample_design(design: ContinuousDesign, tick_hz: int | None = None) -> GainTable:
    """Sample a continuous design at the tick starts (zero-order hold) and quantize to float32."""
    prob = design.problem
    tick_hz = prob.tick_hz if tick_hz is None else int(tick_hz)
    n, m = prob.n, prob.m
    P = prob.max_constraints
    times = prob.times
    counts = np.rint(np.diff(times) * tick_hz).astype(int)
    if np.any(np.abs(np.diff(times) * tick_hz - counts) > 1e-9 * np.maximum(counts, 1)):
        raise ValueError(f"tick rate {tick_hz} Hz does not divide every stage length")
    start = np.concatenate([[0], np.cumsum(counts)])
    T = int(start[-1])
    K = np.zeros((T, m, n)); k0 = np.zeros((T, m)); L = np.zeros((T, m, P))
    Lam = np.zeros((len(counts), P, n)); lam0 = np.zeros((len(counts), P))
    for k, st in enumerate(design.stages):
        t = times[k] + np.arange(counts[k]) / tick_hz
        Kk, k0k, Lk = st.gains(t)
        sl = slice(start[k], start[k + 1])
        K[sl], k0[sl] = Kk, k0k
        L[sl, :, :st.n_constraints] = Lk
        Lam[k, :st.n_constraints] = st.Lambda
        lam0[k, :st.n_constraints] = st.lambda0
    f32 = lambda a: np.asarray(a, dtype=np.float32)  # noqa: E731 (round to nearest, as C does)
    return GainTable(prob.name, tick_hz, prob.t0, start.astype(np.uint32),
                     np.array([s.n_constraints for s in design.stages], dtype=np.uint16),
                     f32(K), f32(k0), f32(L), f32(Lam), f32(lam0), prob.source_sha256)


def table_crc32(table: GainTable) -> int:
    """CRC-32 (IEEE 802.3, as zlib) over the table's canonical little-endian serialization.

    The firmware computes the same value in ``stsp_table_crc32``: the dimensions and tick rate
    as u32, ``stage_start`` as u32, ``stage_np`` as u32, then K, k0, L, Lambda, lambda0 as
    IEEE-754 binary32 bit patterns, each little-endian.
    """
    n, m, P = table.dims
    head = struct.pack("<6I", n, m, P, table.n_stages, table.n_ticks, table.tick_hz)
    parts = [head, np.asarray(table.stage_start, "<u4").tobytes(),
             np.asarray(table.stage_np, "<u4").tobytes()]
    parts += [np.asarray(a, "<f4").tobytes()
              for a in (table.K, table.k0, table.L, table.Lambda, table.lambda0)]
    crc = 0
    for part in parts:
        crc = zlib.crc32(part, crc)
    return crc & 0xFFFFFFFF
