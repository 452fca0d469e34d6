"""The filter's gains and mean maps in compiled C, the same bits on every machine.

`evaluate_estimator` computes the LMMSE gains from the loop's second moments, and the error
covariance ``P = E xx' - E xx̂' - E x̂x' + E x̂x̂'`` is a difference of numbers up to ~1e10 times
larger than it: the last bits in which one BLAS kernel's products differ from another's moved
small gains by up to 6e-9 relative, across float32 and Q31 rounding boundaries
(`tools/check_estimator_blas.py`). ``filter_kernel.c`` (beside this module) runs the same
recursion and the stages' matrix exponentials with every sum in a fixed order, no BLAS or
LAPACK and no fused multiply-adds: the written gains and predictor maps depend on the problem
and the law only. Built and cached as the oracle's kernels are (`stospline.cache`);
``STOSPLINE_FILTER_KERNEL=numpy`` asks for the numpy reference instead, and so does a host
where it cannot be built.

`filter_gains` covers the loop the tables are written from (`evaluate_estimator` without
faults, the exact propagator): stages with constant data and at most `MAX_DW` entries in
``w = [x; u; 1]``; it returns None for the others (time-varying data, whose ticks
`oracle.tick_moments` integrates with an ODE solver), which keep the numpy gains.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from stospline.cache import KERNEL_CFLAGS, LoadOnce, build_kernel_sources
from stospline.design.moments import augmented_drift
from stospline.errors import KernelBuildError

__all__ = ["filter_gains", "with_table_filter", "load_kernel", "MAX_DW"]

# Largest n + m + 1 taken: the stage's moment map is (n + m + 1)^2 square and its exponential
# costs ~12 (n + m + 1)^6 flops in plain C (16: 0.2 s per distinct stage).
MAX_DW = 16

_SOURCES = [Path(__file__).with_name("filter_kernel.c")]
_CDEF = """
size_t stsp_filter_work_size(int n, int m, int P, int p);
size_t stsp_filter_iwork_size(int n, int m);
int stsp_filter_gains(int n, int m, int P, int p, long T, int n_stages, int every, int q,
                      int r, double h, const int64_t *stage_start, const int *latch,
                      const double *Lambda, const double *lambda0, const double *K,
                      const double *L, const double *k0, const double *Ahat, const double *G,
                      const double *C, const double *V, const double *Dm, const double *x0,
                      const double *x0_cov, double *gain, double *Fmean, double *work,
                      int *iwork);
"""
# No contraction to fused multiply-adds (gcc's default outside ISO mode, clang's within
# expressions): an FMA rounds once where the plain product and sum round twice.
_CFLAGS = [*KERNEL_CFLAGS, "-ffp-contract=off"]


def _build():
    return build_kernel_sources("_stsp_filter_kernel", _SOURCES, _CDEF, _CFLAGS)


_load = LoadOnce(_build)


def load_kernel():
    """The loaded cffi module (``.ffi``, ``.lib``), built on first use."""
    return _load()


def _supported(problem, table, meas, propagator: str) -> bool:
    n, m, _ = table.dims
    return (propagator == "exact" and n + m + 1 <= MAX_DW
            and all(st.varying is None for st in problem.stages[:table.n_stages])
            and os.environ.get("STOSPLINE_FILTER_KERNEL", "c") != "numpy")


def filter_gains(problem, table, meas, propagator: str = "exact"
                 ) -> tuple[np.ndarray, np.ndarray] | None:
    """``(gain, predict)`` of the loop `evaluate_estimator` evaluates without faults: the LMMSE
    gain of every tick (T, n, p; zero between samples) and the plant's mean map ``[Ad, Bd,
    fd]`` of every tick (T, n, n + m + 1), from ``filter_kernel.c``; None where it does not
    apply (module docstring) or cannot be built. Raises ValueError for a non-finite
    intermediate."""
    if not _supported(problem, table, meas, propagator):
        return None
    try:
        mod = load_kernel()
    except KernelBuildError:
        return None
    ffi, lib = mod.ffi, mod.lib
    n, m, P = table.dims
    p, T, S = meas.p, table.n_ticks, table.n_stages
    dw = n + m + 1
    h = 1.0 / table.tick_hz
    f64 = lambda a: np.ascontiguousarray(a, dtype=np.float64)  # noqa: E731
    stages = problem.stages[:S]
    q = max(int(st.noise_tensor.shape[2]) for st in stages)
    G = np.zeros((S, n + m, n, max(q, 1)))
    for k, st in enumerate(stages):
        nt = st.noise_tensor
        G[k, :, :, :nt.shape[2]] = nt
    Ahat = f64(np.stack([augmented_drift(st, m + 1) for st in stages]))
    latch = np.array([1 if k == 0 or table.stage_n_latch[k] > 0 else 0 for k in range(S)],
                     dtype=np.intc)
    V = np.zeros((T, p, p))
    for j in range(0, T, meas.every):
        V[j] = meas.V_at(table.t0 + j * h)
    D = np.asarray(meas.D, dtype=float)
    r = int(D.shape[2]) if D.size else 0
    Dm = f64(D) if r else np.zeros(1)
    arrays = [f64(a) for a in (table.Lambda, table.lambda0, table.K, table.L, table.k0)]
    Lam = arrays[0] if P else np.zeros(1)
    lam0 = arrays[1] if P else np.zeros(1)
    gain = np.zeros((T, n, p))
    Fmean = np.zeros((S, n, dw))
    work = np.empty(int(lib.stsp_filter_work_size(n, m, P, p)))
    iwork = np.empty(int(lib.stsp_filter_iwork_size(n, m)), dtype=np.intc)
    starts = np.asarray(table.stage_start, dtype=np.int64)
    dbl = lambda a: ffi.from_buffer("double[]", a)  # noqa: E731
    status = lib.stsp_filter_gains(
        n, m, P, p, T, S, int(meas.every), max(q, 1), r, h,
        ffi.cast("int64_t *", ffi.from_buffer(starts)), ffi.cast("int *", ffi.from_buffer(latch)),
        dbl(Lam), dbl(lam0), dbl(arrays[2]), dbl(arrays[3] if P else np.zeros(1)),
        dbl(arrays[4]), dbl(Ahat), dbl(f64(G)), dbl(f64(meas.C)), dbl(V), dbl(Dm),
        dbl(f64(problem.x0)), dbl(f64(meas.prior_cov(n))), dbl(gain), dbl(Fmean), dbl(work),
        ffi.cast("int *", ffi.from_buffer(iwork)))
    if status == -3:                   # a stage's exponential needs scipy's scaling
        return None
    if status == -2:
        raise ValueError("the filter's moments are not finite")
    if status != 0:
        raise ValueError(f"stsp_filter_gains: bad dimensions (status {status})")
    predict = np.empty((T, n, dw))
    for k in range(S):
        predict[int(starts[k]):int(starts[k + 1])] = Fmean[k]
    return gain, predict


def with_table_filter(loop, problem, table):
    """`loop` (`evaluate_estimator` of the double law) with the filter of the float32 `table`
    in place of its own: the compiled LMMSE gains and mean maps of the law as written
    (`filter_gains`), functions of the written float32 numbers only, the same bits on every
    machine. The double law's own gains inherit its last bits, which follow the BLAS kernel,
    amplified ~1e5 times by the error covariance's cancellation: what the Q15/Q31 filter
    tables store (`pipeline.fixed_point_estimator`). `loop` itself where the kernel does not
    apply."""
    import dataclasses
    compiled = filter_gains(problem, table, problem.measurement)
    if compiled is None:
        return loop
    return dataclasses.replace(loop, gain=compiled[0], predict=compiled[1])
