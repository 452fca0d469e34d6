"""One self-contained HTML page of a design and its Monte Carlo run (`stospline report`).

Everything is inside the page: the figures are PNG data URIs, the style is inline, and a few
lines of script mark the page when every image has loaded and no script error occurred
(``<body data-images="ok" data-errors="0">``), which the browser test reads back. The markup
is the Jinja2 template ``templates/report.html.j2`` (package data), rendered with autoescaping
on, so a problem's name or any other text from the run cannot inject markup; this module
draws the figures and gathers the numbers the template lays out.
"""
from __future__ import annotations

import base64
import io
from functools import lru_cache

import numpy as np

from stospline.report.plot import _walls, oracle_with_path, plot_axes, plot_corridor
from stospline.report.summary_text import design_summary_text

__all__ = ["report_html"]


@lru_cache(maxsize=1)
def _template():
    """The page template, loaded from the package with autoescaping on."""
    import jinja2
    env = jinja2.Environment(loader=jinja2.PackageLoader("stospline.report", "templates"),
                             autoescape=True, undefined=jinja2.StrictUndefined,
                             trim_blocks=True, lstrip_blocks=True, keep_trailing_newline=True)
    return env.get_template("report.html.j2")


def _data_uri(buf: io.BytesIO) -> str:
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _png(fig) -> str:
    import matplotlib.pyplot as plt
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    plt.close(fig)
    return _data_uri(buf)


def _state_band(ax, t, exact, i: int, record, mean, paths: int) -> None:
    """On `ax`, state `i` against time: the oracle's mean +- 2 sd, the 5-95 % band of the
    recorded paths `record` (ticks, paths, n; none where None or fewer than 2 paths) and the
    Monte Carlo `mean` (ticks, n) of `paths` paths."""
    sd = np.sqrt(exact.path_var[:, i])
    ax.fill_between(exact.path_t, exact.path_mean[:, i] - 2 * sd,
                    exact.path_mean[:, i] + 2 * sd, color="tab:orange", alpha=0.25,
                    label="oracle mean +- 2 sd")
    if record is not None and record.shape[1] >= 2:
        lo, hi = np.percentile(record[:, :, i], [5, 95], axis=1)
        ax.plot(t, lo, ":", color="tab:blue", lw=1,
                label=f"5-95 % of {record.shape[1]} recorded paths")
        ax.plot(t, hi, ":", color="tab:blue", lw=1)
    ax.plot(t, mean[:, i], color="tab:blue", lw=1.5, label=f"mean of {paths} paths")


def _label(ax, ylabel: str, legend: bool) -> None:
    """The y label and grid of one panel, and its legend where `legend`."""
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)
    if legend:
        ax.legend(fontsize=7, loc="best")


def _time_png(fig, axs) -> str:
    """`_png` of a column of panels against time."""
    axs[-1, 0].set_xlabel("t [s]")
    fig.tight_layout()
    return _png(fig)


def _corridor(d, mc, exact) -> str:
    buf = io.BytesIO()
    plot_corridor(d, mc, buf, exact)
    return _data_uri(buf)


def _states(d, mc, exact):
    """Every state and input against time: the oracle's mean +- 2 sd, the Monte Carlo mean
    (states), the 5-95 % band of the recorded paths and one realisation (inputs)."""
    import matplotlib.pyplot as plt
    n, m = d.problem.n, d.problem.m
    fig, axs = plt.subplots(n + m, 1, figsize=(9, 1.9 * (n + m) + 0.8), sharex=True,
                            squeeze=False)
    t = mc.sample_t
    for i in range(n):
        ax = axs[i, 0]
        _state_band(ax, t, exact, i, mc.record_x, mc.mean_x, mc.paths)
        ax.plot(exact.path_t, exact.path_mean[:, i], "--", color="tab:orange", lw=1.2,
                label="oracle mean")
        _label(ax, f"x{i}", i == 0)
    for j in range(m):
        ax = axs[n + j, 0]
        if exact.path_u_mean.shape[0] == len(t) - 1:
            sd = np.sqrt(exact.path_u_var[:, j])
            ax.fill_between(t[:-1], exact.path_u_mean[:, j] - 2 * sd,
                            exact.path_u_mean[:, j] + 2 * sd, color="tab:orange", alpha=0.25,
                            step="post", label="oracle mean +- 2 sd")
            ax.plot(t[:-1], exact.path_u_mean[:, j], "--", color="tab:orange", lw=1.2,
                    label="oracle mean")
        if mc.record_u is not None and mc.record_u.shape[1] >= 2:
            lo, hi = np.percentile(mc.record_u[:, :, j], [5, 95], axis=1)
            ax.plot(t[:-1], lo, ":", color="tab:blue", lw=1,
                    label=f"5-95 % of {mc.record_u.shape[1]} recorded paths")
            ax.plot(t[:-1], hi, ":", color="tab:blue", lw=1)
        ax.plot(t[:-1], mc.sample_u[:, j], color="k", lw=0.6, label="one realisation")
        _label(ax, f"u{j + 1}", j == 0)
    return _time_png(fig, axs)


def _regions(d, mc, exact):
    """Each row of each [[regions]] entry at every tick against time: its band, the oracle's
    mean (and +- 2 sd where the row is one state), the Monte Carlo mean and the 5-95 % band
    of the recorded paths, and the ticks where the design holds the row at a bound."""
    import matplotlib.pyplot as plt
    p = d.problem
    rows = [(reg, i) for reg in p.tick_regions for i in range(reg.C.shape[0])]
    fig, axs = plt.subplots(len(rows), 1, figsize=(9, 2.2 * len(rows) + 0.8), sharex=True,
                            squeeze=False)
    # The rows the design holds at a bound: constraint generation's working set, or the
    # tick-grid QP's active region rows (tick, region position, row).
    held = set() if d.every_tick is None else {
        (p.tick_regions[k].index, i, j) for j, k, i in d.every_tick.working_set}
    t = mc.sample_t
    for ax, (reg, i) in zip(axs[:, 0], rows):
        c = reg.C[i]
        a, b = reg.t
        on = (exact.path_t >= a - 1e-12) & (exact.path_t <= b + 1e-12)
        y = exact.path_mean @ c
        unit = np.count_nonzero(c) == 1
        if unit:
            k = int(np.flatnonzero(c)[0])
            sd = abs(c[k]) * np.sqrt(np.maximum(exact.path_var[:, k], 0.0))
            ax.fill_between(exact.path_t[on], (y - 2 * sd)[on], (y + 2 * sd)[on],
                            color="tab:orange", alpha=0.2, label="oracle mean +- 2 sd")
        if mc.record_x is not None and mc.record_x.shape[1] >= 2:
            yr = mc.record_x.astype(float) @ c
            lo, hi = np.percentile(yr, [5, 95], axis=1)
            ax.plot(t[on], lo[on], ":", color="tab:blue", lw=1,
                    label=f"5-95 % of {mc.record_x.shape[1]} recorded paths")
            ax.plot(t[on], hi[on], ":", color="tab:blue", lw=1)
        ax.plot(t[on], (mc.mean_x @ c)[on], color="tab:blue", lw=1.5,
                label=f"mean of {mc.paths} paths")
        ax.plot(exact.path_t[on], y[on], "--", color="tab:orange", lw=1.2, label="oracle mean")
        ticks = sorted(j for (r, q, j) in held if r == reg.index and q == i)
        if ticks:
            ax.plot(exact.path_t[ticks], y[ticks], "o", ms=2.5, color="tab:red",
                    label=f"held at a bound ({len(ticks)} tick{'s' * (len(ticks) > 1)})")
        for bound in (reg.lower[i], reg.upper[i]):
            ax.axhline(bound, color="k", lw=0.8)
        # Zoom on the paths; a bound far from them is drawn but left off the axis range.
        lo_y, hi_y = float(y[on].min()), float(y[on].max())
        pad = 0.3 * max(hi_y - lo_y, 1e-9) + (2 * float(sd[on].max()) if unit else 0.0)
        lo_lim = reg.lower[i] if reg.lower[i] >= lo_y - 2 * pad else lo_y - pad
        hi_lim = reg.upper[i] if reg.upper[i] <= hi_y + 2 * pad else hi_y + pad
        ax.set_ylim(min(lo_lim, lo_y) - 0.1 * pad, max(hi_lim, hi_y) + 0.1 * pad)
        _label(ax, f"region {reg.index}, row {i}", True)
    return _time_png(fig, axs)


def _regions_check(d) -> dict:
    """The every-tick check of the summary (oracle, at every tick and between) for its table."""
    from stospline.refine.every_tick import every_tick_check
    s = every_tick_check(d)
    how = ("one sparse QP on the tick grid" if s["method"] == "tick-qp"
           else f"constraint generation ({s['iterations']} designs)")
    return {"how": how, "working_set_rows": s["working_set_rows"], "rows": s["regions"]}


def _parameter_family(d):
    """``(png, words)``: the exact mean paths of a problem with runtime parameters at the
    nominal (thick) and at the box's vertices or a seeded sample of it (thin,
    `stospline.oracle.over_box.family`), in the plotted plane and against time, with the
    regions' bounds on the plotted states; None when its table has no sensitivity columns."""
    import matplotlib.pyplot as plt
    from stospline.errors import DesignError
    from stospline.oracle.over_box import family, mean_paths
    from stospline.oracle.parametric import check_parametric_options, design_parametric
    p = d.problem
    if d.over_box is not None:
        pt = d.over_box.table
    else:
        try:
            opts = check_parametric_options(p, d.options)
        except DesignError:
            return None
        pt = design_parametric(p, discretization=opts.discretization, mode=opts.mode,
                               delay_ticks=opts.delay_ticks).table
    thetas, what = family(p.parameters)
    paths = mean_paths(p, pt, np.vstack([pt.nominal, thetas]))[..., :p.n]
    t = p.t0 + np.arange(paths.shape[1]) / p.tick_hz
    axes = plot_axes(p)
    panels = ([tuple(axes)] if len(axes) == 2 else []) + list(axes)
    fig, axs = plt.subplots(1, len(panels), figsize=(4.6 * len(panels), 4.2), squeeze=False)
    for ax, panel in zip(axs[0], panels):
        if isinstance(panel, tuple):
            ia, ib = panel
            xs, ys = paths[..., ia], paths[..., ib]
            _walls(ax, p)
            ax.set_xlabel(f"x{ia}"); ax.set_ylabel(f"x{ib}")
        else:
            xs, ys = np.broadcast_to(t, paths.shape[:2]), paths[..., panel]
            ax.set_xlabel("t [s]"); ax.set_ylabel(f"x{panel}")
            for reg in p.tick_regions:
                for i, c in enumerate(reg.C):
                    if np.count_nonzero(c) == 1 and c[panel] != 0:
                        for bound in (reg.lower[i], reg.upper[i]):
                            if np.isfinite(bound):
                                ax.hlines(bound / c[panel], *reg.t, color="k", lw=0.8)
        for k in range(1, len(paths)):
            ax.plot(xs[k], ys[k], color="0.45", lw=0.5, alpha=0.7,
                    label="over the box" if k == 1 else None)
        ax.plot(xs[0], ys[0], color="tab:orange", lw=2, label="nominal")
        ax.grid(alpha=0.3)
    axs[0, 0].legend(fontsize=7, loc="best")
    fig.tight_layout()
    names = ", ".join(q.name for q in p.parameters)
    return _png(fig), {"what": what, "names": names}


def _histogram(mc, oracle_J: float):
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 3.2))
    costs = mc.cost_sample          # the first paths' costs: a bounded sample of the run
    ax.hist(costs, bins=min(80, max(10, len(costs) // 20)), color="tab:blue", alpha=0.7)
    ax.axvline(oracle_J, color="tab:orange", lw=2, label=f"oracle expected cost {oracle_J:.5g}")
    mean = mc.cost_mean_ci()[0]
    ax.axvline(mean, color="k", ls="--", lw=1, label=f"Monte Carlo mean {mean:.5g}")
    ax.set_xlabel("cost of a path")
    ax.set_ylabel("paths" if len(costs) == mc.paths else f"paths (the first {len(costs)})")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return _png(fig)


def _statistics(summary: dict) -> list[dict]:
    """The verdict's statistics: the cost, then each knot's mean of each state."""
    c = summary["cost"]
    rows = [{"name": "cost", "mc": c["mc_mean"], "exact": c["oracle_implemented"], "z": c["z"]}]
    for k, kn in enumerate(summary["knots"]):
        rows += [{"name": f"knot {k} (t = {kn['t']:g}) mean x{i}", "mc": kn["mc_mean"][i],
                  "exact": kn["oracle_mean"][i], "z": z} for i, z in enumerate(kn["z"])]
    return rows


def _faults(summary: dict) -> dict | None:
    """The faults of this run (None without any), their levels as one text."""
    f = summary.get("faults", {})
    if not f.get("levels"):
        return None
    return {**f, "levels": ", ".join(f"{k} = {v}" for k, v in f["levels"].items())}


def _fault_table(rows, left_out, on_model: bool) -> dict | None:
    """The fault sweep (`harness.fault_sweep.fault_table`, or on a [plant] model
    `nonlinear.fault_sweep.model_fault_table` with the rows it `left_out`) as header cells and
    rows of cells (`fault_row_cells`; the template left-aligns the first two, names)."""
    if not rows:
        return None
    from stospline.harness.fault_sweep import FAULT_COLUMNS, fault_row_cells
    return {"columns": FAULT_COLUMNS, "rows": [fault_row_cells(r) for r in rows],
            "paths": rows[0].paths, "on_model": on_model,
            "left_out": [f"{r.fault} ({r.level}): {r.reason}" for r in left_out]}


def _corridors(summary: dict) -> list[dict]:
    """The corridors' exit probabilities (`pipeline.simulation_summary`) with, per time bin,
    the oracle's Gaussian and Cantelli bounds (None for a table designed for a delay)."""
    out = []
    for c in summary.get("corridors", []):
        m, bound = c["mc"], c["bound"]
        gauss = [None] * len(m["by_bin"]) if bound is None else bound["gaussian"]["by_bin"]
        cant = [None] * len(m["by_bin"]) if bound is None else bound["cantelli"]["by_bin"]
        bins = [{"lo": lo, "hi": hi, "mc": mb, "gaussian": g, "cantelli": k}
                for (lo, hi), mb, g, k in zip(c["bins_t"], m["by_bin"], gauss, cant)]
        walls = [{"wall": w["wall"], "mc": mw}
                 for w, mw in zip(c["physical_walls"], m["by_physical_wall"])]
        out.append({**c, "bins": bins, "walls": walls})
    return out


def report_html(d, mc, summary: dict, fault_rows=None, no_fault_table: str | None = None,
                plant: dict | None = None, fault_left_out=()) -> str:
    """The page for design `d` (`pipeline.Designed`), its Monte Carlo run `mc` and that
    run's `pipeline.simulation_summary`; `fault_rows` (`harness.fault_sweep.fault_table`) adds
    the fault table, `no_fault_table` says why there is none. `plant`: of a [plant] problem
    (`d` and `mc` its linearisation's), the Monte Carlo on the model itself
    (`nonlinear.simulate.plant_summary`), shown first; its fault table is the model's, with
    the rows `fault_left_out` (`nonlinear.fault_sweep.LeftOut`) named."""
    p = d.problem
    exact = oracle_with_path(d, mc.faults)
    axes = plot_axes(p)
    layout = ("state " + str(axes[0]) + " against time" if len(axes) == 1
              else f"phase plane of x{axes[0]} and x{axes[1]}, knot covariance ellipses (2 sd)")
    images = {"corridor": _corridor(d, mc, exact), "states": _states(d, mc, exact)}
    if p.tick_regions:
        images["regions"] = _regions(d, mc, exact)
    family = _parameter_family(d) if p.parameters else None
    if family is not None:
        images["parameters"] = family[0]
    images["histogram"] = _histogram(mc, summary["cost"]["oracle_implemented"])
    return _template().render(
        name=p.name, verdict=summary["verdict"], design_text=design_summary_text(d),
        paths=mc.paths, seed=summary["seed"], substeps=summary["substeps"],
        bias=summary["simulation_bias"]["cost"], cost=summary["cost"],
        statistics=_statistics(summary), saturation=summary["saturation"],
        faults=_faults(summary), corridors=_corridors(summary), layout=layout, images=images,
        regions=_regions_check(d) if p.tick_regions else None,
        fault_table=_fault_table(fault_rows, fault_left_out, plant is not None),
        parameters=None if family is None else family[1],
        no_fault_table=no_fault_table, plant=plant, plant_rows=_plant_rows(plant))


def _plant_rows(plant: dict | None) -> list[dict]:
    """One row per knot and state of the model's Monte Carlo: mean and variance with their
    intervals (widened by the scheme's bias), the linearisation's oracle, and whether each is
    inside."""
    rows = []
    for k, kn in enumerate(plant["knots"] if plant else []):
        for i, mean in enumerate(kn["mean"]):
            hw = kn["mean_halfwidth"][i] + kn["scheme_bias"][i]
            vhw = kn["variance_halfwidth"][i] + kn["scheme_bias_variance"][i]
            var, o, ov = kn["variance"][i], kn["oracle_mean"][i], kn["oracle_variance"][i]
            rows.append({"knot": k, "t": kn["t"], "state": i, "mean": mean, "hw": hw,
                         "oracle": o, "mean_ok": abs(mean - o) <= hw, "variance": var,
                         "vhw": vhw, "oracle_variance": ov, "variance_ok": abs(var - ov) <= vhw})
    return rows
