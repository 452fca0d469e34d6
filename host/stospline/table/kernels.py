"""Compiled host kernel of the table layer (double precision C, loaded through cffi): the
composition of a stage's affine tick maps (`compose_kernel.c`), which `spline_latch` needs for
every latch re-solve of a spline table.

Built and cached as the designer's kernels are (`stospline.cache`: the user cache directory,
``STOSPLINE_CACHE_DIR`` overrides, keyed by a hash of the source, declarations and flags).
`affine_compose` returns None where the kernel cannot be built (no C compiler) or
``STOSPLINE_TABLE_KERNEL=numpy`` asks for the numpy reference (`spline_latch`'s pairwise
products).
"""
from __future__ import annotations

import os
import threading
import warnings
from pathlib import Path

import numpy as np

from stospline.cache import build_source_module, load_module

__all__ = ["affine_compose", "build_kernel", "KernelBuildError"]

_SOURCE = Path(__file__).with_name("compose_kernel.c")
_CDEF = """
int stsp_affine_compose(int n, int d, long T, const double *P, double *out, double *work);
"""
_CFLAGS = ["-std=c99", "-O3", "-Wall", "-Wextra"]
_loaded = None
_failed = False
_load_lock = threading.Lock()


class KernelBuildError(RuntimeError):
    """The table kernel could not be compiled or loaded (no C compiler, no cffi)."""


def build_kernel(build_dir: str | Path | None = None, *, quiet: bool = True) -> Path:
    """Compile the kernel (if not cached) and return the path of the extension module."""
    try:
        return build_source_module("_stsp_table_kernel", _SOURCE.read_bytes(), _CDEF, _CFLAGS,
                                   root=build_dir, quiet=quiet)
    except Exception as exc:  # noqa: BLE001 - any failure here means "no compiled kernel"
        raise KernelBuildError(f"cannot build {_SOURCE.name}: {exc}") from exc


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
                warnings.warn(f"{exc}; composing tick maps in numpy (slower)", RuntimeWarning,
                              stacklevel=3)
    return _loaded


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
    ffi, lib = mod.ffi, mod.lib
    status = lib.stsp_affine_compose(n, d, T, *(ffi.from_buffer("double[]", a)
                                                for a in (P, out, work)))
    if status != 0:
        raise ValueError(f"affine blocks of shape {P.shape}: not composable")
    return out
