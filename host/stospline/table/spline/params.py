"""Spline forms of a parametric table's sensitivity columns (float32).

A parametric table (`stospline.table.parametric.ParametricTable`) adds to the feed-forward of
tick ``j`` the columns ``S_k0[j] d``, ``d = theta - theta_nom``. For a spline gain table the
columns are cubic B-splines too, on the nominal spline's own knots (stage by stage), so that
the basis the firmware evaluates for the gains at a tick serves the columns as well. Per
stage ``s``, input ``i`` and parameter ``p`` the ``S_s + 3`` coefficients are stored in

    coef[nu P (knot_start[s] - 4 s) + (i P + p) (S_s + 3) + r]

(``knot_start`` the gain spline's; ``S_s + 3 = knot_start[s+1] - knot_start[s] - 4``).

The law as the firmware evaluates it (``stsp_param_step`` with a spline table, bit for bit
`command`): at tick ``j`` of stage ``s``, in span ``sigma`` with basis ``N`` (The NURBS Book
A2.2, `stospline.table.spline.fit._basis`), per input ``i`` the fold of the feed-forward of
`stospline.table.spline.fit.command` (``f[r] = ((+0 - c_k0[r]) - c_L1[r] v_1) - ...``) goes on
with the columns, ``f[r] = f[r] - c_p[r] d_p`` for ``p = 0 .. P-1``; its value
``((N0 f0 + N1 f1) + N2 f2) + N3 f3`` starts the command, from which each gain of ``x`` times
its state entry is subtracted in stored order; then the clamp. At ``d = 0`` it is the
ordinary spline command bit for bit (up to the sign of a zero).

Error: the fit is a least squares at the stage's ticks (coefficients on the float32 grid of
the column's peak, as the gains' `_coefficients`); ``error[i, p]`` is the largest
``|S_k0 evaluated - S_k0 exact|`` over the ticks (evaluated in binary32 as the firmware
does), and ``box_error[i]`` the largest over the ticks of
``sum_p max(D_ip(j) (upper_p - nom_p), -D_ip(j) (nom_p - lower_p))`` with ``D`` the signed
error: the largest change of the command's feed-forward from the compression over the box,
exactly (affine in ``d``: its extreme is at a vertex).

The latch offsets' columns are re-solved for the spline's law as the nominal's are
(`stospline.table.spline.latch.resolve_latch` on the problem with parameter ``p``'s source
alone, `stospline.design.sensitivity.unit_problem`, under the spline gains and the column's
feed-forward as evaluated): the constraints of every latch then hold in expectation for
every ``theta`` of the box, as for the nominal. A table that latches the state (restored
feed-forward, `stospline.table.spline.restore`) has no latch offsets; its columns are fitted
but not restored (the certificate over the box, `stospline.refine.spline_params`, says what
then holds).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stospline.table.format import positive_zeros
from stospline.table.params_spec import ParamSpec
from stospline.table.spline.fit import (_Bases, _basis, _combine, _coefficients,
                                        _ill_conditioned, _min_norm, _normal_rhs,
                                        _solve_banded)

__all__ = ["SplineColumns", "fit_columns", "column_layout", "command", "ParamSplineSpec"]

f32 = np.float32


@dataclass(frozen=True)
class SplineColumns:
    """The spline columns of a parametric table on a spline gain table's knots.

    ``coef`` float32 in the module docstring's layout; ``S_k0`` (ticks, nu, P) their
    evaluation as the firmware computes it (float32); ``S_lambda0`` (stages, n_latch, P) the
    re-solved latch columns (float32); ``error`` (nu, P) and ``box_error`` (nu,) as in the
    module docstring."""
    coef: np.ndarray
    S_k0: np.ndarray
    S_lambda0: np.ndarray
    error: np.ndarray
    box_error: np.ndarray

    @property
    def nbytes(self) -> int:
        """Bytes of the columns in flash (coefficients and latch columns)."""
        return int(self.coef.nbytes + self.S_lambda0.nbytes)


def column_layout(spline, P: int) -> np.ndarray:
    """The first coefficient of each stage's columns, then their number (n_stages + 1)."""
    ks = np.asarray(spline.knot_start, np.int64)
    return spline.nu * P * (ks - 4 * np.arange(ks.size))


def fit_columns(spline, stage_start, S_k0: np.ndarray, parameters) -> tuple[np.ndarray,
                                                                              np.ndarray,
                                                                              np.ndarray]:
    """``(coef, evaluated, error)``: the least-squares fit of the exact columns `S_k0`
    (ticks, nu, P, float64) on `spline`'s knots, the float32 evaluation at every tick and the
    largest error per input and parameter."""
    start = np.asarray(stage_start, np.int64)
    T_all, nu, P = S_k0.shape
    offs = column_layout(spline, P)
    coef = np.zeros(int(offs[-1]), np.float32)
    G_all = np.zeros((T_all, nu, P), np.float32)
    bases = _Bases()
    for s in range(spline.n_stages):
        a, b = int(start[s]), int(start[s + 1])
        breaks = np.asarray(spline.knots(s)[3:-3], np.float64).astype(np.int64)
        sigma, N, N64, band = bases.get(b - a, breaks)
        YT = np.ascontiguousarray(S_k0[a:b].reshape(b - a, nu * P).T, dtype=float)
        if _ill_conditioned(breaks):
            C = _min_norm(breaks, sigma, N64, YT)
        else:
            C = _solve_banded(band, _normal_rhs(breaks, N64, YT).T).T
        C = _coefficients(C, np.abs(YT).max(axis=1))
        coef[offs[s]:offs[s + 1]] = C.ravel()
        G_all[a:b] = _combine(sigma, N, C).reshape(b - a, nu, P)
    coef = positive_zeros(coef)
    error = np.abs(G_all.astype(float) - S_k0).max(axis=0) if T_all else np.zeros((nu, P))
    return coef, G_all, error


def box_error(evaluated: np.ndarray, exact: np.ndarray, parameters) -> np.ndarray:
    """Per input, the largest change of the feed-forward over the box that the compression
    makes: ``max_j sum_p max(D (upper - nom), -D (nom - lower))``, ``D`` the signed error."""
    nom = np.array([p.nominal for p in parameters])
    up = np.array([p.upper for p in parameters]) - nom
    down = nom - np.array([p.lower for p in parameters])
    D = evaluated.astype(float) - exact
    return np.maximum(D * up, -D * down).sum(axis=2).max(axis=0)


def command(table, cols: SplineColumns, tick: int, x, v, d) -> np.ndarray:
    """The unclamped command of ``stsp_param_step`` at `tick` of spline table `table`
    (`GainTable` with ``spline``) with the columns `cols`, state `x`, latch `v` and ``d =
    theta - nominal`` (float32), bit for bit (module docstring)."""
    sp = table.spline
    start = np.asarray(table.stage_start, np.int64)
    s = int(np.searchsorted(start[1:], tick, side="right"))
    P = len(d)
    x, v, d = (np.asarray(a, f32) for a in (x, v, d))
    z = np.concatenate([x, [f32(1)], v]).astype(f32)
    sigma, N = _basis(np.asarray(sp.knots(s), f32), np.array([tick - start[s]], f32))
    sg, N = int(sigma[0]), [n[0] for n in N]
    C = sp.coefficients(s)[:, sg:sg + 4]
    width = sp.spans(s) + 3
    Cp = cols.coef[column_layout(sp, P)[s]:column_layout(sp, P)[s + 1]]
    Cp = Cp.reshape(sp.nu, P, width)[:, :, sg:sg + 4]
    inputs, ccol = sp.entries(s)

    def value(c):
        g = f32(N[0] * c[0])
        for r in (1, 2, 3):
            g = f32(g + f32(N[r] * c[r]))
        return g

    u = np.zeros(sp.nu, f32)
    for i in range(sp.nu):
        fold = np.zeros(4, f32)
        for e in np.flatnonzero((inputs == i) & (ccol >= sp.nx)):
            fold = (fold - C[e] * z[ccol[e]]).astype(f32)
        for p in range(P):
            fold = (fold - Cp[i, p] * d[p]).astype(f32)
        acc = value(fold)
        for e in np.flatnonzero((inputs == i) & (ccol < sp.nx)):
            acc = f32(acc - f32(value(C[e]) * z[ccol[e]]))
        u[i] = acc
    return u


class ParamSplineSpec(ParamSpec):
    """`ParamSpec` (``set(theta)``, ``step(tick, X) -> U`` for `paths` instances, ticks in
    order from 0, float32 bit for bit) of ``stsp_param_step`` with a spline table and its
    spline columns: the latch as for a per-tick table, the command `command`, the clamp."""

    def __init__(self, table, cols: SplineColumns, nominal, paths: int = 1):
        self.t, self.spline_cols = table, cols
        self.Lambda = np.asarray(table.Lambda, f32)
        self.lambda0 = np.asarray(table.lambda0, f32)
        self.u_min, self.u_max = (np.asarray(a, f32) for a in (table.u_min, table.u_max))
        self.cols = {"nominal": np.asarray(nominal, f32),
                     "S_lambda0": np.asarray(cols.S_lambda0, f32)}
        self.d = np.zeros(self.cols["nominal"].size, f32)
        self.v = np.zeros((paths, table.dims[2]), f32)

    def _command(self, j: int, X: np.ndarray) -> np.ndarray:
        U = np.stack([command(self.t, self.spline_cols, j, x, v, self.d)
                      for x, v in zip(X, self.v)])
        return np.minimum(np.maximum(U, self.u_min), self.u_max)
