"""The HTML page of a loop on a sensor (`stospline report` for a problem with ``[measurement]``):
the verdict and statistics of `report.sensor_simulation`, the true path beside the
controller's estimate, and the estimation error ``x - x̂`` against the estimator oracle's
band. Self-contained as `report.html`'s page (the template ``sensor_report.html.j2``).

``d`` is a `stospline.pipeline.Designed`; ``run`` a `harness.estimator_run.SensorRun` whose
``record`` holds recorded paths (``run_sensor_loop(..., record=N)``, N >= 2).
"""
from __future__ import annotations

import numpy as np

from stospline.report.html import _histogram, _label, _state_band, _statistics, _time_png
from stospline.report.summary_text import design_summary_text

__all__ = ["sensor_report_html"]


def _true_and_estimate(d, run):
    """Per state: the oracle's mean +- 2 sd of the true state, the Monte Carlo mean, the 5-95 %
    band of the recorded paths, and one recorded path with the controller's estimate of it."""
    import matplotlib.pyplot as plt
    mc, exact, rec = run.mc, run.exact.moments, run.record
    n = d.problem.n
    fig, axs = plt.subplots(n, 1, figsize=(9, 1.9 * n + 0.8), sharex=True, squeeze=False)
    t = mc.sample_t
    for i in range(n):
        ax = axs[i, 0]
        _state_band(ax, t, exact, i, rec["x"], mc.mean_x, mc.paths)
        ax.plot(t, rec["x"][:, 0, i], color="k", lw=0.8, label="one path: true state")
        ax.plot(t, rec["xhat"][:, 0, i], color="tab:red", lw=0.8, ls="--",
                label="its estimate x̂ (the controller's)")
        _label(ax, f"x{i}", i == 0)
    return _time_png(fig, axs)


def _error_band(d, run):
    """Per state: the estimation error of the prediction the controller holds at each tick,
    the oracle's +- 2 sd band (exact, zero mean up to float32 rounding) beside the recorded
    paths' +- 2 sd and one path's error."""
    import matplotlib.pyplot as plt
    rec, loop = run.record, run.exact
    n = d.problem.n
    err = rec["x"][:-1] - rec["xhat"][:-1].astype(float)      # (ticks, record, n)
    t = run.mc.sample_t[:-1]
    sd_oracle = np.sqrt(np.maximum(np.diagonal(loop.prior_error_cov, axis1=1, axis2=2), 0.0))
    sd_mc = err.std(axis=1, ddof=1)
    fig, axs = plt.subplots(n, 1, figsize=(9, 1.7 * n + 0.8), sharex=True, squeeze=False)
    for i in range(n):
        ax = axs[i, 0]
        ax.fill_between(t, -2 * sd_oracle[:, i], 2 * sd_oracle[:, i], color="tab:orange",
                        alpha=0.3, step="post", label="oracle +- 2 sd")
        ax.plot(t, 2 * sd_mc[:, i], color="tab:blue", lw=1,
                label=f"+- 2 sd of {err.shape[1]} recorded paths")
        ax.plot(t, -2 * sd_mc[:, i], color="tab:blue", lw=1)
        ax.plot(t, err[:, 0, i], color="k", lw=0.6, label="one path")
        _label(ax, f"x{i} - x̂{i}", i == 0)
    return _time_png(fig, axs)


def _errors(summary: dict) -> list[dict]:
    """Per knot and state: the estimation error's Monte Carlo mean and sd beside the oracle's."""
    rows = []
    for k, kn in enumerate(summary["knots"]):
        e = kn["estimation_error"]
        mc_sd = np.sqrt(np.maximum(np.diag(np.atleast_2d(e["mc_cov"])), 0.0))
        or_sd = np.sqrt(np.maximum(np.diag(np.atleast_2d(e["oracle_cov"])), 0.0))
        rows += [{"name": f"knot {k} (t = {kn['t']:g}) x{i} - x̂{i}", "mc_mean": e["mc_mean"][i],
                  "oracle_mean": e["oracle_mean"][i], "mc_sd": float(mc_sd[i]),
                  "oracle_sd": float(or_sd[i])} for i in range(len(mc_sd))]
    return rows


def sensor_report_html(d, run, summary: dict) -> str:
    """The page of design `d` run on its sensor (`run`, summarised by `summary` from
    `report.sensor_simulation.sensor_simulation_summary`)."""
    from stospline.report.html import _template
    if run.record["x"].shape[1] < 2:
        raise ValueError("sensor_report_html: the run recorded fewer than 2 paths")
    meas = summary["measurement"]
    images = {"paths": _true_and_estimate(d, run), "errors": _error_band(d, run),
              "histogram": _histogram(run.mc, summary["cost"]["oracle_implemented"])}
    return _template().environment.get_template("sensor_report.html.j2").render(
        name=d.problem.name, verdict=summary["verdict"], design_text=design_summary_text(d),
        paths=run.mc.paths, seed=summary["seed"], substeps=summary["substeps"],
        bias=summary["simulation_bias"]["cost"], cost=summary["cost"],
        statistics=_statistics(summary), saturation=summary["saturation"],
        sensor={"outputs": len(meas["C"]), "every": meas.get("every", 1),
                "hz": d.table.tick_hz / meas.get("every", 1),
                "full_state": meas["full_state_oracle"]},
        errors=_errors(summary), recorded=run.record["x"].shape[1], images=images)
