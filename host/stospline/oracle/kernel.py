"""The oracle's compiled tick loops (double precision C, loaded through cffi).

`build_kernel` compiles ``tick_kernel.c`` and ``tails_kernel.c`` (beside this module; the
latter the fourth-moment oracle's, `oracle.tails_kernel`) into a cffi API-mode module cached
as the designer's kernels are (`stospline.cache`: the user cache directory,
``STOSPLINE_CACHE_DIR`` overrides, keyed by a hash of the source, declarations and flags);
`load_kernel` returns the loaded module, building it on first use.
Two run the tick loop of `oracle.evaluate_table` over one time-invariant stage:
`oracle_stage_ticks` on the packed moment map `pack_oracle_maps` makes (any stage,
O(n² d²) per tick), `factored_stage_ticks` on the tick's transition ``Phi`` and the cost row
`pack_cost` makes (a noise-free stage: ``Phi E ww' Phi'``, O(n d²) per tick).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from stospline.cache import LoadOnce, build_kernel_sources
from stospline.errors import KernelBuildError

__all__ = ["build_kernel", "load_kernel", "oracle_stage_ticks", "pack_oracle_maps",
           "factored_stage_ticks", "pack_cost", "KernelBuildError"]

_SOURCES = [Path(__file__).with_name(f) for f in ("tick_kernel.c", "tails_kernel.c")]
_CDEF = """
size_t stsp_oracle_work_size(int n, int m, int n_latch);
int stsp_oracle_stage_ticks(int n, int m, int n_latch, long T, const double *K, const double *L,
                            const double *k0, const double *Phi_x, const double *cost,
                            const double *Fmean, double *M, double *J, double *work,
                            double *xm, double *xv, double *um, double *uv, double *xx);
size_t stsp_oracle_factored_work_size(int n, int m, int P);
int stsp_oracle_factored_ticks(int n, int m, int P, long T, const double *K, const double *L,
                               const double *k0, const double *Phi, const double *cost,
                               const double *Fmean, double *M, double *J, double *work,
                               double *xm, double *xv, double *um, double *uv, double *xx);
int stsp_tails_operator(int d, int o, long size, long row0, long rows, const int64_t *idx,
                        long nodes, const double *M, const double *w, const int64_t *of_full,
                        double *out, double *work, int64_t *iwork);
size_t stsp_tails_ticks_work(int m, int dy, long D4, long D2);
int stsp_tails_ticks(int n, int m, int P, long T, const double *K, const double *L,
                     const double *k0, long D4, long D2, const int64_t *rowptr,
                     const int64_t *colidx, const double *val, int substeps,
                     const int64_t *ins, const int64_t *src4, const int64_t *src2,
                     const int64_t *back4, const int64_t *back2, double *Y4, double *Y2,
                     double *J2, double *work);
"""


def build_kernel(build_dir: str | Path | None = None, *, quiet: bool = True) -> Path:
    """Compile the kernel (if not cached) and return the path of the extension module."""
    return build_kernel_sources("_stsp_oracle_kernel", _SOURCES, _CDEF, root=build_dir,
                                quiet=quiet)


def load_kernel():
    """The loaded cffi module (``.ffi``, ``.lib``), built on first use (once, whichever
    thread asks first)."""
    return _load()


_load = LoadOnce(lambda: build_kernel())


def pack_oracle_maps(Phi: np.ndarray, cost_row: np.ndarray, n: int):
    """The tick's moment map and cost row on the upper triangle of the symmetric ``E w w'``
    (``w = [x; u; 1]``), keeping only the rows the oracle's update reads: ``(Phi_x, cost)``
    for `oracle_stage_ticks` (layout in ``tick_kernel.c``)."""
    dw = int(round(np.sqrt(cost_row.shape[0])))
    p, q = np.triu_indices(dw)
    upper, lower = p * dw + q, q * dw + p
    off = (p != q).astype(float)
    rows = [a * dw + b for a in range(n) for b in [*range(n), dw - 1]]
    Phi_x = Phi[rows][:, upper] + Phi[rows][:, lower] * off
    cost = cost_row[upper] + cost_row[lower] * off
    return np.ascontiguousarray(Phi_x), np.ascontiguousarray(cost)


def pack_cost(cost_row: np.ndarray) -> np.ndarray:
    """The tick's cost row (d² entries, acting on ``vec E ww'``) on the upper triangle of the
    symmetric ``E ww'``, row by row, off-diagonal entries counted twice."""
    dw = int(round(np.sqrt(cost_row.shape[0])))
    p, q = np.triu_indices(dw)
    return np.ascontiguousarray(cost_row[p * dw + q] + cost_row[q * dw + p] * (p != q))


def oracle_stage_ticks(K: np.ndarray, L: np.ndarray, k0: np.ndarray, Phi_x: np.ndarray,
                       cost: np.ndarray, Fmean: np.ndarray, M: np.ndarray, J: float, *,
                       path: bool = False, moments: bool = False):
    """The tick loop of `oracle.evaluate_table` over one time-invariant stage, in C
    (``tick_kernel.c``): gains ``K`` (T, m, n), ``L`` (T, m, n_latch), ``k0`` (T, m), the tick's
    moment map and cost row packed by `pack_oracle_maps`, the mean map ``Fmean`` (n, n + m),
    the second moment ``M`` of ``[x; v; 1]`` before the stage; returns ``(M, J)`` after it
    (a new array), and with `path` also the state's mean and variance after each tick (T, n)
    and the command's over it (T, m): ``(M, J, xm, xv, um, uv)``; with `moments` last the
    state's second moments and mean after each tick, ``xx`` (T, n, n + 1): ``xx[j, a] = [E x_a
    x_b for b < n, E x_a]``."""
    n, m = K.shape[2], K.shape[1]
    dw = n + m + 1
    return _stage_ticks("stsp_oracle", (n * (n + 1), dw * (dw + 1) // 2), K, L, k0, Phi_x,
                        cost, Fmean, M, J, path, moments)


def factored_stage_ticks(K: np.ndarray, L: np.ndarray, k0: np.ndarray, Phi: np.ndarray,
                         cost: np.ndarray, Fmean: np.ndarray, M: np.ndarray, J: float, *,
                         path: bool = False, moments: bool = False):
    """`oracle_stage_ticks` for a noise-free stage (``tick_kernel.c``'s factored loop): the tick's state
    transition ``Phi = exp(Ahat h)`` of ``w = [x; u; 1]`` and its cost row packed by
    `pack_cost` instead of the packed moment map; the same results to rounding."""
    dw = K.shape[2] + K.shape[1] + 1
    return _stage_ticks("stsp_oracle_factored", (dw, dw), K, L, k0, Phi, cost, Fmean, M, J,
                        path, moments)


def _stage_ticks(prefix: str, map_shape: tuple, K, L, k0, tick_map, cost, Fmean, M, J, path,
                 moments):
    """Run ``<prefix>_ticks`` (``<prefix>_stage_ticks`` for the general loop) of the loaded
    module after checking every shape."""
    mod = load_kernel()
    ffi, lib = mod.ffi, mod.lib
    T, m, n = K.shape
    n_latch = L.shape[2]
    K, L, k0, tick_map, cost, Fmean = (np.ascontiguousarray(a, dtype=np.float64)
                                       for a in (K, L, k0, tick_map, cost, Fmean))
    M = np.array(M, dtype=np.float64, order="C")
    dw, dy = n + m + 1, n + n_latch + 1
    want = {"L": (L, (T, m, n_latch)), "k0": (k0, (T, m)), "tick map": (tick_map, map_shape),
            "cost": (cost, (dw * (dw + 1) // 2,)), "Fmean": (Fmean, (n, n + m)),
            "M": (M, (dy, dy))}
    for name, (a, shape) in want.items():
        if a.shape != shape:
            raise ValueError(f"{name} has shape {a.shape}, expected {shape}")
    loop = getattr(lib, prefix + ("_stage_ticks" if prefix == "stsp_oracle" else "_ticks"))
    work = np.empty(int(getattr(lib, prefix + "_work_size")(n, m, n_latch)))
    Jp = ffi.new("double *", float(J))
    p = [ffi.from_buffer("double[]", a) for a in (K, L, k0, tick_map, cost, Fmean, M)]
    rec = [np.empty((T, n)), np.empty((T, n)), np.empty((T, m)), np.empty((T, m))] if path else []
    out = [ffi.from_buffer("double[]", a) for a in rec] if path else [ffi.NULL] * 4
    xx = np.empty((T, n, n + 1)) if moments else None
    status = loop(n, m, n_latch, T, *p, Jp, ffi.from_buffer("double[]", work), *out,
                  ffi.from_buffer("double[]", xx) if moments else ffi.NULL)
    if status != 0:
        raise ValueError(f"{prefix} tick loop: bad dimensions (status {status})")
    return (M, float(Jp[0]), *rec, *([xx] if moments else []))
