"""The ``estimator`` entry of a design's JSON summary: what the loop costs when the law runs on
the filter's estimate of the problem's ``[measurement]`` sensor (exact moments,
`estimator.oracle`)."""
from __future__ import annotations

from typing import Callable

import numpy as np

from stospline.estimator.oracle import evaluate_estimator

__all__ = ["estimator_summary"]


def estimator_summary(problem, table, cov_digits: Callable = lambda cov, mean: cov) -> dict:
    """``{"oracle_J", "every", "knots": [{"t", "mean", "cov", "error_cov",
    "constraint_violation"?}]}`` for the float32 `table` on the estimate; ``{"not_evaluated":
    reason}`` for a table the estimator loop cannot run (a one-tick delay, a band latch).
    `cov_digits(cov, mean)` rounds covariances as the rest of the summary does."""
    try:
        loop = evaluate_estimator(problem, table)
    except ValueError as exc:
        return {"not_evaluated": str(exc).partition(": ")[2]}
    mom = loop.moments
    knots = []
    for k, kn in enumerate(problem.knots):
        entry = {"t": kn.t, "mean": mom.knot_mean[k],
                 "cov": cov_digits(mom.knot_cov[k], mom.knot_mean[k]),
                 "error_cov": cov_digits(loop.knot_error_cov[k], mom.knot_mean[k])}
        if kn.constraint is not None:
            lo, hi = kn.constraint.bounds
            y = mom.knot_constraint[k]
            entry["constraint_violation"] = np.where(
                lo == hi, y - lo, np.maximum(y - hi, 0) - np.maximum(lo - y, 0))
        knots.append(entry)
    return {"oracle_J": mom.J, "every": problem.measurement.every, "knots": knots}


def gain_spline_certificate(problem, table, tolerance: float, cov_digits: Callable = lambda
                            cov, mean: cov) -> dict:
    """The ``estimator.gain_spline`` entry of a spline design's summary: the filter's gains
    as a spline (`estimator.gain_spline`, fitted to `tolerance`) against the per-tick float32
    gains, both as flashed (with the flashed predictor): the loop's exact cost with each, the
    relative change, the largest relative change of a knot covariance (Frobenius, 2 digits),
    the spline's knot covariances, its spans per stage and its bytes against the per-tick
    gains'. Raises SplineBudgetError when the tolerance cannot be met."""
    from stospline.estimator.ctable import estimator_table
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
