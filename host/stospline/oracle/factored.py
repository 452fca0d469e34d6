"""The oracle's tick loop for a noise-free, time-invariant stage in C (``factored_kernel.c``):
the tick's moment map applied as ``Phi E ww' Phi'`` (O(n d²) per tick) instead of the
packed d²-square product of the general kernel (O(n² d²)). Built and cached with cffi as the
designer's kernels are (`stospline.cache`)."""
from __future__ import annotations

import threading
from pathlib import Path

import numpy as np

from stospline.cache import build_source_module, load_module
from stospline.errors import KernelBuildError

__all__ = ["factored_stage_ticks", "load_factored", "pack_cost"]

_SOURCE = Path(__file__).with_name("factored_kernel.c")
_CDEF = """
size_t stsp_oracle_factored_work_size(int n, int m, int P);
int stsp_oracle_factored_ticks(int n, int m, int P, long T, const double *K, const double *L,
                               const double *k0, const double *Phi, const double *cost,
                               const double *Fmean, double *M, double *J, double *work,
                               double *xm, double *xv, double *um, double *uv);
"""
_CFLAGS = ["-std=c99", "-O3", "-Wall", "-Wextra"]
_loaded = None
_load_lock = threading.Lock()


def load_factored():
    """The loaded cffi module, built on first use; KernelBuildError when it cannot be."""
    global _loaded
    with _load_lock:
        if _loaded is None:
            try:
                path = build_source_module("_stsp_oracle_factored", _SOURCE.read_bytes(),
                                           _CDEF, _CFLAGS)
            except Exception as exc:  # noqa: BLE001 - any failure means "no compiled kernel"
                raise KernelBuildError(f"cannot build {_SOURCE.name}: {exc}") from exc
            _loaded = load_module(path)
    return _loaded


def pack_cost(cost_row: np.ndarray) -> np.ndarray:
    """The tick's cost row (d² entries, acting on ``vec E ww'``) on the upper triangle of the
    symmetric ``E ww'``, row by row, off-diagonal entries counted twice."""
    dw = int(round(np.sqrt(cost_row.shape[0])))
    p, q = np.triu_indices(dw)
    return np.ascontiguousarray(cost_row[p * dw + q] + cost_row[q * dw + p] * (p != q))


def factored_stage_ticks(K: np.ndarray, L: np.ndarray, k0: np.ndarray, Phi: np.ndarray,
                         cost: np.ndarray, Fmean: np.ndarray, M: np.ndarray, J: float, *,
                         path: bool = False):
    """The tick loop of `oracle.evaluate_table` over one noise-free time-invariant stage:
    gains ``K`` (T, m, n), ``L`` (T, m, n_latch), ``k0`` (T, m), the tick's state transition
    ``Phi = exp(Ahat h)`` of ``w = [x; u; 1]``, the cost row packed by `pack_cost`, the mean
    map ``Fmean`` (n, n + m), the second moment ``M`` of ``[x; v; 1]`` before the stage.
    Returns ``(M, J)`` after it (a new array), with `path` also the state's mean and variance
    after each tick (T, n) and the command's over it (T, m), as
    `design.kernels.oracle_stage_ticks`."""
    mod = load_factored()
    ffi, lib = mod.ffi, mod.lib
    T, m, n = K.shape
    n_latch = L.shape[2]
    K, L, k0, Phi, cost, Fmean = (np.ascontiguousarray(a, dtype=np.float64)
                                  for a in (K, L, k0, Phi, cost, Fmean))
    M = np.array(M, dtype=np.float64, order="C")
    dw, dy = n + m + 1, n + n_latch + 1
    want = {"L": (L, (T, m, n_latch)), "k0": (k0, (T, m)), "Phi": (Phi, (dw, dw)),
            "cost": (cost, (dw * (dw + 1) // 2,)), "Fmean": (Fmean, (n, n + m)),
            "M": (M, (dy, dy))}
    for name, (a, shape) in want.items():
        if a.shape != shape:
            raise ValueError(f"{name} has shape {a.shape}, expected {shape}")
    work = np.empty(int(lib.stsp_oracle_factored_work_size(n, m, n_latch)))
    Jp = ffi.new("double *", float(J))
    p = [ffi.from_buffer("double[]", a) for a in (K, L, k0, Phi, cost, Fmean, M)]
    rec = [np.empty((T, n)), np.empty((T, n)), np.empty((T, m)), np.empty((T, m))] if path else []
    out = [ffi.from_buffer("double[]", a) for a in rec] if path else [ffi.NULL] * 4
    status = lib.stsp_oracle_factored_ticks(n, m, n_latch, T, *p, Jp,
                                            ffi.from_buffer("double[]", work), *out)
    if status != 0:
        raise ValueError(f"stsp_oracle_factored_ticks: bad dimensions (status {status})")
    return (M, float(Jp[0]), *rec) if path else (M, float(Jp[0]))
