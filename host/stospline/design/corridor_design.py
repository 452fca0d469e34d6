"""Designs that keep the *paths* inside a corridor with a risk budget: the centre-line knob.

The exit probability of a path is set by how far the mean runs from the walls in units of
the spread across them. With noise proportional to the velocity (the robot) the spread at the
corner is what leaves the corridor: its x-spread there is 0.52 with the outer wall one unit
from the centre line, a 2.7 % per-tick probability (Gaussian) even with the mean on the
centre line, so moving the mean (bands on E{C x}) does not meet a 1 % budget unless it also
changes the spread (which grows with the velocity; ``docs/evidence/corridor-exit.md``). The knob here does
both at once: for each stage, a running cost ``w |a'y - c|^2`` for every *strip* of the polygon
the stage's mean path lies in (two parallel walls ``a'y <= b1``, ``-a'y <= b2``; ``c`` their
centre line), i.e. a constant ``Q``, ``q``, ``rho`` per stage. It pulls the mean to the centre
line and, through the feedback it adds, shrinks the spread across the walls; the multiplicative
noise coupling is handled by evaluating every candidate with the exact oracle of its own law
(the covariance depends on the mean path through the velocity noise) and by Monte Carlo
through the compiled C controller, not by a Gaussian model. The data stay constant per stage,
so the Monte Carlo harness keeps its fused C tick.

A second weight damps the outputs' rate (the velocity), whose heavy tails make paths
overshoot the open end of a leg. `strip_weights_problem` builds the problem for the two
weights; the search (the grid point of least cost in the original cost functional whose
Monte Carlo upper bound meets epsilon, certified on fresh paths) is
`stospline.corridor_search`, the command ``stospline corridor-design``.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from stospline.problem.corridors import Corridor

__all__ = ["strips", "stage_polygons", "strip_weights_problem", "add_strip_cost"]


def strips(A: np.ndarray, b: np.ndarray, tol: float = 1e-12) -> list[tuple[np.ndarray, float]]:
    """``(a, c)`` per pair of opposite walls of one polygon (unit normal a, centre line
    ``a'y = c``)."""
    norm = np.linalg.norm(A, axis=1)
    U, off = A / norm[:, None], b / norm
    out = []
    for i in range(len(U)):
        for j in range(i + 1, len(U)):
            if np.allclose(U[i], -U[j], atol=tol):
                out.append((U[i], 0.5 * (off[i] - off[j])))
    return out


def stage_polygons(problem, corridor: Corridor, y_mean: np.ndarray) -> list[int]:
    """For each stage, the polygon holding most of its ticks' mean outputs (`y_mean`, ticks
    + 1 x p, of some design; the deepest one at each tick)."""
    A, b = corridor.unit_walls()
    margin = b[None, :] - y_mean @ A.T                       # ticks x walls
    starts = corridor.row_start
    depth = np.stack([margin[:, starts[k]:starts[k + 1]].min(axis=1)
                      for k in range(len(corridor.polygons))], axis=1)
    best = np.argmax(depth, axis=1)
    bounds = np.concatenate([[0], np.cumsum(problem.ticks_per_stage)])
    return [int(np.bincount(best[lo + 1:hi + 1], minlength=depth.shape[1]).argmax())
            for lo, hi in zip(bounds[:-1], bounds[1:])]


def strip_weights_problem(problem, corridor: Corridor, polygons: list[int], weight: float,
                          rate_weight: float = 0.0):
    """`problem` with ``weight * (a'C x - c)^2`` added to the running cost of stage k for every
    strip ``(a, c)`` of polygon ``polygons[k]``: ``Q += w C'aa'C``, ``q -= w c C'a``,
    ``rho += w c^2``; and ``rate_weight * |C A x|^2``, the outputs' drift rate (the robot's
    velocity): with noise proportional to the velocity its tails are heavy (a velocity that
    runs away overshoots the end of a leg, which no strip faces), and damping it shortens
    them. Stages with time-varying data are refused (ValueError): the knob keeps the data
    constant."""
    stages = []
    for k, st in enumerate(problem.stages):
        if st.varying is not None:
            raise ValueError("strip weights: stage data must be constant")
        Q, q, rho = st.Q.copy(), st.q.copy(), float(st.rho)
        rate = corridor.C @ st.A
        Q += rate_weight * rate.T @ rate
        rho = add_strip_cost(corridor, polygons[k], weight, Q, q, rho)
        stages.append(replace(st, Q=Q, q=q, rho=rho))
    return replace(problem, stages=tuple(stages))


def add_strip_cost(corridor: Corridor, polygon: int, weight: float, Q: np.ndarray,
                   q: np.ndarray, rho: float) -> float:
    """Add ``weight * |a'C x - c|^2`` for every strip ``(a, c)`` of the corridor's polygon
    `polygon` to the cost ``x'Qx + 2q'x + rho``: `Q` and `q` in place; returns the new rho."""
    A, b = corridor.polygons[polygon]
    for a, c in strips(A, b):
        g = corridor.C.T @ a
        Q += weight * np.outer(g, g)
        q -= weight * c * g
        rho += weight * c * c
    return rho
