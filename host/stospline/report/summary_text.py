"""The human summaries `stospline design` and `stospline simulate` print (``--json`` prints
the full ones)."""
from __future__ import annotations

import numpy as np

from stospline.table.flash import ARITH_ELEMENT_BYTES, flash_bytes

__all__ = ["worst_constraint_residual", "design_summary_text", "design_run_text",
           "simulation_summary_text", "saturation_warning"]


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


def design_run_text(d, arith: str, summary: dict) -> str:
    """What ``stospline design`` prints for `d` written in `arith`, whose JSON summary is
    `summary` (`stospline.pipeline.design_files`): a Q15/Q31 spline table's certificate is
    there, under ``table``; a Q spline table with parameter columns under ``fixed.spline``; a
    filter's gain spline under ``estimator.gain_spline``."""
    text = design_summary_text(d, arith, None if arith == "float32" else summary.get("table"))
    q = summary.get("fixed", {}).get("spline")
    if q is not None:                           # a Q spline table with parameter columns
        text += (f"  {arith + ' spline + columns':<31}{q['gain_bytes']:,} B + "
                 f"{q['column_bytes']:,} B; spans of {q['span_ticks']} ticks, tolerance "
                 f"{q['spline_tolerance']:g}\n")
    g = summary.get("estimator", {}).get("gain_spline")
    if g is not None:
        text += (f"  filter gains as a spline       {g['gain_bytes']:,} B, "
                 f"{g['per_tick_gain_bytes'] / g['gain_bytes']:.3g}x smaller than per sample "
                 f"({g['per_tick_gain_bytes']:,} B); spans per stage {g['spans']}\n"
                 f"  loop on the estimate, J        {g['oracle_J']:.10g}   (estimator oracle, "
                 f"gains as flashed; {g['J_change']:+.3g} relative to the per-sample gains', "
                 f"knot covariances within {g['knot_cov_change']:.2g})\n")
    return text


def simulation_summary_text(s: dict) -> str:
    """What ``stospline simulate`` prints: the cost and knot means of Monte Carlo beside the
    oracle's, the plant scheme's bias, faults, saturation, corridors and the verdict, from
    the run's summary (`stospline.report.simulation_summary.simulation_summary`)."""
    lines = []
    sat = s["saturation"]
    c = s["cost"]
    lines.append(f"{s['name']}: {s['paths']} paths, seed {s['seed']}, compiled C controller at "
                 f"{s['tick_hz']} Hz, plant {s['substeps']} substeps/tick, from x0 = {s['x0']}")
    lines.append(f"  cost  MC {c['mc_mean']:.6g}  95% CI [{c['ci95'][0]:.6g}, {c['ci95'][1]:.6g}]"
                 f"   oracle {c['oracle_implemented']:.6g}   predicted J0 {c['predicted_J0']:.6g}"
                 f"   z {_z_text(c['z'])}")
    bias = s["simulation_bias"]
    ratio = ("n/a MC standard errors (all paths alike)" if bias["cost_over_stderr"] is None
             else f"{bias['cost_over_stderr']:.3g} MC standard errors")
    how = ""
    if bias["substeps_chosen"] == "auto":
        how = (f"; {s['substeps']} substeps/tick chosen: the fewest with |bias| <= "
               f"{bias['target']:.3g}, under 0.1 of the standard error a "
               f"{bias['pilot_paths']}-path pilot predicts"
               + ("" if bias["target_met"] else " (NOT met at the largest allowed number)"))
    lines.append(f"  plant-scheme bias in cost {bias['cost']:.3g} = {ratio}{how}")
    f = s.get("faults", {})
    if f.get("levels"):
        levels = " ".join(f"{k}={v}" for k, v in f["levels"].items())
        oracle = (f"exact oracle of the faulty loop {f['oracle_cost']:.6g}" if f["exact_oracle"]
                  else "no exact oracle (quantization, missed ticks, or sensor noise before "
                       "the band latch): Monte Carlo only")
        lines.append(f"  faults: {levels}; {oracle} (fault-free {f['nominal_cost']:.6g})")
    if sat["limited"]:
        lines.append(f"  actuator limits: saturated on {100 * sat['tick_fraction']:.4g}% of ticks "
                     f"({100 * sat['path_fraction']:.4g}% of paths); commands issued within "
                     f"[{', '.join(_number_text(v) for v in sat['u_low'])}] .. "
                     f"[{', '.join(_number_text(v) for v in sat['u_high'])}]")
    for i, c in enumerate(s.get("corridors", [])):
        mc = c["mc"]
        eps = "" if c["epsilon"] is None else f", epsilon {c['epsilon']:g}"
        bounds = "no oracle bounds (a table designed for a delay)"
        if c["bound"] is not None:
            bc, bg = c["bound"]["cantelli"], c["bound"]["gaussian"]
            bounds = (f"oracle union bounds over the ticks: Cantelli {bc['total']:.4g} (valid), "
                      f"Gaussian {bg['total']:.4g} (assumes Gaussian outputs); worst tick "
                      f"{bc['worst_tick']:.3g} / {bg['worst_tick']:.3g}")
        lines.append(f"  corridor {i} (t = [{c['t'][0]:g}, {c['t'][1]:g}]{eps}): left by "
                     f"{mc['exits']} of {mc['paths']} paths = {100 * mc['estimate']:.4g}%, "
                     f"one-sided 99% upper bound {100 * mc['upper99']:.4g}%; {bounds}")
    fmt = lambda v: "[" + ", ".join(f"{x:+.5f}" for x in v) + "]"  # noqa: E731
    for k, kn in enumerate(s["knots"]):
        lines.append(f"  knot {k} (t = {kn['t']:g}): state mean, MC     {fmt(kn['mc_mean'])}")
        lines.append(f"  {'':>15}state mean, oracle {fmt(kn['oracle_mean'])}   "
                     f"z {'[' + ', '.join(_z_text(z) for z in kn['z']) + ']'}")
    v = s["verdict"]
    lines.append(f"  verdict: {'agree' if v['agree'] else 'DISAGREE'}: max |z| "
                 f"{v['max_abs_z']:.3g} ({v['max_abs_z_of']}) against {v['z_limit']:.3g}, "
                 f"{v['correction']} over {v['statistics']} statistics at "
                 f"{100 * v['confidence']:g}% jointly, {v.get('standard_errors', 'sample')} "
                 f"standard errors; {v['reason']}")
    return "\n".join(lines) + "\n"


def _number_text(v) -> str:
    """A number, or "n/a" when it is undefined (JSON null)."""
    return "n/a" if v is None else f"{v:.6g}"


def _z_text(z) -> str:
    """A z-score, or "n/a" when it is undefined (zero standard error; JSON null)."""
    return "n/a" if z is None else f"{z:+.2f}"


def saturation_warning(s: dict) -> str | None:
    """The warning a run whose controller saturated deserves (None when it never did): the
    oracle's and the predicted numbers assume the law is never clipped."""
    sat = s["saturation"]
    if not sat["tick_fraction"] > 0:
        return None
    return (f"the controller saturated (STSP_WARN_SATURATED) on "
            f"{100 * sat['tick_fraction']:.4g}% of ticks, on {100 * sat['path_fraction']:.4g}% "
            f"of paths; the oracle and predicted numbers assume no saturation (the design "
            f"ignores the actuator limits), so they do not predict this run")
