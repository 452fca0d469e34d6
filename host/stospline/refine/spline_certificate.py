"""A spline table for a design, and its certificate: what the law exactly as the firmware
evaluates it (B-spline gains in binary32, re-solved latch maps, held per tick) costs against
the uncompressed optimum, how well it meets the expected constraints, and the flash it saves.

The table's K, k0 and L are the spline's evaluation tick by tick, bit for bit as the firmware
computes them (`stospline.table.spline.fit.evaluate`), so the exact moment oracle, the fault
oracle and the Monte Carlo harness (which compiles the spline itself) all see the law the
firmware runs."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from stospline.problem.model import Problem
from stospline.oracle.tick_moments import Moments
from stospline.table.flash import flash_bytes, spline_bytes
from stospline.table.format import GainTable

__all__ = ["certificate", "q_certificate", "constraint_residual", "band_terms",
           "first_latch_in_float32"]


def constraint_residual(problem: Problem, moments: Moments) -> float:
    """Largest |E{C2 x} - value| of an equality row, or distance of E{C2 x} outside its band,
    over the constrained knots (0 without constraints), and over every row of every tick
    region at each of its ticks when `moments` carries the mean path (``path=True``; t0, the
    start's, excluded)."""
    worst = 0.0
    if problem.tick_regions and moments.path_mean.shape[0] > 1:
        for reg in problem.tick_regions:
            j = reg.ticks(problem.t0, problem.tick_hz)
            y = moments.path_mean[j[j > 0]] @ reg.C.T
            worst = max(worst, float(np.max(np.maximum(y - reg.upper, reg.lower - y),
                                            initial=0.0)))
    for k, kn in enumerate(problem.knots):
        if kn.constraint is not None:
            lo, hi = kn.constraint.bounds
            y = np.asarray(moments.knot_constraint[k], dtype=float)
            r = np.where(lo == hi, np.abs(y - lo), np.maximum(np.maximum(y - hi, lo - y), 0.0))
            worst = max(worst, float(np.max(r, initial=0.0)))
    return worst


def first_latch_in_float32(problem: Problem, table: GainTable) -> GainTable:
    """`table` with its t0 latch as the firmware computes it from the design's start: the
    oracle takes ``v = lambda0 + Lambda x0`` exactly (float64 of the stored values), the
    firmware ``acc = lambda0; acc += Lambda_j x0_j`` in binary32, one rounding per
    operation (`stsp_latch_row`), so its v is a float32 vector. The copy's ``lambda0[0]``
    (float64) is ``v_32 - Lambda[0] x0``, so that the oracle of the copy latches exactly
    ``v_32`` at x0 (the law's state: with a delay ``[x0; u_hold]``); its residual is what
    the firmware's t0 latch leaves, at x0 only. Not for band tables (their t0 latch solves
    the band dual): ValueError."""
    from stospline.table.spline.latch import start_state
    if table.band_qp is not None:
        raise ValueError("a band table's t0 latch is its band dual, not Lambda x + lambda0")
    x = start_state(problem, table).astype(np.float32)
    Lam = np.asarray(table.Lambda[0], dtype=np.float32)
    acc = np.asarray(table.lambda0[0], dtype=np.float32).copy()
    for j in range(x.size):
        acc = (acc + (Lam[:, j] * x[j]).astype(np.float32)).astype(np.float32)
    lam0 = np.array(table.lambda0, dtype=float)
    lam0[0] = acc.astype(float) - Lam.astype(float) @ x.astype(float)
    return replace(table, Lambda=np.array(table.Lambda, dtype=float), lambda0=lam0)


def band_terms(table: GainTable, per_tick: GainTable) -> dict:
    """A spline band table's dual against the per-tick table's: rows, how far W' is from
    symmetric and from the design's W (largest entry difference over W's largest entry), and
    its P-matrix margin (`stospline.table.spline.band.is_p_matrix`)."""
    from stospline.table.spline.band import is_p_matrix
    W, W0 = table.band_qp.W, per_tick.band_qp.W
    scale = float(np.abs(W0).max())
    return {"rows": table.band_qp.q,
            "w_asymmetry": float(np.abs(W - W.T).max()) / scale,
            "w_change": float(np.abs(W - W0).max()) / scale,
            "p_margin": is_p_matrix(W)[2]}


def _cov_change(reference: Moments, implemented: Moments) -> float:
    """Largest change of a knot covariance, relative to its norm (Frobenius), to 2
    significant digits: a difference of two nearly equal covariances, it keeps few of the
    design's digits (investment's, 5.6e-8, moves by 7.5e-12 between the compiled and the
    numpy tick loop of the designer), and the summary must not print the rest."""
    worst = 0.0
    for a, b in zip(reference.knot_cov, implemented.knot_cov):
        scale = float(np.linalg.norm(a))
        if scale > 0:
            worst = max(worst, float(np.linalg.norm(b - a)) / scale)
    return float(f"{worst:.2g}")


def certificate(problem: Problem, table: GainTable, per_tick: GainTable, J0: float,
                compressed: Moments, implemented: Moments, *, tolerance: float) -> dict:
    """The spline table's certificate (the summary's ``table``): its oracle cost
    (`implemented`) and excess over the designed optimum ``J0`` and over the per-tick law the
    spline compresses in double precision (`compressed`: the oracle of
    ``table_of(design, quantize=False)``, which for a continuous-time design is its gains
    sampled at the ticks, not the continuous law, whose difference is the cost of sampling),
    the worst expected-constraint residual (for a band, the distance outside it), the knot
    covariances' change against the same
    per-tick law, the flash and the compression ratio against the per-tick float32 table, the
    spans per stage."""
    sp = table.spline
    total, per_tick_total = flash_bytes(table), flash_bytes(per_tick)
    J = compressed.J
    return {
        "kind": "spline",
        "spline_tolerance": tolerance,
        "spans": [int(sp.spans(s)) for s in range(table.n_stages)],
        "entries": int(sp.col.size),
        "oracle_J": implemented.J,
        "excess_over_J0": (implemented.J - J0) / abs(J0) if J0 else implemented.J - J0,
        "excess_over_law": (implemented.J - J) / abs(J) if J else implemented.J,
        "constraint_residual": constraint_residual(problem, implemented),
        "knot_cov_change": _cov_change(compressed, implemented),
        "flash_bytes": total,
        "gain_bytes": spline_bytes(sp),
        "per_tick_flash_bytes": per_tick_total,
        "compression_ratio": per_tick_total / total,
        **({"band_dual": band_terms(table, per_tick)} if table.band_qp is not None else {}),
        **({"restored": {"rows": table.restored["rows"], "active": table.restored["active"],
                         "rounds": table.restored["rounds"]}}
           if getattr(table, "restored", None) is not None else {}),
    }


def q_certificate(problem: Problem, ft, per_tick, J0: float, law: Moments,
                  implemented: Moments, per_tick_moments: Moments, *, tolerance: float) -> dict:
    """The certificate of a fixed-point spline table `ft` (`stospline.table.spline.fixed_point`): the
    exact oracle's cost of its law as the firmware evaluates it (`implemented`: the gains the
    integer splines give at every tick and the re-solved latch maps, both as stored, in real
    units; the command's final rounding is the error bound's), its excess over ``J0``, over
    the design's per-tick law in double precision (`law`) and over the per-tick table of the
    same arithmetic (`per_tick`, whose oracle is `per_tick_moments`), the worst
    expected-constraint residual of both, the error bound of both (``|u_fixed - u_double|``
    per input in the command's LSBs, as written), the flash of both and the ratio."""
    from stospline.table.flash import flash_bytes as _flash
    from stospline.table.spline.fixed_point import q_spline_bytes
    sp = ft.spline
    total, per_tick_total = _flash(ft, ft.arith), _flash(per_tick, per_tick.arith)
    start = np.asarray(ft.stage_start, dtype=np.int64)

    def rel(a, b):
        return (a - b) / abs(b) if b else a - b
    return {
        "kind": "spline",
        "arith": ft.arith,
        "spline_tolerance": tolerance,
        "span_ticks": [1 << int(k) for k in sp.span_log2],
        "spans": [int(sp.spans(s, start[s + 1] - start[s])) for s in range(sp.n_stages)],
        "entries": int(sp.n_entries),
        "oracle_J": implemented.J,
        "excess_over_J0": rel(implemented.J, J0),
        "excess_over_law": rel(implemented.J, law.J),
        "excess_over_per_tick": rel(implemented.J, per_tick_moments.J),
        "per_tick_oracle_J": per_tick_moments.J,
        "constraint_residual": constraint_residual(problem, implemented),
        "per_tick_constraint_residual": constraint_residual(problem, per_tick_moments),
        "knot_cov_change": _cov_change(law, implemented),
        "u_error_bound_lsb": ft.written_bound_lsb(),
        "per_tick_u_error_bound_lsb": per_tick.written_bound_lsb(),
        "u_error_bound": ft.written_bound(),
        "flash_bytes": total,
        "gain_bytes": q_spline_bytes(sp),
        "per_tick_flash_bytes": per_tick_total,
        "compression_ratio": per_tick_total / total,
    }
