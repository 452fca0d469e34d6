"""Compiled host kernels of the designers (double precision C, loaded through cffi).

Build and load are separate steps, as for the firmware (`stospline.harness.controller`): `build_kernels` compiles ``tick_kernel.c``
into a cffi API-mode module cached (`stospline.cache`: the user cache directory,
``STOSPLINE_CACHE_DIR`` overrides) by a hash of the source, the declarations and the flags,
and `load_kernels` returns the loaded module, building it on first use. `zoh_stage_ticks` runs the per-tick loop of one stage
of the exact zero-order-hold design (`design_zoh`) in C.
"""
from __future__ import annotations

import threading
from pathlib import Path

import numpy as np

from stospline.cache import build_source_module, load_module
from stospline.errors import KernelBuildError

__all__ = ["build_kernels", "load_kernels", "zoh_stage_ticks", "oracle_stage_ticks",
           "pack_oracle_maps", "KernelBuildError"]

_SOURCE = Path(__file__).with_name("tick_kernel.c")
_ORACLE_SOURCE = Path(__file__).with_name("oracle_kernel.c")
_VARYING_SOURCE = Path(__file__).with_name("varying_kernel.c")
_CDEF = """
size_t stsp_zoh_work_size(int n, int m, int q);
int stsp_zoh_stage_ticks(int n, int m, int q, long T,
                         const double *A2sT, const double *Hcs, const double *F,
                         double *V, double *N, double *W, double *mv,
                         double *K, double *k0, double *L, double *work, long *bad_tick);
size_t stsp_oracle_work_size(int n, int m, int n_latch);
int stsp_oracle_stage_ticks(int n, int m, int n_latch, long T, const double *K, const double *L,
                            const double *k0, const double *Phi_x, const double *cost,
                            const double *Fmean, double *M, double *J, double *work,
                            double *xm, double *xv, double *um, double *uv);
size_t stsp_tv_zoh_work_size(int n, int m, int q, int na, int mz);
size_t stsp_tv_iwork_size(int n, int m, int na, int mz);
int stsp_tv_zoh_ticks(int n, int m, int q, long T, int P, int na, int mz, const double *coef,
                      double h, const int *act, const double *Ar, const double *G,
                      const double *Lb, const int *same, const int *ar_nz, int ar_cnt,
                      double *V, double *N, double *W,
                      double *mv, double *K, double *k0, double *L, double *work,
                      int *iwork, int noise_path, long *bad_tick);
size_t stsp_tv_oracle_work_size(int n, int m, int n_latch, int na, int mz);
int stsp_tv_oracle_ticks(int n, int m, int n_latch, long T, const double *K, const double *L,
                         const double *k0, int P, int na, int mz, const double *coef,
                         double h, const int *act, const double *Ar, const double *G,
                         const double *Lb, const int *same, const int *ar_nz, int ar_cnt,
                         double *M, double *J, double *xm,
                         double *xv, double *um, double *uv, double *work, int *iwork,
                         int noise_path);
size_t stsp_tv_euler_work_size(int n, int m, int n_latch, int na, int mz);
int stsp_tv_euler_oracle_ticks(int n, int m, int n_latch, long T, const double *K,
                               const double *L, const double *k0, int sub, int na, int mz,
                               double dt, const int *act, const double *Ad, const double *G,
                               const double *Lb, const int *same, double *M, double *J,
                               double *xm, double *xv, double *um, double *uv, double *work,
                               int *iwork);
"""
_CFLAGS = ["-std=c99", "-O3", "-Wall", "-Wextra"]
_ERR_NOT_PD, _ERR_DIMS = -1, -2
_loaded = None
_load_lock = threading.Lock()


def build_kernels(build_dir: str | Path | None = None, *, quiet: bool = True) -> Path:
    """Compile the kernels (if not cached) and return the path of the extension module."""
    source = b"\n".join(p.read_bytes() for p in (_SOURCE, _ORACLE_SOURCE, _VARYING_SOURCE))
    try:
        return build_source_module("_stsp_kernels", source, _CDEF, _CFLAGS, root=build_dir,
                                   quiet=quiet)
    except Exception as exc:  # noqa: BLE001 - any failure here means "no compiled kernel"
        names = ", ".join(p.name for p in (_SOURCE, _ORACLE_SOURCE, _VARYING_SOURCE))
        raise KernelBuildError(f"cannot build {names}: {exc}") from exc


def load_kernels():
    """The loaded cffi module (``.ffi``, ``.lib``), built on first use (once, whichever
    thread asks first)."""
    global _loaded
    with _load_lock:
        if _loaded is None:
            _loaded = load_module(build_kernels())
    return _loaded


def _c(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64)


def zoh_stage_ticks(A2sT: np.ndarray, Hcs: np.ndarray, F: np.ndarray, V: np.ndarray,
                    N: np.ndarray, W: np.ndarray, mv: np.ndarray, T: int, m: int):
    """Run the `T` ticks of one stage of the exact ZOH Riccati recursion in C.

    Parameters
    ----------
    A2sT : ndarray, shape (vs, ds)
        Transposed packed tick map (``vs = (n+1)(n+2)/2``, ``ds = d(d+1)/2``, ``d = n+m+1``;
        packed = upper triangle row by row).
    Hcs : ndarray, shape (ds,)
        Packed expected running cost over one tick.
    F : ndarray, shape (n, d)
    V, N, W, mv : ndarray
        Value after the stage's last tick: ``(n+1, n+1)``, ``(n, q)``, ``(q, q)``, ``(q,)``.
    T, m : int
        Number of ticks and inputs.

    Returns
    -------
    K, k0, L, V, N, W, mv
        Gains per tick ``(T, m, n)``, ``(T, m)``, ``(T, m, q)`` and the value before the
        stage's first tick (new arrays; the inputs are not modified).

    Raises
    ------
    numpy.linalg.LinAlgError
        ``Huu`` is not positive definite at some tick (a finite Cholesky pivot <= 0), as the
        numpy reference raises for a singular one.
    """
    mod = load_kernels()
    ffi, lib = mod.ffi, mod.lib
    n = F.shape[0]
    q = N.shape[1]
    T = int(T)
    A2sT, Hcs, F = _c(A2sT), _c(Hcs), _c(F)
    V, N, W, mv = (np.array(a, dtype=np.float64, order="C") for a in (V, N, W, mv))
    d = n + m + 1
    ds, vs = d * (d + 1) // 2, (n + 1) * (n + 2) // 2
    want = {"A2sT": (A2sT, (vs, ds)), "Hcs": (Hcs, (ds,)), "F": (F, (n, d)),
            "V": (V, (n + 1, n + 1)), "N": (N, (n, q)), "W": (W, (q, q)), "mv": (mv, (q,))}
    for name, (a, shape) in want.items():
        if a.shape != shape:
            raise ValueError(f"{name} has shape {a.shape}, expected {shape}")
    K, k0, L = np.empty((T, m, n)), np.empty((T, m)), np.empty((T, m, q))
    work = np.empty(max(int(lib.stsp_zoh_work_size(n, m, q)), 1))
    bad = ffi.new("long *", -1)
    # from_buffer keeps each array alive for the call; every array is C-contiguous float64.
    p = [ffi.from_buffer("double[]", a) for a in (A2sT, Hcs, F, V, N, W, mv, K, k0, L, work)]
    status = lib.stsp_zoh_stage_ticks(n, m, q, T, *p, bad)
    if status == _ERR_NOT_PD:
        raise np.linalg.LinAlgError(f"Huu is not positive definite at tick {bad[0]}")
    if status != 0:
        raise ValueError(f"stsp_zoh_stage_ticks: bad dimensions (status {status})")
    return K, k0, L, V, N, W, mv


def pack_oracle_maps(Phi: np.ndarray, cost_row: np.ndarray, n: int):
    """The tick's moment map and cost row on the upper triangle of the symmetric ``E w w'``
    (``w = [x; u; 1]``), keeping only the rows the oracle's update reads: ``(Phi_x, cost)``
    for `oracle_stage_ticks` (layout in ``oracle_kernel.c``)."""
    dw = int(round(np.sqrt(cost_row.shape[0])))
    p, q = np.triu_indices(dw)
    upper, lower = p * dw + q, q * dw + p
    off = (p != q).astype(float)
    rows = [a * dw + b for a in range(n) for b in [*range(n), dw - 1]]
    Phi_x = Phi[rows][:, upper] + Phi[rows][:, lower] * off
    cost = cost_row[upper] + cost_row[lower] * off
    return np.ascontiguousarray(Phi_x), np.ascontiguousarray(cost)


def oracle_stage_ticks(K: np.ndarray, L: np.ndarray, k0: np.ndarray, Phi_x: np.ndarray,
                       cost: np.ndarray, Fmean: np.ndarray, M: np.ndarray, J: float, *,
                       path: bool = False):
    """The tick loop of `oracle.evaluate_table` over one time-invariant stage, in C
    (``oracle_kernel.c``): gains ``K`` (T, m, n), ``L`` (T, m, n_latch), ``k0`` (T, m), the tick's
    moment map and cost row packed by `pack_oracle_maps`, the mean map ``Fmean`` (n, n + m),
    the second moment ``M`` of ``[x; v; 1]`` before the stage; returns ``(M, J)`` after it
    (a new array), and with `path` also the state's mean and variance after each tick (T, n)
    and the command's over it (T, m): ``(M, J, xm, xv, um, uv)``."""
    mod = load_kernels()
    ffi, lib = mod.ffi, mod.lib
    T, m, n = K.shape
    n_latch = L.shape[2]
    K, L, k0, Phi_x, cost, Fmean = (_c(a) for a in (K, L, k0, Phi_x, cost, Fmean))
    M = np.array(M, dtype=np.float64, order="C")
    dw, dy = n + m + 1, n + n_latch + 1
    nv = dw * (dw + 1) // 2
    want = {"L": (L, (T, m, n_latch)), "k0": (k0, (T, m)), "Phi_x": (Phi_x, (n * (n + 1), nv)),
            "cost": (cost, (nv,)), "Fmean": (Fmean, (n, n + m)), "M": (M, (dy, dy))}
    for name, (a, shape) in want.items():
        if a.shape != shape:
            raise ValueError(f"{name} has shape {a.shape}, expected {shape}")
    work = np.empty(int(lib.stsp_oracle_work_size(n, m, n_latch)))
    Jp = ffi.new("double *", float(J))
    p = [ffi.from_buffer("double[]", a) for a in (K, L, k0, Phi_x, cost, Fmean, M)]
    rec = [np.empty((T, n)), np.empty((T, n)), np.empty((T, m)), np.empty((T, m))] if path else []
    out = [ffi.from_buffer("double[]", a) for a in rec] if path else [ffi.NULL] * 4
    status = lib.stsp_oracle_stage_ticks(n, m, n_latch, T, *p, Jp,
                                         ffi.from_buffer("double[]", work), *out)
    if status != 0:
        raise ValueError(f"stsp_oracle_stage_ticks: bad dimensions (status {status})")
    return (M, float(Jp[0]), *rec) if path else (M, float(Jp[0]))
