"""The summary of a Monte Carlo run of the loop on a sensor (``stospline simulate`` for a
problem with ``[measurement]``): the keys of `simulation_summary.simulation_summary` with the
estimator oracle of the flashed filter tables as the exact numbers, plus the sensor and the
estimation error ``x - x̂`` at each knot, Monte Carlo beside the oracle; and its text.

``d`` is a `stospline.pipeline.Designed`; ``run`` a `harness.estimator_run.SensorRun`.
"""
from __future__ import annotations

import numpy as np

from stospline import strict
from stospline.precision import verbatim
from stospline.report.design_summary import actuator_limits
from stospline.report.json_numbers import rounded
from stospline.report.simulation_summary import cost_and_bias, knot_entry, saturation, verdict
from stospline.report.summary_text import simulation_summary_text

__all__ = ["sensor_simulation_summary", "sensor_simulation_text", "exact_standard_errors"]

_ZERO_SE = ("every path gave the same value: the Monte Carlo standard error is 0 up to "
            "rounding, so the ratio is undefined")


def sensor_simulation_summary(d, run, *, seed: int, confidence: float = 0.99) -> dict:
    """Monte Carlo statistics of the sensor loop beside the estimator oracle of the flashed
    tables (cost, knot means and covariances, z-scores, the verdict of
    `simulation_summary.verdict`), the plant scheme's bias, saturation, and per knot the
    estimation error: its Monte Carlo mean and covariance beside the oracle's (the oracle's
    mean is ``E x - E x̂``, zero up to the float32 predictor's rounding)."""
    mc, exact, scheme = run.mc, run.exact.moments, run.scheme.moments
    meas = d.problem.measurement
    tails, tails_why = exact_standard_errors(d, run)
    cost, bias = cost_and_bias(d, mc, exact, scheme, _ZERO_SE, tails=tails)
    knots = []
    for k, kn in enumerate(d.problem.knots):
        err = run.record["knot_error"][k]
        cov = err.cov()
        knots.append({
            **knot_entry(mc, exact, k, kn.t, _ZERO_SE, tails=tails),
            "estimation_error": {
                "mc_mean": err.mean, "mc_mean_stderr": err.mean_se(),
                "mc_cov": cov[0, 0] if cov.shape == (1, 1) else cov,
                "oracle_mean": exact.knot_mean[k] - run.exact.knot_estimate_mean[k],
                "oracle_cov": run.exact.knot_error_cov[k],
            },
        })
    summary = rounded({
        "name": d.problem.name, "paths": mc.paths, "seed": seed, "substeps": mc.substeps,
        "x0": verbatim(d.problem.x0),
        "tick_hz": d.table.tick_hz, "worst_status": mc.worst_status,
        "measurement": {
            **verbatim(meas.as_dict()),
            "loop": ("the law on the estimate of the filter's float32 tables as flashed, "
                     "through the compiled C estimator controller"),
            "full_state_oracle": d.implemented.J,
        },
        "cost": cost,
        **_faults_entry(d, run),
        "simulation_bias": bias,
        "knots": knots,
        "standard_errors": {"used": "sample" if tails is None else "exact", "why": tails_why},
        "saturation": saturation(d, mc, {"u_low": [float(v) for v in mc.u_low],
                                         "u_high": [float(v) for v in mc.u_high]}),
        **actuator_limits(d),
        **_corridors(d, run),
    })
    summary["verdict"] = verdict(summary, confidence)
    strict.check_summary_finite(d.problem, summary, "simulated numbers")
    return summary


def _faults_entry(d, run) -> dict:
    """``{"faults": ...}`` as the full-state summary's (levels, the exact oracle of the loop
    with them, the fault-free one), or nothing without faults."""
    faults = d.problem.faults
    if not faults.any or run.nominal is None:
        return {}
    return {"faults": {"levels": verbatim(faults.as_dict()), "exact_oracle": True,
                       "oracle_cost": run.exact.moments.J,
                       "nominal_cost": run.nominal.moments.J}}


def exact_standard_errors(d, run):
    """``(tails, why)``: the exact moments up to the fourth of the sensor loop the run
    simulates (`estimator.tails.evaluate_estimator_tails`, with the run's plant scheme and the
    flashed filter, in the loop with the problem's faults), and why the z-scores divide by
    them or by the sample's own (tails None)."""
    from stospline.estimator.tails import (estimator_tails_unsupported,
                                           evaluate_estimator_tails)
    faults = d.problem.faults
    why = estimator_tails_unsupported(d.problem, d.table, faults)
    if why is not None:
        return None, f"sample: {why} (no fourth-moment oracle)"
    if run.mc.cost_moments.alike()[0]:
        return None, "sample: every path alike (no noise)"
    _, pred = run.tables.per_tick()
    tails = evaluate_estimator_tails(d.problem, d.table, run.scheme, predictor=pred,
                                     substeps=run.mc.substeps, faults=faults)
    return tails, ("exact: the estimator oracle's cost variance and knot covariances of the "
                   f"plant scheme ({run.mc.substeps} steps per tick"
                   f"{', with the faults' if faults.any else ''})")


def _corridors(d, run) -> dict:
    """``{"corridors": [...]}`` as `simulation_summary`'s, for the sensor loop: the exits of
    the true state through the C, and the union bounds from the exact per-tick moments of the
    true output under the loop on the flashed filter (`harness.estimator_run.sensor_outputs`)."""
    if not d.problem.corridors or run.mc.exits is None:
        return {}
    from stospline.harness.estimator_run import sensor_outputs
    from stospline.harness.exit_stats import corridor_report
    gains, pred = run.tables.per_tick()
    outputs = [sensor_outputs(d.problem, d.table, c.C, (run.tables, gains, pred))[1:]
               for c in d.problem.corridors]
    rep = corridor_report(d.problem, d.table, run.mc.exits, outputs=outputs)
    for entry in rep:
        entry["bound"]["loop"] = "the law on the flashed filter's estimate (true state)"
    return {"corridors": rep}


def sensor_simulation_text(s: dict) -> str:
    """`simulation_summary_text` of `s` with the sensor and, per knot, the standard
    deviations of the estimation error (Monte Carlo and oracle) before the verdict."""
    base = simulation_summary_text(s).rstrip("\n").split("\n")
    meas = s["measurement"]
    every = meas.get("every", 1)
    sensor = (f"  sensor: y = C x + noise, {len(meas['C'])} output(s) every {every} tick(s) "
              f"({s['tick_hz'] / every:g} Hz); the law runs on the estimate (the oracle: the "
              f"flashed filter tables; full-state oracle {meas['full_state_oracle']:.6g})")
    fmt = lambda v: "[" + ", ".join(f"{x:.5f}" for x in v) + "]"  # noqa: E731
    errors = []
    for k, kn in enumerate(s["knots"]):
        e = kn["estimation_error"]
        sd = lambda c: np.sqrt(np.maximum(np.diag(np.atleast_2d(c)), 0.0))  # noqa: E731
        errors.append(f"  knot {k} estimation error x - x̂: sd MC {fmt(sd(e['mc_cov']))}, "
                      f"oracle {fmt(sd(e['oracle_cov']))}; mean MC "
                      f"{'[' + ', '.join(f'{x:+.2e}' for x in e['mc_mean']) + ']'}")
    return "\n".join([base[0], sensor, *base[1:-1], *errors, base[-1]]) + "\n"
