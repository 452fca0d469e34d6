"""The fourth-moment oracle's loop in C (``tails_kernel.c``, compiled into the oracle's module,
`oracle.kernel`): the step's map on symmetric tensors (`_Sym.operator` without the dense
tensor products) and a stage's ticks (`_TickOperator.apply` tick after tick), equal to the
numpy loop of `oracle.tails` to rounding.

A tick's moments of ``q = [x; u; v; 1]`` are gathered from the levels of contractions of
``E y^(x)4`` (and ``E J y y'``) with the command's rows (``tails_kernel.c``); `CompiledTails`
holds where each of q's moments sits among them, and where each of y's lies among q's.
`compiled_tails` returns None where the numpy loop runs: ``STOSPLINE_ORACLE_KERNEL=numpy``
asks for it, and a host where the module cannot be built falls back to it with a
`cache.FallbackWarning`.
"""
from __future__ import annotations

import os
import warnings

import numpy as np

from stospline.errors import KernelBuildError

__all__ = ["CompiledTails", "compiled_tails"]


def compiled_tails(n: int, m: int, n_latch: int, s4, s2, *, sym, step_matrix
                   ) -> "CompiledTails | None":
    """The C loop for a loop of these dimensions (`s4`, `s2`: `tails._Sym` of order 4 and 2
    on q), or None where the numpy loop runs (see the module docstring). `sym` and
    `step_matrix` are `tails._Sym` and `tails.step_matrix`, handed in by `oracle.tails`
    (which imports this module, not the other way round)."""
    if os.environ.get("STOSPLINE_ORACLE_KERNEL", "c") == "numpy":
        return None
    from stospline.oracle.kernel import load_kernel
    try:
        mod = load_kernel()
    except KernelBuildError as exc:
        from stospline.cache import FallbackWarning
        warnings.warn(f"{exc}; the fourth-moment oracle runs its numpy loop (slower)",
                      FallbackWarning, stacklevel=3)
        return None
    return CompiledTails(mod, n, m, n_latch, s4, s2, sym, step_matrix)


def _number(sy: dict, size: int, flat: np.ndarray) -> np.ndarray:
    """The numbers of multisets of `size` y-indices given by a full index of each (row-major;
    the empty multiset is number 0)."""
    return np.zeros_like(flat) if size == 0 else sy[size].of_full[flat]


def _insertions(sy: dict, dy: int) -> np.ndarray:
    """``tails_kernel.c``'s ``ins``: for sizes s = 1 to 4 in turn, the number of the multiset
    {j} + t of s y-indices, per j (rows) and multiset t of s - 1 (columns)."""
    tables = []
    for s in range(1, 5):
        rest = sy[s - 1].rep if s > 1 else np.zeros(1, dtype=np.intp)
        tables.append(_number(sy, s, np.arange(dy)[:, None] * dy ** (s - 1) + rest[None, :]))
    return np.ascontiguousarray(np.concatenate([t.ravel() for t in tables]), dtype=np.int64)


def _sources(s, sy: dict, n: int, m: int, dy: int) -> np.ndarray:
    """Where each multiset of q-indices of `s` sits among the contraction levels of order
    ``s.order`` (``tails_kernel.c``'s ``tails_levels``): level k (k commands among the
    indices) after the lower ones, its u-indices in order, then the number of the multiset
    of the other indices, as y's."""
    o = s.order
    idx = s.idx
    is_u = (idx >= n) & (idx < n + m)
    k = is_u.sum(axis=1)
    count = [len(sy[o - j].idx) if o > j else 1 for j in range(o + 1)]
    base = np.cumsum([0] + [m ** j * count[j] for j in range(o)])
    A = np.zeros(len(idx), dtype=np.int64)
    R = np.zeros(len(idx), dtype=np.int64)
    for t in range(o):
        col, u = idx[:, t], is_u[:, t]
        A = np.where(u, A * m + (col - n), A)
        R = np.where(u, R, R * dy + np.where(col < n, col, col - m))
    rest = np.zeros(len(idx), dtype=np.int64)
    for j in range(o + 1):
        rows = k == j
        rest[rows] = _number(sy, o - j, R[rows])
    return np.ascontiguousarray(base[k] + A * np.take(count, k) + rest, dtype=np.int64)


def _back(s, sy: dict, n: int, m: int) -> np.ndarray:
    """The number among q's multisets of each of y's (of the order of `s`)."""
    q = sy[s.order].idx
    q = np.where(q < n, q, q + m)
    flat = np.ravel_multi_index(tuple(q.T), (s.d,) * s.order)
    return np.ascontiguousarray(s.of_full[flat], dtype=np.int64)


class CompiledTails:
    """The C loop of `oracle.tails` for one loop's dimensions (see the module docstring)."""

    def __init__(self, mod, n: int, m: int, n_latch: int, s4, s2, sym, step_matrix):
        self.mod, self.n, self.m, self.n_latch = mod, n, m, n_latch
        self.s4, self.s2 = s4, s2
        self._step_matrix = step_matrix
        self.dy = dy = n + n_latch + 1
        self.sy = sy = {size: sym(dy, size) for size in range(1, 5)}
        self.ins = _insertions(sy, dy)
        self.src4, self.src2 = (_sources(s, sy, n, m, dy) for s in (s4, s2))
        self.back4, self.back2 = (_back(s, sy, n, m) for s in (s4, s2))

    def operator(self, s, nodes) -> np.ndarray:
        """`_Sym.operator` of `s` over `nodes` ``(w, M)``, summed in the same order."""
        ffi, lib = self.mod.ffi, self.mod.lib
        d, size = s.d, s.size
        w = np.array([wt for wt, _ in nodes], dtype=np.float64)
        M = np.ascontiguousarray(np.array([Mn for _, Mn in nodes], dtype=np.float64))
        idx = np.ascontiguousarray(s.idx, dtype=np.int64)
        of_full = np.ascontiguousarray(s.of_full, dtype=np.int64)
        out = np.zeros((size, size))
        work = np.empty(size + d * d)
        iwork = np.zeros(2 * size + d + d * d, dtype=np.int64)
        status = lib.stsp_tails_operator(
            d, s.order, size, 0, size, ffi.from_buffer("int64_t[]", idx), len(nodes),
            ffi.from_buffer("double[]", M), ffi.from_buffer("double[]", w),
            ffi.from_buffer("int64_t[]", of_full), ffi.from_buffer("double[]", out),
            ffi.from_buffer("double[]", work), ffi.from_buffer("int64_t[]", iwork))
        if status != 0:
            raise ValueError(f"stsp_tails_operator: bad dimensions (status {status})")
        return out

    def step(self, stage, h: float, substeps: int):
        """One plant step's map (`tails.step_matrix`) in CSR, and the steps per tick."""
        S = self._step_matrix(stage, self.n, self.m, self.n_latch, h / substeps, self.s4, self.s2,
                        operator=self.operator)
        rows, cols = np.nonzero(S)
        rowptr = np.zeros(len(S) + 1, dtype=np.int64)
        np.cumsum(np.bincount(rows, minlength=len(S)), out=rowptr[1:])
        return (rowptr, cols.astype(np.int64), np.ascontiguousarray(S[rows, cols]), substeps)

    def ticks(self, step, K, L, k0, T4: np.ndarray, P: np.ndarray, J2: float):
        """The ticks with gains ``K`` (T, m, n), ``L`` (T, m, n_latch), ``k0`` (T, m) from
        ``E y^(x)4``, ``E J y y'`` and ``E J^2``: those after them (new arrays)."""
        ffi, lib = self.mod.ffi, self.mod.lib
        rowptr, cols, vals, substeps = step
        K, L, k0 = (np.ascontiguousarray(a, dtype=np.float64) for a in (K, L, k0))
        T4, P = np.asarray(T4, dtype=np.float64), np.asarray(P, dtype=np.float64)
        T, dy = len(K), self.dy
        want = [(K, (T, self.m, self.n)), (L, (T, self.m, self.n_latch)), (k0, (T, self.m)),
                (T4, (dy,) * 4), (P, (dy, dy))]
        if any(a.shape != shape for a, shape in want):
            raise ValueError("CompiledTails.ticks: arrays of the wrong shapes")
        Y4 = np.ascontiguousarray(self.sy[4].compress(T4))
        Y2 = np.ascontiguousarray(self.sy[2].compress(P))
        D4, D2 = self.s4.size, self.s2.size
        work = np.empty(int(lib.stsp_tails_ticks_work(self.m, self.dy, D4, D2)))
        J2p = ffi.new("double *", float(J2))
        buf = [ffi.from_buffer("int64_t[]" if a.dtype == np.int64 else "double[]", a)
               for a in (K, L, k0, rowptr, cols, vals, self.ins, self.src4, self.src2,
                         self.back4, self.back2, Y4, Y2, work)]
        status = lib.stsp_tails_ticks(self.n, self.m, self.n_latch, T, *buf[:3], D4, D2,
                                      *buf[3:6], substeps, *buf[6:13], J2p, buf[13])
        if status != 0:
            raise ValueError(f"stsp_tails_ticks: bad dimensions (status {status})")
        return self.sy[4].expand(Y4), self.sy[2].expand(Y2), float(J2p[0])
