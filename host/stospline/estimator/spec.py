"""The specification of the firmware's estimator controller (``stsp_est_step``,
firmware/include/stospline/stsp_estimator.h) in numpy float32: the same operations in the same
order, one rounding per multiply and per add, so that the compiled C must agree bit for bit
(up to the sign of a zero command). Batched over paths. Per-tick gain tables; ticks in order
or skipped ahead (the missed ticks predicted with the last command held), no repeats or errors
(the C tests cover those)."""
from __future__ import annotations

import numpy as np

__all__ = ["EstimatorSpec"]

f32 = np.float32


class EstimatorSpec:
    """``step(tick, Y) -> U`` for `paths` instances of the law `table` on the filter `et`
    (`estimator.ctable.EstimatorTable`); Y (paths, ny) float32, or None without a reading."""

    def __init__(self, table, et, paths: int):
        if getattr(table, "spline", None) is not None or getattr(table, "arith",
                                                                 "float32") != "float32":
            raise ValueError("EstimatorSpec: float32 tables with gains per tick only")
        self.t, self.et = table, et
        n, m, nl = table.dims
        self.xhat = np.tile(et.xhat0.astype(f32), (paths, 1))
        self.v = np.zeros((paths, nl), f32)
        self.pred = self._maps()
        self.next = 0
        self.u_last = np.tile(np.asarray(table.u_hold, f32), (paths, 1))
        self.K, self.k0, self.L, self.Lambda, self.lambda0, self.u_min, self.u_max = (
            np.asarray(a, f32) for a in (table.K, table.k0, table.L, table.Lambda,
                                         table.lambda0, table.u_min, table.u_max))

    def _maps(self) -> np.ndarray:
        et = self.et
        out = np.empty((et.n_ticks,) + et.model.shape[1:], f32)
        for s in range(et.n_stages):
            a, b = int(et.stage_start[s]), int(et.stage_start[s + 1])
            maps = et.model[int(et.model_start[s]):int(et.model_start[s + 1])]
            out[a:b] = maps if len(maps) == b - a else maps[0]
        return out

    def step(self, j: int, Y: np.ndarray | None) -> np.ndarray:
        t, et = self.t, self.et
        n, m, nl = t.dims
        x = self.xhat.copy()
        for missed in range(self.next, j):
            x = self._predict(missed, x, self.u_last)
        if j % et.every == 0 and Y is not None:
            F = et.gain[j // et.every]
            e = np.empty((x.shape[0], et.ny), f32)
            for i in range(et.ny):
                acc = Y[:, i].astype(f32)
                for c in range(n):
                    acc = acc - et.C[i, c] * x[:, c]
                e[:, i] = acc
            for r in range(n):
                acc = x[:, r].copy()
                for i in range(et.ny):
                    acc = acc + F[r, i] * e[:, i]
                x[:, r] = acc
        k = t.stage_of_tick(j)
        if j == int(t.stage_start[k]) and (k == 0 or t.stage_n_latch[k] > 0):
            for c in range(nl):
                acc = np.full(x.shape[0], self.lambda0[k][c], f32)
                for col in range(n):
                    acc = acc + self.Lambda[k][c, col] * x[:, col]
                self.v[:, c] = acc if c < t.stage_n_latch[k] else f32(0)
        U = np.empty((x.shape[0], m), f32)
        for i in range(m):
            acc = np.full(x.shape[0], self.k0[j][i], f32)
            for c in range(n):
                acc = acc + self.K[j][i, c] * x[:, c]
            for c in range(nl):
                acc = acc + self.L[j][i, c] * self.v[:, c]
            U[:, i] = np.minimum(np.maximum(-acc, self.u_min[i]), self.u_max[i])
        self.xhat = self._predict(j, x, U)
        self.u_last, self.next = U, j + 1
        return U

    def _predict(self, j: int, x: np.ndarray, U: np.ndarray) -> np.ndarray:
        n, m = self.t.dims[:2]
        P = self.pred[j]
        xn = np.empty_like(x)
        for r in range(n):
            acc = np.full(x.shape[0], P[r, n + m], f32)
            for c in range(n):
                acc = acc + P[r, c] * x[:, c]
            for c in range(m):
                acc = acc + P[r, n + c] * U[:, c]
            xn[:, r] = acc
        return xn
