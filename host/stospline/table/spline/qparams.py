"""Fixed-point (Q15/Q31) spline columns of a parametric table: the sensitivity columns of the
feed-forward as integer cubic B-splines on a Q spline gain table's spans (format 2 of the
parameter table in a Q15/Q31 build, ``stsp_param_step`` with a Q spline gain table).

The fixed-point parametric table (`stospline.table.qparams`) treats the parameters as ``P``
more states of the law, ``d_q`` their integer deviations, with constant columns of gains per
tick. Here those columns are, like the gains of a Q spline table
(`stospline.table.spline.fixed_point`), uniform cubic B-splines with integer coefficients, on
the same spans (the gain spline's ``span_log2[s]`` per stage, so one basis ``P_0..P_3`` serves
both) and in the same scales: those of the augmented law over ``[x; d]``
(`stospline.table.qparams.augmented`), which cover the whole box. Per stage ``s``, input ``i``
and parameter ``p`` one block of ``S_s + 4`` words of the table's scalar::

    block[0]          the column's coefficient scale s (1 <= s <= 30)
    block[1 + r]      its S_s + 3 coefficients, r = 0 .. S_s + 2

at ``nu P (sum_{s' < s} (S_{s'} + 4)) + (i P + p)(S_s + 4)`` of the table's ``S_k0``
(``n_spline_coef`` words in all). At tick ``tau`` of stage ``s`` the column's gain is the exact
``g = floor((sum_r c[sigma + r] P_r) / 2^(3k + s) + 1/2)`` of `fixed_point.basis_numerators`
(negated and pre-scaled as a per-tick Q column: `qparams`), and the command is the per-tick Q
law over ``[x_q; d_q]`` with these gains, one rounding
(``u_q = k0 + floor((sum K x_q + sum_p g_p d_q + sum L v_q) / 2^F + 1/2)``, the gains of
``x``, ``k0`` and ``L`` the gain spline's): `stospline.table.qformat.law_q` of
`ParametricFixedPoint.augmented`, whose integer gains are the splines as evaluated.

Error bound over the box: `qformat.assemble`'s bound of the augmented table with every entry's
actual error (the fit's included, gains and columns), plus the rounding of ``d``
(`qparams.with_deviation_bound`). The latch maps and their columns are the per-tick Q
table's (not re-solved for the spline's gains, as a float32 spline table's are): the
constraints then hold up to what the error bound and the oracle of the table as flashed say.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stospline.errors import DesignError
from stospline.firmware_interface import FRAC_BITS
from stospline.table import qformat
from stospline.table.qformat import EXP_MAX, assemble, row_sums, scale_exponents, scaled_entries
from stospline.table.qparams import ParametricFixedPoint, augmented, with_deviation_bound
from stospline.table.spline.fixed_point import (COEF_BITS, FIELD, _fit_q, _fit_uniform,
                                                _stage_gains)

__all__ = ["QSplineColumns", "quantize_spline_parametric", "column_starts", "spline_gain_table",
           "column_flash_bytes"]


@dataclass(frozen=True)
class QSplineColumns:
    """The integer blocks of the module docstring (``coef``: int16 for Q15, int32 for Q31),
    with each column's largest fit error in LSB of its scaled value (``error``: (nu, P))
    relative to its peak (``relative``)."""
    coef: np.ndarray
    error: np.ndarray
    relative: np.ndarray

    @property
    def nbytes(self) -> int:
        return int(self.coef.nbytes)


def column_starts(gains, stage_start, P: int) -> np.ndarray:
    """The first word of each stage's blocks, then their number (n_stages + 1)."""
    start = np.asarray(stage_start, np.int64)
    widths = [gains.spans(s, int(start[s + 1] - start[s])) + 4 for s in range(gains.n_stages)]
    return np.concatenate([[0], np.cumsum(gains.nu * P * np.asarray(widths, np.int64))])


def _fit_columns(Ys: np.ndarray, gains, stage_start, arith: str):
    """``(coef, G, error, relative)``: the blocks of the scaled, negated columns `Ys` (ticks,
    nu, P, LSB) on `gains`' spans, their evaluation G (ticks, nu, P, int64) and errors."""
    start = np.asarray(stage_start, np.int64)
    T, m, P = Ys.shape
    offs = column_starts(gains, start, P)
    dtype = np.int16 if arith == "q15" else np.int32
    coef = np.zeros(int(offs[-1]), np.int64)
    G = np.zeros((T, m, P), np.int64)
    for s in range(gains.n_stages):
        a, b = int(start[s]), int(start[s + 1])
        k = int(gains.span_log2[s])
        YT = np.ascontiguousarray(Ys[a:b].reshape(b - a, m * P).T)
        peak = np.abs(YT).max(axis=1, initial=0.0)
        with np.errstate(over="ignore"):      # a zero column: the largest scale
            fit = _fit_uniform(YT, k, COEF_BITS[arith], peak, {})
        if fit is None:
            raise DesignError(FIELD, f"stage {s}: a parameter column's fixed-point spline "
                                     f"exceeds the integer format on the gains' spans")
        C, shift = fit
        G[a:b] = _stage_gains(k, C, shift, b - a).reshape(b - a, m, P)
        coef[offs[s]:offs[s + 1]] = np.column_stack([shift, C]).ravel()
    err = np.abs(G - Ys).max(axis=0, initial=0.0)
    peak = np.abs(Ys).max(axis=0, initial=0.0)
    rel = err / np.where(peak > 0, peak, 1.0)
    return coef.astype(dtype), G, err, rel


def quantize_spline_parametric(ptable, arith: str, x_range, tolerance: float, *,
                               max_spans: int = 1024):
    """``(pf, gains, cols)``: the Q15/Q31 spline parametric controller of the parametric table
    `ptable` (double precision) for states within `x_range` over the box: its augmented
    fixed-point law `pf` (`qparams.ParametricFixedPoint`, whose integer gains are the splines
    as evaluated and whose bound covers the box), the gain spline `gains`
    (`fixed_point.QSplineGains`, fitted at `tolerance` as `fixed_point.fit_q_spline`) and the
    columns `cols` (`QSplineColumns`). Raises DesignError (``design.spline_tolerance``, or
    ``design.table`` when no scale keeps the row sums within the format) and ValueError as
    `qformat.quantize_table`."""
    aug, x_aug = augmented(ptable, arith, x_range)
    F = FRAC_BITS[arith]
    qmax = (1 << F) - 1
    n = ptable.table.dims[0]
    start = np.asarray(aug.stage_start, np.int64)
    x_exp, u_exp, v_exp = (np.asarray(e, int).copy() for e in scale_exponents(aug, arith, x_aug))
    for _ in range(8):
        scaled = scaled_entries(aug, F, x_exp, u_exp, v_exp)
        gains, Kq, k0q, Lq = _fit_q((scaled[0][..., :n], scaled[1], scaled[2]), start, arith,
                                    tolerance, max_spans)
        coef, G, err, rel = _fit_columns(scaled[0][..., n:], gains, start, arith)
        q = (np.concatenate([Kq, G], axis=2), k0q, Lq, qformat._rhu(scaled[3]),
             qformat._rhu(scaled[4]))
        law_rows, latch_rows = row_sums(*q)
        over_u = law_rows.max(axis=0, initial=0) > qmax
        over_v = (latch_rows.max(axis=0, initial=0) > qmax if latch_rows.size
                  else np.zeros(v_exp.size, bool))
        if not over_u.any() and not over_v.any():
            break
        # A row the splines pushed past 2^F - 1: one more bit for that input or multiplier.
        u_exp, v_exp = u_exp + over_u, v_exp + over_v
        if max(np.abs(u_exp).max(initial=0), np.abs(v_exp).max(initial=0)) > EXP_MAX:
            break
    else:
        over_u = np.ones(1, bool)
    if over_u.any() or over_v.any():
        raise DesignError("design.table", f"the {arith} spline columns' rows exceed the "
                                          f"format's row sums whatever the scales")
    ft = assemble(aug, arith, x_aug, (x_exp, u_exp, v_exp), q, scaled,
                  name=f"{ptable.table.name}_params_{arith}_spline")
    pf = with_deviation_bound(ptable, aug, ft)
    return pf, gains, QSplineColumns(coef, err, rel)


def spline_gain_table(pf: ParametricFixedPoint, gains, name: str):
    """The Q spline gain table the firmware runs with the columns: `pf`'s gain table
    (`ParametricFixedPoint.gain_table`) with `gains` as its spline."""
    ft = pf.gain_table(name)
    object.__setattr__(ft, "spline", gains)
    return ft


def column_flash_bytes(pf: ParametricFixedPoint, cols: QSplineColumns) -> int:
    """Flash of the spline columns' arrays (``<name>_<arith>_spline_params.c``): the blocks,
    ``S_lambda0`` in the table's scalar, nominal, lower and upper (float64) and the scale
    exponents (int8)."""
    P = pf.nominal.size
    width = 2 if pf.augmented.arith == "q15" else 4
    return cols.nbytes + width * pf.S_lambda0.size + 8 * 3 * P + P
