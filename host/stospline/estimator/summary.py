"""The ``estimator`` entry of a design's JSON summary: what the loop costs when the law runs on
the filter's estimate of the problem's ``[measurement]`` sensor (exact moments,
`estimator.oracle`)."""
from __future__ import annotations

from typing import Callable

import numpy as np

from stospline.estimator.oracle import evaluate_estimator

__all__ = ["estimator_summary"]


def estimator_summary(problem, table, cov_digits: Callable = lambda cov, mean: cov, *,
                      flashed: tuple | None = None) -> dict:
    """``{"oracle_J", "every", "knots": [{"t", "mean", "cov", "error_cov",
    "constraint_violation"?}]}`` for the float32 `table` on the estimate; ``{"not_evaluated":
    reason}`` for a table the estimator loop cannot run (a one-tick delay, a band latch).
    `cov_digits(cov, mean)` rounds covariances as the rest of the summary does.

    `flashed`: ``(label, gains, predictor)`` of the filter as flashed (a spline table's:
    ``("spline", ...)`` from `harness.estimator_run.flashed_filter`); the figures are then that
    loop's, with ``"filter_gains": label`` and the per-sample filter's cost as
    ``"per_sample_oracle_J"``. Without it, the per-sample filter's (double LMMSE gains)."""
    try:
        per_sample = evaluate_estimator(problem, table)
    except ValueError as exc:
        return {"not_evaluated": str(exc).partition(": ")[2]}
    loop = per_sample if flashed is None else evaluate_estimator(
        problem, table, gains=flashed[1], predictor=flashed[2])
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
    out = {"oracle_J": mom.J, "every": problem.measurement.every, "knots": knots}
    if flashed is not None:
        out["filter_gains"] = flashed[0]
        out["per_sample_oracle_J"] = per_sample.moments.J
    return out
