"""The machine-readable summary of a design (``stospline design --json``, ``<name>.json``).

``d`` is a `stospline.pipeline.Designed` throughout (not imported: the pipeline imports this)."""
from __future__ import annotations

import numpy as np

from stospline.design.bands import has_bands
from stospline.precision import verbatim
from stospline.report.json_numbers import cov_digits, rounded
from stospline.table.codegen import GENERATOR

__all__ = ["design_summary", "actuator_limits"]


def design_summary(d) -> dict:
    """Machine-readable summary: predicted J0 and per-knot predicted moments (and the
    actuator limits, when the problem sets them)."""
    p = d.problem
    knots = []
    for k, kn in enumerate(p.knots):
        entry = {
            "t": verbatim(kn.t),
            "mean": d.law.knot_mean[k],
            "cov": cov_digits(d.law.knot_cov[k], d.law.knot_mean[k]),
            "implemented_mean": d.implemented.knot_mean[k],
            "implemented_cov": cov_digits(d.implemented.knot_cov[k], d.implemented.knot_mean[k]),
        }
        if kn.constraint is not None:
            lo, hi = kn.constraint.bounds
            entry["constraint"] = {
                "lower": lo, "upper": hi,
                "design_violation": _violation(d.law.knot_constraint[k], lo, hi),
                "implemented_violation": _violation(d.implemented.knot_constraint[k], lo, hi),
            }
        knots.append(entry)
    return rounded({
        "name": p.name,
        "generator": GENERATOR,
        "problem_sha256": p.source_sha256,
        "design": f"{d.design.mode}-{d.discretization}"
                  + ("" if d.design.noise_aware else "-noise-ignoring"),
        "tick_hz": d.table.tick_hz,
        "n_ticks": d.table.n_ticks,
        "J0": d.design.J0,
        "oracle_J_design": d.law.J,
        "oracle_J_implemented": d.implemented.J,
        "knots": knots,
        **({"table": d.certificate} if d.certificate is not None else {}),
        **_band_terms(d),
        **actuator_limits(d),
        **_estimator(d),
        **_parameters(d),
    })


def _parameters(d) -> dict:
    """With [[parameters]]: each one's name, nominal and range, in the columns' order (the
    ``<name>_params.c`` index macros); ``{}`` otherwise (summaries stay unchanged)."""
    if not d.problem.parameters:
        return {}
    out = {"parameters": [{"name": q.name, "nominal": q.nominal, "lower": q.lower,
                           "upper": q.upper} for q in d.problem.parameters]}
    if getattr(d, "over_box", None) is not None:
        out["over_box"] = over_box_terms(d.problem, d.over_box)
    return out


def over_box_terms(problem, pd) -> dict:
    """What a design with bands and runtime parameters guarantees over the box: every band
    row's margins (nominal, worst case over the box, where and which parameter moves it most)
    and each corridor's Cantelli and Gaussian exit bounds at the nominal and over the box, over
    its ticks (``total``) and at its worst tick (`stospline.oracle.over_box`, `stospline.oracle.exit_bound.exit_bounds_over_box`)."""
    from stospline.oracle.exit_bound import exit_bounds, exit_bounds_over_box
    corridors = []
    for c in problem.corridors:
        nominal = exit_bounds(c, pd.box.mean @ c.C.T, c.C @ pd.box.cov @ c.C.T, problem.t0,
                              problem.tick_hz)
        box = exit_bounds_over_box(c, pd.box, problem.t0, problem.tick_hz)
        corridors.append({"epsilon": c.epsilon, "nominal": _bound_terms(nominal),
                          "over_box": _bound_terms(box)})
    return {"bands": [m.as_dict() for m in pd.margins], "corridors": corridors}


def fixed_over_box_terms(problem, cert: dict) -> dict:
    """`over_box_terms` of a Q15/Q31 parametric table as flashed, from its
    `stospline.oracle.fixed_point_margin.fixed_point_certificate`: every band row's margins
    and each corridor's exit bounds over the box, less the fixed-point error bound propagated
    to the mean (the spread the double table's)."""
    return {"bands": [m.as_dict() for m in cert["margins"]],
            "corridors": [{"epsilon": c.epsilon, "over_box": _bound_terms(b)}
                          for c, b in zip(problem.corridors, cert["corridors"])]}


def _bound_terms(bounds: dict) -> dict:
    """Each tail's exit bound over the corridor's ticks and at its worst tick."""
    return {k: {"total": b.total, "worst_tick": b.worst_tick} for k, b in bounds.items()}


def _estimator(d) -> dict:
    """With a [measurement] table: the loop on the filter's estimate (docs/theory/estimator.md),
    for a spline table with the filter as flashed (its gain spline); ``{}`` otherwise
    (summaries stay unchanged)."""
    if d.problem.measurement is None:
        return {}
    from stospline.estimator.summary import estimator_summary
    flashed = None
    if d.table.spline is not None:      # flashed with the filter's gain spline: that loop
        from stospline.harness.estimator_run import flashed_filter
        try:
            flashed = ("spline", *flashed_filter(d.problem, d.table)[1:])
        except ValueError:              # the loop cannot run: estimator_summary says why
            pass
    out = estimator_summary(d.problem, d.table, cov_digits, flashed=flashed)
    if d.table.spline is not None and "not_evaluated" not in out:   # the filter's spline
        from stospline.options import resolve_options
        options = d.options if d.options is not None else resolve_options(d.problem)
        out["gain_spline"] = _gain_spline_certificate(
            d.problem, d.table, options.spline_tolerance, cov_digits)
    return {"estimator": out}


def _gain_spline_certificate(problem, table, tolerance: float, cov_digits=cov_digits) -> dict:
    """The ``estimator.gain_spline`` entry of a spline design's summary: the filter's gains
    as a spline (`estimator.gain_spline`, fitted to `tolerance`) against the per-tick float32
    gains, both as flashed (with the flashed predictor): the loop's exact cost with each, the
    relative change, the largest relative change of a knot covariance (Frobenius, 2 digits),
    the spline's knot covariances, its spans per stage and its bytes against the per-tick
    gains'. Raises SplineBudgetError when the tolerance cannot be met."""
    from stospline.estimator.ctable import estimator_table
    from stospline.estimator.oracle import evaluate_estimator
    from stospline.refine.spline_certificate import _cov_change
    loop = evaluate_estimator(problem, table)
    per_tick = estimator_table(problem, table, loop)
    spline = estimator_table(problem, table, loop, spline_tolerance=tolerance)
    ref, got = (evaluate_estimator(problem, table, gains=g, predictor=p).moments
                for g, p in (per_tick.per_tick(), spline.per_tick()))
    return {
        "spline_tolerance": tolerance,
        "spans": spline.gain_spline.spans(),
        "oracle_J": got.J,
        "per_tick_oracle_J": ref.J,
        "J_change": (got.J - ref.J) / abs(ref.J) if ref.J else got.J - ref.J,
        "knot_cov_change": _cov_change(ref, got),
        "knot_cov": [cov_digits(c, m) for c, m in zip(got.knot_cov, got.knot_mean)],
        "gain_bytes": spline.gain_spline.nbytes,
        "per_tick_gain_bytes": int(per_tick.gain.nbytes),
    }


def _violation(y: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Signed distance outside [lo, hi] per row (0 inside; for an equality, y - value)."""
    return np.where(lo == hi, y - lo, np.maximum(y - hi, 0) - np.maximum(lo - y, 0))


def actuator_limits(d) -> dict:
    """``{"actuator_limits": {"u_min": [...] | None, "u_max": ...}}`` as the table stores them
    (float32), when the problem sets limits; ``{}`` otherwise (summaries stay unchanged)."""
    p = d.problem
    if p.u_min is None and p.u_max is None and p.u_hold is None:
        return {}
    return {"actuator_limits": {
        "u_min": None if p.u_min is None else d.table.u_min.astype(float),
        "u_max": None if p.u_max is None else d.table.u_max.astype(float),
        **({} if p.u_hold is None else {"u_hold": d.table.u_hold.astype(float)}),
        "note": "the design ignores the limits: the firmware clips the unconstrained law, "
                "and the oracle's numbers assume no command is clipped",
    }}


def _band_terms(d) -> dict:
    """The design's own summary entries; with bands also the rows of the dual the firmware
    re-solves from the measured x0 (0: it latches the affine map of the design's active set,
    see docs/theory/math-notes.md)."""
    terms = d.design.summary_terms()
    if has_bands(d.problem):
        terms["band_qp_rows"] = 0 if d.table.band_qp is None else d.table.band_qp.q
    if d.every_tick is not None:
        from stospline.refine.every_tick import every_tick_check   # loaded when a design has them
        sensor = None
        if d.problem.measurement is not None:     # the loop on the filter's estimate too
            from stospline.harness.estimator_run import sensor_path_mean
            sensor = sensor_path_mean(d.problem, d.table)
        terms["every_tick"] = every_tick_check(d, sensor_path=sensor)
    return terms
