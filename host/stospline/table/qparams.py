"""Fixed-point (Q15/Q31) scaling of the sensitivity columns and its error bound over the whole
parameter box: the host side of a fixed-point parametric table (the firmware's Q15/Q31
``stsp_param_step``, stsp_params.h; its C: `stospline.table.parametric_c.generate_parametric_qc`).

The parameters enter the law as ``k0 + S_k0 d`` and ``lambda0 + S_lambda0 d``, ``d = theta -
nominal``: exactly as ``P`` more states with constant gains. So the columns are scaled as
states of the fixed-point law (`stospline.table.qformat`, whose notation this follows)::

    d[p] = d_q[p] 2^(d_exp[p] - F),   d_q[p] = rhu(d[p] 2^(F - d_exp[p]))   (once, at set)

(``d = theta - nominal`` in binary64, as the firmware computes it: `ParametricFixedPoint.d_q`
is its arithmetic bit for bit),
    S_k0_q[t][i][p]     = rhu(-S_k0_ip(t) 2^(d_exp[p] - u_exp[i] + F))     (stored negated)
    S_lambda0_q[s][c][p] = rhu(S_lambda0_cp 2^(d_exp[p] - v_exp[c] + F))

with ``d_exp[p]`` the smallest exponent with ``|d_q[p]| <= 2^F - 1`` over the whole range
(``reach_p = max(upper_p - nominal_p, nominal_p - lower_p)``). `quantize_parametric` quantizes
the augmented table (``K`` and ``Lambda`` with the columns appended, the state range with the
reaches appended), so ``u_exp`` and ``v_exp`` are chosen with the columns' terms in every row
sum: for every ``theta`` in the box and every state in the range no sum overflows and no
command leaves the Q range. The state range must hold over the box too (the means move with
``theta``): `stospline.oracle.over_box.box_state_range` gives it.

Error bound over the box, per tick and input, in the command's LSB: the augmented table's bound
(`qformat`: the rounding of every stored entry, the columns' included, and of the latch) plus
the rounding of ``d`` itself, at most ``e_d = 1/2 + 2^(F-52)`` of its LSB (half, and the binary64
subtraction's and the ``+ 1/2``'s roundings, each at most ``2^(F-53)`` as ``|d_q| < 2^F``)::

    bound + sum_p |S_k0s_p| e_d / 2^F + sum_c |L~_c| / 2^F * sum_p |S_lambda0s_cp| e_d / 2^F

(``S_k0s``, ``S_lambda0s`` the scaled entries before rounding). It holds for every ``theta`` in
the box and every state in the range against the double law at that ``theta``
(`law_double_at`); the commands are `qformat.law_q` of the augmented table with the state
``[x_q; d_q]``.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from stospline.problem.parameters import check_theta
from stospline.table.format import GainTable
from stospline.table.parametric import ParametricTable
from stospline.table.qformat import (FRAC_BITS, FixedPointTable, _rhu, latch_q, law_q,
                                     quantize_table, scaled_entries)

__all__ = ["ParametricFixedPoint", "FlashedParametric", "quantize_parametric", "augmented",
           "with_deviation_bound", "law_double_at", "QParamSpec"]


@dataclass
class ParametricFixedPoint:
    """The fixed-point table of the law over ``[x; d]`` (`augmented`: its K and Lambda hold the
    columns as their last ``P`` columns), the nominal and ranges, and the bound over the box
    (``bound_lsb``: (ticks, m), command LSBs)."""
    augmented: FixedPointTable
    nominal: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    bound_lsb: np.ndarray

    @property
    def n(self) -> int:
        return self.augmented.dims[0] - self.nominal.size

    @property
    def d_exp(self) -> np.ndarray:
        return self.augmented.x_exp[self.n:].astype(int)

    @property
    def bound(self) -> np.ndarray:
        return self.bound_lsb * self.augmented.u_lsb

    def d_q(self, theta) -> np.ndarray:
        """The integer parameter deviation the device would store for `theta` ((N, P))."""
        F = self.augmented.frac_bits
        d = np.atleast_2d(np.asarray(theta, float)) - self.nominal
        return _rhu(d * np.ldexp(1.0, F - self.d_exp))

    @property
    def S_k0(self) -> np.ndarray:
        """The stored columns of the feed-forward (ticks, m, P): negated, pre-scaled."""
        return self.augmented.K[..., self.n:]

    @property
    def S_lambda0(self) -> np.ndarray:
        """The stored columns of the latch offsets (stages, n_latch, P): pre-scaled."""
        return self.augmented.Lambda[..., self.n:]

    def gain_table(self, name: str | None = None) -> FixedPointTable:
        """The gain table the firmware runs with these columns: the augmented table's own
        ``n`` state columns and scales, with the bound over the box (``bound_lsb``)."""
        ft, n = self.augmented, self.n
        return replace(ft, name=name or ft.name, K=ft.K[..., :n], Lambda=ft.Lambda[..., :n],
                       x_exp=ft.x_exp[:n], x_range=np.asarray(ft.x_range)[:n],
                       bound_lsb=self.bound_lsb)

    def as_flashed(self, ptable) -> "FlashedParametric":
        """The law the device runs, in real units: `ptable` (the `ParametricTable` quantized
        here) with its gains, offsets and columns replaced by the stored integers times their
        scales (exact in float64, `stospline.table.spline.fixed_point.dequantized`). Its
        ``at(theta)`` applies the columns at ``theta`` itself (affine in it: the oracle over
        the box reads this); ``at(theta, quantize=True)`` at the deviation the device stores,
        ``d_q`` of ``theta`` in binary32 (`QParamSpec.set`). Left out, for the error bound: the
        rounding of the state to its Q format and of the command's sum."""
        from stospline.table.spline.fixed_point import dequantized
        real, n = dequantized(self.augmented), self.n
        table = replace(ptable.table, K=real.K[..., :n], k0=real.k0, L=real.L,
                        Lambda=real.Lambda[..., :n], lambda0=real.lambda0)
        return FlashedParametric(table, real.K[..., n:], real.Lambda[..., n:],
                                 tuple(ptable.parameters), self)

    def command_error_bound(self, ptable) -> np.ndarray:
        """The bound (ticks, m), real units, on the device's command against the double law
        of `ptable` at the same ``theta`` and the *real* state: `bound` (the table's, at the
        state as the device reads it) plus the state's rounding to its Q format, half an LSB
        per component, through ``K`` and, latched, through ``L Lambda``. For states within
        the range (no saturation) and commands within the limits."""
        t = ptable.table
        half = self.augmented.x_lsb[:self.n] / 2
        K, L, Lam = (np.abs(np.asarray(a, float)) for a in (t.K, t.L, t.Lambda))
        ls = self.augmented.latch_stage(self.augmented.stage_of_tick(np.arange(t.n_ticks)))
        latch = np.where((ls >= 0)[:, None], (Lam @ half)[np.maximum(ls, 0)], 0.0)
        return self.bound + K @ half + np.einsum("tic,tc->ti", L, latch)

    def column_bytes(self) -> int:
        """Flash of the columns (S_k0, S_lambda0), of nominal, lower, upper (binary64) and of
        d_exp in this format."""
        width = 2 if self.augmented.arith == "q15" else 4
        P = self.nominal.size
        T, m, _ = self.augmented.K.shape
        S, c, _ = self.augmented.Lambda.shape
        return width * (T * m * P + S * c * P) + 8 * 3 * P + P


@dataclass(frozen=True)
class FlashedParametric(ParametricTable):
    """`ParametricFixedPoint.as_flashed`: a `ParametricTable` of the stored integers in real
    units; ``at(theta, quantize=True)`` rounds the deviation as the device does."""
    fixed: ParametricFixedPoint = None

    def at(self, theta, *, quantize: bool = False) -> GainTable:
        d = check_theta(self.parameters, theta) - self.nominal
        if quantize:
            pf = self.fixed
            dq = pf.d_q(np.asarray(np.asarray(theta, np.float32), float))[0]
            d = dq * np.ldexp(1.0, pf.d_exp - pf.augmented.frac_bits)
        return replace(self.table, k0=self.table.k0 + self.S_k0 @ d,
                       lambda0=self.table.lambda0 + self.S_lambda0 @ d)


def quantize_parametric(ptable, arith: str, x_range) -> ParametricFixedPoint:
    """Q15/Q31 scales, integer entries and error bound over the box of the parametric table
    `ptable` (`stospline.table.parametric.ParametricTable`, double precision), for states
    within `x_range` ((n,): magnitudes over the whole box). Raises ValueError as
    `qformat.quantize_table`."""
    aug, x_aug = augmented(ptable, arith, x_range)
    ft = quantize_table(aug, arith, x_aug, name=f"{ptable.table.name}_params_{arith}")
    return with_deviation_bound(ptable, aug, ft)


def augmented(ptable, arith: str, x_range):
    """``(aug, x_aug)``: the double law over ``[x; d]`` (``K`` and ``Lambda`` with the columns
    appended) and its state range (`x_range`, then the parameters' reaches with room for the
    rounding of ``d_q``: ``|d_q| <= 2^F - 1``)."""
    if arith not in FRAC_BITS:
        raise ValueError(f"arith must be one of {list(FRAC_BITS)}, got {arith!r}")
    F = FRAC_BITS[arith]
    table = ptable.table
    nom = np.asarray(ptable.nominal, float)
    lower = np.array([q.lower for q in ptable.parameters], float)
    upper = np.array([q.upper for q in ptable.parameters], float)
    reach = np.maximum(upper - nom, nom - lower)
    # |d| <= reach < 2^d_exp strictly, with room for d_q's rounding: |d_q| <= 2^F - 1.
    d_range = np.where(reach > 0, reach, 1.0) * (1.0 + 2.0 ** (2 - F))
    aug = replace(table, K=np.concatenate([np.asarray(table.K, float), ptable.S_k0], axis=2),
                  Lambda=np.concatenate([np.asarray(table.Lambda, float), ptable.S_lambda0],
                                        axis=2))
    return aug, np.concatenate([np.asarray(x_range, float).reshape(-1), d_range])


def with_deviation_bound(ptable, aug, ft: FixedPointTable) -> ParametricFixedPoint:
    """The `ParametricFixedPoint` of `ft`, the fixed-point table of the augmented law `aug`
    (`augmented`; its integer entries, per tick or a spline's as evaluated), with the rounding
    of ``d`` added to its bound (the module docstring)."""
    table = ptable.table
    F = ft.frac_bits
    nom = np.asarray(ptable.nominal, float)
    lower = np.array([q.lower for q in ptable.parameters], float)
    upper = np.array([q.upper for q in ptable.parameters], float)
    n = table.dims[0]
    Ks, _, Ls, Lams, _ = scaled_entries(aug, F, ft.x_exp, ft.u_exp, ft.v_exp)
    e_d = (0.5 + 2.0 ** (F - 52)) / (1 << F)     # d_q's error, in the columns' units
    d_law = np.abs(Ks[..., n:]).sum(axis=2) * e_d                       # (T, m)
    d_latch = np.abs(Lams[..., n:]).sum(axis=2) * e_d                   # (S, n_latch)
    n_latch = table.dims[2]
    ls = ft.latch_stage(ft.stage_of_tick(np.arange(ft.n_ticks)))
    live = np.arange(n_latch)[None, :] < np.asarray(table.stage_n_latch)[np.maximum(ls, 0)][:, None]
    eps_t = np.where((ls >= 0)[:, None] & live, d_latch[np.maximum(ls, 0)], 0.0)
    bound = ft.bound_lsb + d_law + np.einsum("tic,tc->ti", np.abs(Ls), eps_t) / (1 << F)
    return ParametricFixedPoint(ft, nom, lower, upper, bound)


def law_double_at(ptable, tick, x, x_latch, theta) -> np.ndarray:
    """The parametric law in double precision at `theta` ((N, P)): ``u = -K x - k0' - L v``,
    ``v = lambda0' + Lambda x_latch`` at the tick's latch stage (rows beyond stage_n_latch
    zero), ``k0'``, ``lambda0'`` the columns at `theta` (N, m)."""
    t = ptable.table
    tick = np.asarray(tick)
    d = np.atleast_2d(np.asarray(theta, float)) - ptable.nominal
    latching = np.where(np.asarray(t.stage_n_latch) > 0, np.arange(t.n_stages), -1)
    stage = np.searchsorted(t.stage_start, tick, side="right") - 1
    ls = np.maximum.accumulate(latching)[stage]
    lsc = np.maximum(ls, 0)
    n_latch = t.dims[2]
    v = (np.asarray(t.lambda0, float)[lsc] + np.einsum("ncp,np->nc", ptable.S_lambda0[lsc], d)
         + np.einsum("ncj,nj->nc", np.asarray(t.Lambda, float)[lsc], x_latch))
    live = (ls >= 0)[:, None] & (np.arange(n_latch)[None, :]
                                 < np.asarray(t.stage_n_latch)[lsc][:, None])
    v = np.where(live, v, 0.0)
    return -(np.einsum("nij,nj->ni", np.asarray(t.K, float)[tick], x)
             + np.asarray(t.k0, float)[tick] + np.einsum("nip,np->ni", ptable.S_k0[tick], d)
             + np.einsum("nic,nc->ni", np.asarray(t.L, float)[tick], v))


class QParamSpec:
    """The firmware's fixed-point ``stsp_set_params`` and ``stsp_param_step`` (stsp_params.h)
    bit for bit, batched over paths: ``set(theta)`` (binary32 values, the range the C's) and
    ``step(tick, Xq) -> Uq`` (integer states (paths, n), commands clamped to the limits);
    ticks in order from 0. The latch at a stage start uses the d_q in force then, and is kept
    until the next latch."""

    def __init__(self, pf: ParametricFixedPoint, paths: int):
        self.pf, self.ft = pf, pf.augmented
        self.dq = np.zeros((paths, pf.nominal.size), np.int64)
        self.V = np.zeros((paths, self.ft.dims[2]), np.int64)

    def set(self, theta) -> None:
        theta = np.asarray(np.asarray(theta, np.float32), float)
        self.dq = np.broadcast_to(self.pf.d_q(theta), self.dq.shape).copy()

    def step(self, j: int, Xq) -> np.ndarray:
        ft = self.ft
        Z = np.hstack([np.asarray(Xq, np.int64), self.dq])
        k = int(ft.stage_of_tick(j))
        if j == int(ft.stage_start[k]) and (k == 0 or ft.stage_n_latch[k] > 0):
            self.V = latch_q(ft, np.full(len(Z), k), Z)
        U = law_q(ft, np.full(len(Z), j), Z, self.V)
        return np.clip(U, ft.u_min, ft.u_max)
