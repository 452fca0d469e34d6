"""Compiled host kernels of the designers (double precision C, loaded through cffi).

Build and load are separate steps, as for the firmware (`stospline.harness.controller`): `build_kernels` compiles ``tick_kernel.c``
and ``varying_kernel.c`` into a cffi API-mode module cached (`stospline.cache`: the user cache
directory, ``STOSPLINE_CACHE_DIR`` overrides) by a hash of the source, the declarations and the
flags, and `load_kernels` returns the loaded module, building it on first use. `zoh_stage_ticks` runs the per-tick loop of one stage
of the exact zero-order-hold design (`design_zoh`) in C. The oracle's tick loop has its own
kernel (`stospline.oracle.kernel`).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from stospline.cache import LoadOnce, build_kernel_sources
from stospline.errors import KernelBuildError

__all__ = ["build_kernels", "load_kernels", "zoh_stage_ticks", "KernelBuildError"]

_SOURCES = [Path(__file__).with_name(f) for f in ("tick_kernel.c", "varying_kernel.c")]
_CDEF = """
size_t stsp_zoh_work_size(int n, int m, int q);
int stsp_zoh_stage_ticks(int n, int m, int q, long T,
                         const double *A2sT, const double *Hcs, const double *F,
                         double *V, double *N, double *W, double *mv,
                         double *K, double *k0, double *L, double *work, long *bad_tick);
size_t stsp_tv_zoh_work_size(int n, int m, int q, int na, int mz);
size_t stsp_tv_iwork_size(int n, int m, int na, int mz);
int stsp_tv_zoh_ticks(int n, int m, int q, long T, int P, int na, int mz, const double *coef,
                      double h, const int *act, const double *Ar, const double *G,
                      const double *Lb, const int *same, const int *ar_nz, int ar_cnt,
                      int nseg, const double *seg_ops, const double *seg_ends,
                      const int *seg_idx, const double *seg_w, double *V, double *N, double *W,
                      double *mv, double *K, double *k0, double *L, double *work,
                      int *iwork, int noise_path, long *bad_tick);
size_t stsp_tv_oracle_work_size(int n, int m, int n_latch, int na, int mz);
int stsp_tv_oracle_ticks(int n, int m, int n_latch, long T, const double *K, const double *L,
                         const double *k0, int P, int na, int mz, const double *coef,
                         double h, const int *act, const double *Ar, const double *G,
                         const double *Lb, const int *same, const int *ar_nz, int ar_cnt,
                         int nseg, const double *seg_ops, const double *seg_ends,
                         const int *seg_idx, const double *seg_w, double *M, double *J,
                         double *xm,
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
_ERR_NOT_PD, _ERR_DIMS = -1, -2


def build_kernels(build_dir: str | Path | None = None, *, quiet: bool = True) -> Path:
    """Compile the kernels (if not cached) and return the path of the extension module."""
    return build_kernel_sources("_stsp_kernels", _SOURCES, _CDEF, root=build_dir, quiet=quiet)


def load_kernels():
    """The loaded cffi module (``.ffi``, ``.lib``), built on first use (once, whichever
    thread asks first)."""
    return _load()


_load = LoadOnce(lambda: build_kernels())


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
