"""Corridors (``[[corridors]]``): where realisations of the outputs must stay.

A corridor says that over the ticks of ``t = [a, b]`` (both ends included) the output
``y = C x`` lies in a union of convex polygons, polygon ``P_k = {y : A_k y <= b_k}``, and
optionally that a design must keep the probability of leaving it at any of those ticks at
most ``epsilon``. The design ignores corridors unless asked; the oracle bounds
(`stospline.oracle.exit_bound`) and the Monte Carlo harness (`stospline.harness.montecarlo`) measure
them.

Walls. Every row of every polygon is a *wall*, numbered through the polygons in order (wall
``w`` is row ``w - row_start[k]`` of polygon ``k``). A point outside the union is attributed to
one wall: in each polygon its most violated row (largest ``(a y - b) / |a|``, the distance
beyond that half-plane), and of those the one of the polygon it is nearest to by that measure.
For the L-shaped robot corridor that is the wall a path actually crossed.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Corridor", "corridor_ticks"]


@dataclass(frozen=True)
class Corridor:
    """``C x(t)`` inside the union of ``{y : A_k y <= b_k}`` for every tick in ``t = [a, b]``.

    ``polygons`` holds ``(A_k, b_k)`` pairs (``A_k``: rows x p); ``epsilon`` the risk budget
    ``P(leave at some tick) <= epsilon`` (None: none given, measured only)."""
    t: tuple[float, float]
    C: np.ndarray
    polygons: tuple[tuple[np.ndarray, np.ndarray], ...]
    epsilon: float | None = None

    @property
    def p(self) -> int:
        return self.C.shape[0]

    @property
    def A(self) -> np.ndarray:
        """Every wall's row, stacked (walls x p)."""
        return np.vstack([A for A, _ in self.polygons])

    @property
    def b(self) -> np.ndarray:
        return np.concatenate([b for _, b in self.polygons])

    @property
    def row_start(self) -> np.ndarray:
        """Wall index of each polygon's first row, and the total (polygons + 1,)."""
        return np.concatenate([[0], np.cumsum([len(b) for _, b in self.polygons])]).astype(int)

    def wall_names(self) -> list[str]:
        """``"polygon k row i: a.y <= b"`` per wall, for reports."""
        out = []
        for k, (A, b) in enumerate(self.polygons):
            for i in range(len(b)):
                terms = " + ".join(f"{A[i, j]:g} y{j}" for j in range(A.shape[1]) if A[i, j])
                out.append(f"polygon {k} row {i}: {terms} <= {b[i]:g}")
        return out

    def unit_walls(self) -> tuple[np.ndarray, np.ndarray]:
        """``(A, b)`` of every wall scaled so each row of A has length 1: ``a y - b`` is then
        the distance beyond the wall (the harness's C uses these same numbers)."""
        A = np.ascontiguousarray(self.A, dtype=float)
        norm = np.linalg.norm(A, axis=1)
        return np.ascontiguousarray(A / norm[:, None]), np.ascontiguousarray(self.b / norm)

    def physical_walls(self) -> list[tuple[str, list[int]]]:
        """The walls grouped by the line they lie on (the same unit row and offset: two legs of
        the L share the outer walls), each as ``(label, wall indices)``, in order of first
        appearance; the label reads ``"1 y0 <= 0"``."""
        A, b = self.unit_walls()
        groups: dict = {}
        for w in range(len(b)):
            key = tuple(np.round(np.append(A[w], b[w]), 12))
            groups.setdefault(key, []).append(w)
        out = []
        for walls in groups.values():
            a, off = self.A[walls[0]], self.b[walls[0]]
            terms = " + ".join(f"{a[j]:g} y{j}" for j in range(len(a)) if a[j])
            out.append((f"{terms} <= {off:g}", walls))
        return out

    def exit_wall(self, Y: np.ndarray) -> np.ndarray:
        """The wall each output of `Y` (points x p) is attributed to, -1 inside the union
        (the module docstring's rule; ties go to the first)."""
        Y = np.atleast_2d(Y)
        starts = self.row_start
        A, b = self.unit_walls()
        excess = Y @ A.T - b                                       # points x walls
        best_wall = np.empty((Y.shape[0], len(self.polygons)), dtype=int)
        best = np.empty((Y.shape[0], len(self.polygons)))
        for k in range(len(self.polygons)):
            e = excess[:, starts[k]:starts[k + 1]]
            best_wall[:, k] = starts[k] + np.argmax(e, axis=1)
            best[:, k] = e.max(axis=1)
        k = np.argmin(best, axis=1)
        out = best_wall[np.arange(Y.shape[0]), k]
        return np.where(best[np.arange(Y.shape[0]), k] > 0, out, -1)


def corridor_ticks(corridor: Corridor, t0: float, tick_hz: int) -> tuple[int, int]:
    """The first and last tick index (states ``x(t0 + j / tick_hz)``) the corridor covers."""
    a, b = corridor.t
    return int(round((a - t0) * tick_hz)), int(round((b - t0) * tick_hz))
