"""The short human summary `stospline design` prints (``--json`` prints the full one)."""
from __future__ import annotations

import numpy as np

from stospline.table.flash import ARITH_ELEMENT_BYTES, flash_bytes

__all__ = ["worst_constraint_residual", "design_summary_text"]


def worst_constraint_residual(d) -> tuple[float, int, int] | None:
    """``(residual, knot, row)`` of the constraint row the float32 table, as the oracle
    evaluates it, misses most (distance outside a band; ``E{Cx} - value`` for an equality);
    None when no knot has a constraint."""
    worst = None
    for k, kn in enumerate(d.problem.knots):
        if kn.constraint is None:
            continue
        lo, hi = kn.constraint.bounds
        y = np.asarray(d.implemented.knot_constraint[k], dtype=float)
        r = np.where(lo == hi, y - lo, np.maximum(y - hi, 0) - np.maximum(lo - y, 0))
        i = int(np.argmax(np.abs(r)))
        if worst is None or abs(r[i]) > abs(worst[0]):
            worst = (float(r[i]), k, i)
    return worst


def design_summary_text(d, arith: str = "float32", q_cert: dict | None = None) -> str:
    """A few lines: J0, the oracle's cost of the implemented (float32) table, ticks, stages,
    the flash the tables take in each arithmetic, and the worst constraint residual; with
    `q_cert` (a Q15/Q31 spline table's certificate, `pipeline.fixed_point_spline`) its flash,
    cost, residual and error bound."""
    t, p = d.table, d.problem
    n, m, _ = t.dims
    delay = getattr(t, "delay_ticks", 0)
    cert = getattr(d, "certificate", None)
    kind = "spline" if cert is not None else "float32"
    states = (f"n = {p.n} states + {m} applied command{'s' * (m > 1)} (one-tick delay: the "
              f"controller is fed {n})" if delay else f"n = {n} states")
    lines = [f"{p.name}: {d.design.mode} {d.discretization} design"
             f"{'' if d.design.noise_aware else ' (noise ignored)'}, {states}, "
             f"m = {m} inputs",
             f"  J0 (designed)                  {d.design.J0:.10g}",
             f"  {'J of the ' + kind + ' table':<31}{d.implemented.J:.10g}   (exact moment oracle, "
             f"held per tick)",
             f"  ticks                          {t.n_ticks} at {t.tick_hz} Hz "
             f"({t.n_ticks / t.tick_hz:g} s), {t.n_stages} stage"
             f"{'' if t.n_stages == 1 else 's'}"]
    # Delayed designs and spline tables are float32 only: no fixed-point sizes.
    ariths = [a for a in ARITH_ELEMENT_BYTES if not (delay or cert) or a == "float32"]
    sizes = "   ".join(f"{a}{'*' if a == arith else ''} {flash_bytes(t, a):,} B"
                       for a in ariths)
    lines.append(f"  flash of the tables            {sizes}   (* this run's arithmetic)")
    if cert is not None:
        ratio = cert["compression_ratio"]
        # Short stages hardly compress, and a stage of a few ticks takes more as a spline.
        size = (f"{ratio:.0f}x smaller" if ratio >= 100 else f"{ratio:.3g}x smaller"
                if ratio >= 1 else f"{1 / ratio:.3g}x larger")
        lines.append(f"  spline table                   {size} than per-tick "
                     f"({cert['per_tick_flash_bytes']:,} B); spans per stage "
                     f"{cert['spans']}, tolerance {cert['spline_tolerance']:g}")
        lines.append(f"  its cost over J0               {cert['excess_over_J0']:+.3g} relative "
                     f"(oracle, as the firmware evaluates it)")
    if q_cert is not None:
        lines.append(f"  {q_cert['arith']} spline table               {q_cert['flash_bytes']:,} B, "
                     f"{q_cert['compression_ratio']:.0f}x smaller than the {q_cert['arith']} "
                     f"per-tick table ({q_cert['per_tick_flash_bytes']:,} B); spans of "
                     f"{q_cert['span_ticks']} ticks")
        lines.append(f"  its J (oracle, as evaluated)   {q_cert['oracle_J']:.10g}   "
                     f"({q_cert['excess_over_J0']:+.3g} relative to J0); worst constraint "
                     f"residual {q_cert['constraint_residual']:.3g}")
        lines.append(f"  its error bound |u - u_double| {q_cert['u_error_bound']} "
                     f"({q_cert['u_error_bound_lsb']} LSB)")
    worst = worst_constraint_residual(d)
    if worst is None:
        lines.append("  worst constraint residual      - (no constraints)")
    else:
        r, k, i = worst
        lines.append(f"  worst constraint residual      {r:.3g}   (knot {k}, row {i}; "
                     f"E{{Cx}} of the {kind} table, oracle)")
    et = getattr(d, "every_tick", None)
    if et is not None:
        ticks = len({j for j, _, _ in et.working_set})
        if et.method == "tick-qp":
            lines.append(f"  regions at every tick          met by the tick-grid QP, "
                         f"{len(et.working_set)} rows active at {ticks} ticks "
                         f"(--json: every_tick has each region checked by the oracle)")
        else:
            lines.append(f"  regions at every tick          met after {et.iterations} design"
                         f"{'s' * (et.iterations > 1)}, {len(et.working_set)} band rows added "
                         f"at {ticks} ticks "
                         f"(--json: every_tick has each region checked by the oracle)")
    return "\n".join(lines) + "\n"
