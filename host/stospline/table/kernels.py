"""Compiled host kernels of the table layer (C, loaded through cffi): the composition of a
stage's affine tick maps (`compose_kernel.c`), which `spline_latch` needs for every latch
re-solve of a spline table, the exact evaluation of a fixed-point spline stage with its
error (`qspline_kernel.c`), which `qspline` needs for every span length it tries, and the
shortest float32 literals of a table's C text (`literal_kernel.c`, `codegen`).

Built and cached as the designer's kernels are (`stospline.cache`: the user cache directory,
``STOSPLINE_CACHE_DIR`` overrides, keyed by a hash of the source, declarations and flags).
`affine_compose`, `affine_compose_gains`, `qspline_stage` and `f32_array_text` return None
where the kernels cannot be built (no C compiler) or ``STOSPLINE_TABLE_KERNEL=numpy`` asks for
the numpy references (`spline_latch`'s pairwise products of `spline_latch._tick_blocks`,
`qspline._stage_gains`, numpy's `format_float_scientific`).
"""
from __future__ import annotations

import os
import threading
import warnings
from pathlib import Path

import numpy as np

from stospline.cache import FallbackWarning, build_kernel_sources, load_module
from stospline.errors import KernelBuildError

__all__ = ["affine_compose", "affine_compose_gains", "qspline_stage", "f32_array_text",
           "build_kernel", "KernelBuildError"]

_SOURCES = [Path(__file__).with_name(f)
            for f in ("compose_kernel.c", "qspline_kernel.c", "literal_kernel.c")]
_CDEF = """
int stsp_affine_compose(int n, int d, long T, const double *P, double *out, double *work);
int stsp_affine_compose_gains(int n, int d, long T, long K, const double *g, const int64_t *col,
                              const double *vec, const double *base, double *out,
                              double *work);
int stsp_qspline_stage(int k, long T, long E, long nb, const int64_t *C, const int64_t *shift,
                       const double *YT, const double *allowed, int64_t *G, double *err);
long stsp_f32_array_text(long N, const float *x, long per_line, char *out, long cap,
                         long *flagged, long *n_flagged);
"""
_LITERAL_SLOT = 16   # literal_kernel.c's STSP_LITERAL_SLOT
_loaded = None
_failed = False
_load_lock = threading.Lock()


def build_kernel(build_dir: str | Path | None = None, *, quiet: bool = True) -> Path:
    """Compile the kernel (if not cached) and return the path of the extension module."""
    return build_kernel_sources("_stsp_table_kernel", _SOURCES, _CDEF, root=build_dir,
                                quiet=quiet)


def _kernel():
    """The loaded module, built on first use; None where it cannot be built (tried once per
    process, with a warning) or the numpy path is asked for."""
    global _loaded, _failed
    if os.environ.get("STOSPLINE_TABLE_KERNEL", "c") == "numpy":
        return None
    with _load_lock:
        if _loaded is None and not _failed:
            try:
                _loaded = load_module(build_kernel())
            except KernelBuildError as exc:
                _failed = True
                warnings.warn(f"{exc}; the table layer runs its numpy references (slower)",
                              FallbackWarning, stacklevel=3)
    return _loaded


def _buffers(ffi, *arrays: np.ndarray) -> list:
    """C pointers to contiguous float64 / int64 arrays, for one kernel call."""
    return [ffi.from_buffer("int64_t[]" if a.dtype == np.int64 else "double[]", a)
            for a in arrays]


def affine_compose(P: np.ndarray) -> np.ndarray | None:
    """``P[-1] o ... o P[0]`` of the affine blocks `P` (T, n, d) (`compose_kernel.c`), or None
    where the kernel is not available."""
    mod = _kernel()
    if mod is None:
        return None
    T, n, d = P.shape
    P = np.ascontiguousarray(P, dtype=np.float64)
    out = np.empty((n, d))
    work = np.empty(2 * n * d)
    status = mod.lib.stsp_affine_compose(n, d, T, *_buffers(mod.ffi, P, out, work))
    if status != 0:
        raise ValueError(f"affine blocks of shape {P.shape}: not composable")
    return out


def affine_compose_gains(base: np.ndarray, col: np.ndarray, vec: np.ndarray, g: np.ndarray
                         ) -> np.ndarray | None:
    """The composition of the blocks ``P[t] = base`` plus ``g[t, k] vec[k]`` in column
    ``col[k]`` (k in turn), ``P[-1] o ... o P[0]`` (`compose_kernel.c`), without forming them:
    `base` (n, d), `col` (K,), `vec` (K, n), `g` (T, K). None where the kernel is not
    available."""
    mod = _kernel()
    if mod is None:
        return None
    base = np.ascontiguousarray(base, dtype=np.float64)
    n, d = base.shape
    g = np.ascontiguousarray(g, dtype=np.float64)
    T, K = g.shape
    col = np.ascontiguousarray(col, dtype=np.int64)
    vec = np.ascontiguousarray(vec, dtype=np.float64)
    if col.shape != (K,) or vec.shape != (K, n):
        raise ValueError(f"columns {col.shape} and vectors {vec.shape} for {K} gains of "
                         f"blocks {base.shape}")
    out = np.empty((n, d))
    work = np.empty(4 * n * d)
    status = mod.lib.stsp_affine_compose_gains(
        n, d, T, K, *_buffers(mod.ffi, g, col, vec, base, out, work))
    if status != 0:
        raise ValueError(f"{T} ticks of blocks {base.shape} with gain columns {col.tolist()}: "
                         f"not composable")
    return out


def qspline_stage(k: int, C: np.ndarray, shift: np.ndarray, YT: np.ndarray,
                  allowed: np.ndarray | None = None
                  ) -> tuple[np.ndarray, np.ndarray] | bool | None:
    """``(G, err)`` of a fixed-point spline stage (`qspline_kernel.c`): its E entries'
    integer gains at ticks 0..T-1 as the firmware evaluates them, G (T, E) int64 (a view of
    an (E, T) array), from coefficients `C` (E, nb) and scales `shift` (E,) on spans of 2^k
    ticks, and each entry's worst ``|G - YT|`` against the values fitted `YT` (E, T).
    With `allowed` (E,): False as soon as an entry's error exceeds its allowance. None where
    the kernel is not available."""
    mod = _kernel()
    if mod is None:
        return None
    YT = np.ascontiguousarray(YT, dtype=np.float64)
    E, T = YT.shape
    C = np.ascontiguousarray(C, dtype=np.int64)
    shift = np.ascontiguousarray(shift, dtype=np.int64)
    if C.ndim != 2 or C.shape[0] != E or shift.shape != (E,):
        raise ValueError(f"coefficients {C.shape} and shifts {shift.shape} for {E} entries")
    G = np.empty((E, T), dtype=np.int64)
    err = np.empty(E)
    ffi = mod.ffi
    if allowed is not None:
        allowed = np.ascontiguousarray(np.broadcast_to(allowed, (E,)), dtype=np.float64)
    limit = ffi.NULL if allowed is None else _buffers(ffi, allowed)[0]
    c, sh, y, g, e = _buffers(ffi, C, shift, YT, G, err)
    status = mod.lib.stsp_qspline_stage(int(k), T, E, C.shape[1], c, sh, y, limit, g, e)
    if status < 0:
        raise ValueError(f"a fixed-point spline stage of {T} ticks, spans of 2^{k}, "
                         f"coefficients {C.shape}: not evaluable")
    return (G.T, err) if status == 0 else False


def f32_array_text(values: np.ndarray, per_line: int) -> str | None:
    """The body of a C array of float32 `values`: lines of `per_line` literals
    (``"    -1.2573022e-01f, 1.0e+00f,"``), each the shortest that reads back, as numpy's
    ``format_float_scientific(unique=True, trim="0", exp_digits=2)`` writes it
    (`literal_kernel.c`; the values it cannot vouch for are written by numpy here). None
    where the kernel is not available; ValueError for a non-finite value."""
    mod = _kernel()
    if mod is None:
        return None
    x = np.ascontiguousarray(np.ravel(values), dtype=np.float32)
    if x.size == 0:
        return ""
    cap = x.size * (_LITERAL_SLOT + 2) + 4 * (x.size // per_line + 1) + 8
    out = np.empty(cap, dtype=np.uint8)
    flagged = np.empty(x.size, dtype=np.dtype("l"))     # C long
    n_flagged = np.zeros(1, dtype=np.dtype("l"))
    ffi = mod.ffi
    n = mod.lib.stsp_f32_array_text(x.size, ffi.from_buffer("float[]", x), per_line,
                                    ffi.from_buffer("char[]", out), cap,
                                    ffi.from_buffer("long[]", flagged),
                                    ffi.from_buffer("long[]", n_flagged))
    if n < 0:
        bad = x[~np.isfinite(x)]
        if bad.size:
            raise ValueError(f"a table entry is {bad[0]}: generated C holds finite numbers only")
        raise ValueError(f"{x.size} literals, {per_line} a line: not written")
    text = out[:n].tobytes().decode("ascii")
    if not n_flagged[0]:
        return text
    pieces = text.split("?")
    literals = [np.format_float_scientific(v, unique=True, trim="0", exp_digits=2) + "f"
                for v in x[flagged[:n_flagged[0]]] + np.float32(0)]
    return "".join(p + lit for p, lit in zip(pieces, literals)) + pieces[-1]
