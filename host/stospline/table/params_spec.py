"""The specification of the firmware's parametric law (``stsp_param_step``,
firmware/include/stospline/stsp_params.h) in numpy float32: the same operations in the same
order, one rounding per multiply and per add, so that the compiled C must agree bit for bit
(up to the sign of a zero command). Batched over paths; per-tick float32 tables, ticks in
order from 0 (the C tests cover skips, repeats and errors)."""
from __future__ import annotations

import numpy as np

__all__ = ["ParamSpec"]

f32 = np.float32


class ParamSpec:
    """``set(theta)`` and ``step(tick, X) -> U`` for `paths` instances of the law `table`
    (`stospline.table.format.GainTable`) with the parameter columns `cols`
    (`stospline.table.parametric_c.flash_columns`)."""

    def __init__(self, table, cols: dict, paths: int):
        if getattr(table, "spline", None) is not None or getattr(table, "arith",
                                                                 "float32") != "float32":
            raise ValueError("ParamSpec: float32 tables with gains per tick only")
        self.t = table
        self.K, self.k0, self.L, self.Lambda, self.lambda0, self.u_min, self.u_max = (
            np.asarray(a, f32) for a in (table.K, table.k0, table.L, table.Lambda,
                                         table.lambda0, table.u_min, table.u_max))
        self.cols = {k: np.asarray(v, f32) for k, v in cols.items()}
        self.d = np.zeros(len(self.cols["nominal"]), f32)
        self.v = np.zeros((paths, table.dims[2]), f32)

    def set(self, theta) -> None:
        """d = theta - nominal in binary32 (the range check is the C's)."""
        self.d = np.asarray(theta, f32) - self.cols["nominal"]

    def _shift(self, c, S) -> np.float32:
        e = f32(c)
        for p in range(len(self.d)):
            e = f32(e + f32(S[p] * self.d[p]))
        return e

    def step(self, j: int, X: np.ndarray) -> np.ndarray:
        X = np.asarray(X, f32)
        self._latch(j, X)
        return self._command(j, X)

    def _latch(self, j: int, X: np.ndarray) -> None:
        """At a latching tick, ``v = lambda0' + Lambda x`` (stsp_params.h's order)."""
        t = self.t
        n, _, nl = t.dims
        k = t.stage_of_tick(j)
        if j == int(t.stage_start[k]) and (k == 0 or t.stage_n_latch[k] > 0):
            for c in range(nl):
                if c >= t.stage_n_latch[k]:
                    self.v[:, c] = f32(0)
                    continue
                acc = np.full(X.shape[0], self._shift(self.lambda0[k][c],
                                                      self.cols["S_lambda0"][k, c]), f32)
                for col in range(n):
                    acc = acc + self.Lambda[k][c, col] * X[:, col]
                self.v[:, c] = acc

    def _command(self, j: int, X: np.ndarray) -> np.ndarray:
        """The clamped commands of tick j (per-tick rows)."""
        t = self.t
        n, m, nl = t.dims
        U = np.empty((X.shape[0], m), f32)
        for i in range(m):
            acc = np.full(X.shape[0], -self._shift(self.k0[j][i], self.cols["S_k0"][j, i]), f32)
            for c in range(n):
                acc = acc - self.K[j][i, c] * X[:, c]
            for c in range(nl):
                acc = acc - self.L[j][i, c] * self.v[:, c]
            U[:, i] = np.minimum(np.maximum(acc, self.u_min[i]), self.u_max[i])
        return U
