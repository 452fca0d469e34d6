"""One self-contained HTML page of a design and its Monte Carlo run (`stospline report`).

Everything is inside the page: the figures are PNG data URIs, the style is inline, and a few
lines of script mark the page when every image has loaded and no script error occurred
(``<body data-images="ok" data-errors="0">``), which the browser test reads back.
"""
from __future__ import annotations

import base64
import html
import io

import numpy as np

from stospline.report.plot import plot_axes, plot_corridor
from stospline.report.summary_text import design_summary_text

__all__ = ["report_html"]

_STYLE = """
body { font-family: sans-serif; max-width: 1100px; margin: 2em auto; color: #222; }
h1 { font-size: 1.6em; } h2 { font-size: 1.2em; margin-top: 1.6em; }
pre { background: #f6f6f6; padding: 0.8em; overflow-x: auto; }
table { border-collapse: collapse; margin: 0.5em 0; }
td, th { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: right; }
th { background: #eee; } td.name { text-align: left; }
.agree { color: #176b1d; font-weight: bold; } .disagree { color: #a31515; font-weight: bold; }
img { max-width: 100%; }
"""

# Marks the page for the browser test: every image decoded, and no script error.
_CHECK = """
window.__errors = 0;
window.addEventListener("error", function () { window.__errors += 1; }, true);
window.addEventListener("load", function () {
  var imgs = document.images, ok = imgs.length > 0;
  for (var i = 0; i < imgs.length; i++) {
    if (!imgs[i].complete || imgs[i].naturalWidth === 0) { ok = false; }
  }
  document.body.setAttribute("data-images", ok ? "ok" : "missing");
  document.body.setAttribute("data-errors", String(window.__errors));
});
"""


def _data_uri(buf: io.BytesIO) -> str:
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _png(fig) -> str:
    import matplotlib.pyplot as plt
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    plt.close(fig)
    return _data_uri(buf)


def _img(uri: str, alt: str) -> str:
    return f'<img src="{uri}" alt="{html.escape(alt)}">'


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
        sd = np.sqrt(exact.path_var[:, i])
        ax.fill_between(exact.path_t, exact.path_mean[:, i] - 2 * sd,
                        exact.path_mean[:, i] + 2 * sd, color="tab:orange", alpha=0.25,
                        label="oracle mean +- 2 sd")
        if mc.record_x is not None and mc.record_x.shape[1] >= 2:
            lo, hi = np.percentile(mc.record_x[:, :, i], [5, 95], axis=1)
            ax.plot(t, lo, ":", color="tab:blue", lw=1,
                    label=f"5-95 % of {mc.record_x.shape[1]} recorded paths")
            ax.plot(t, hi, ":", color="tab:blue", lw=1)
        ax.plot(t, mc.mean_x[:, i], color="tab:blue", lw=1.5, label=f"mean of {mc.paths} paths")
        ax.plot(exact.path_t, exact.path_mean[:, i], "--", color="tab:orange", lw=1.2,
                label="oracle mean")
        ax.set_ylabel(f"x{i}")
        ax.grid(alpha=0.3)
        if i == 0:
            ax.legend(fontsize=7, loc="best")
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
        ax.set_ylabel(f"u{j + 1}")
        ax.grid(alpha=0.3)
        if j == 0:
            ax.legend(fontsize=7, loc="best")
    axs[-1, 0].set_xlabel("t [s]")
    fig.tight_layout()
    return _png(fig)


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
        ax.set_ylabel(f"region {reg.index}, row {i}")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="best")
    axs[-1, 0].set_xlabel("t [s]")
    fig.tight_layout()
    return _png(fig)


def _regions_text(d) -> str:
    """The every-tick check of the summary as a table (oracle, at every tick and between)."""
    from stospline.sim.every_tick import every_tick_check
    s = every_tick_check(d)
    how = ("one sparse QP on the tick grid" if s["method"] == "tick-qp"
           else f"constraint generation ({s['iterations']} designs)")
    rows = "".join(
        f"<tr><td>{r['region']}</td><td>{r['ticks']}</td>"
        f"<td>{r['worst_at_ticks_design']:.3g}</td><td>{r['worst_at_ticks_implemented']:.3g}</td>"
        f"<td>{r['worst_over_interval']:.3g}{'' if r['over_interval_exact'] else ' (sampled)'}"
        f"</td><td>{'yes' if r['between_ticks_enforced'] else 'no'}</td></tr>"
        for r in s["regions"])
    return (f"<p id=\"regions\">Met by {how}, {s['working_set_rows']} rows held at a bound. "
            "Worst excursion beyond each band (negative: inside by that much), exact moment "
            "oracle:</p><table><tr><th>region</th><th>ticks</th><th>at the ticks, design's "
            "law</th><th>at the ticks, float32 table</th><th>over [a, b], between ticks "
            f"too</th><th>between ticks enforced</th></tr>{rows}</table>")


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


def _verdict_rows(summary: dict) -> str:
    c = summary["cost"]
    rows = [("cost", c["mc_mean"], c["oracle_implemented"], c["z"])]
    for k, kn in enumerate(summary["knots"]):
        rows += [(f"knot {k} (t = {kn['t']:g}) mean x{i}", kn["mc_mean"][i],
                  kn["oracle_mean"][i], z) for i, z in enumerate(kn["z"])]
    out = ["<tr><th>statistic</th><th>Monte Carlo</th><th>oracle (exact)</th><th>z</th></tr>"]
    for name, mc_v, exact, z in rows:
        z_text = "n/a" if z is None else f"{z:+.2f}"
        out.append(f'<tr><td class="name">{html.escape(name)}</td><td>{mc_v:.6g}</td>'
                   f"<td>{exact:.6g}</td><td>{z_text}</td></tr>")
    return "\n".join(out)


def _faults_text(summary: dict) -> str:
    f = summary.get("faults", {})
    if not f.get("levels"):
        return "<p>Faults: none modelled in this run.</p>"
    levels = ", ".join(f"{k} = {v}" for k, v in f["levels"].items())
    how = (f"the exact oracle of the faulty loop gives {f['oracle_cost']:.6g}" if f["exact_oracle"]
           else "these faults have no exact oracle (quantization, missed ticks, or sensor noise "
           "before the band latch): Monte Carlo only")
    return (f'<p id="faults">Faults in this run: {html.escape(levels)}; {how} (the fault-free '
            f"loop: {f['nominal_cost']:.6g}).</p>")


def _fault_table(rows) -> str:
    """The fault sweep (`sim.fault_sweep.fault_table`) as an HTML table (the cells of
    `fault_row_cells`; the first two, names, left-aligned)."""
    from stospline.sim.fault_sweep import FAULT_COLUMNS, fault_row_cells
    out = ['<table id="fault-table"><tr>' + "".join(f"<th>{html.escape(c)}</th>"
                                                    for c in FAULT_COLUMNS) + "</tr>"]
    for r in rows:
        cells = [html.escape(c) for c in fault_row_cells(r)]
        out.append("<tr>" + "".join(f'<td class="name">{c}</td>' for c in cells[:2])
                   + "".join(f"<td>{c}</td>" for c in cells[2:]) + "</tr>")
    return "\n".join(out) + "</table>"


def _corridor_text(summary: dict) -> str:
    """The corridors' exit probabilities (`pipeline.simulation_summary`), by time and wall,
    beside the oracle's bounds (none for a table designed for a delay)."""
    out = []
    for i, c in enumerate(summary.get("corridors", [])):
        m, bound = c["mc"], c["bound"]
        eps = "" if c["epsilon"] is None else f", risk budget epsilon = {c['epsilon']:g}"
        if bound is None:
            said = "No oracle bounds: the table is designed for a delay."
            per_bin = [("-", "-")] * len(m["by_bin"])
        else:
            bc, bg = bound["cantelli"], bound["gaussian"]
            said = (f"The oracle's union bounds over the ticks: Cantelli {bc['total']:.4g} "
                    f"(valid for any distribution; sum {bc['sum']:.4g}), Gaussian "
                    f"{bg['total']:.4g} (an assumption: the multiplicative noise makes the "
                    f"outputs non-Gaussian; sum {bg['sum']:.4g}); worst single tick "
                    f"{bc['worst_tick']:.3g} (Cantelli), {bg['worst_tick']:.3g} (Gaussian).")
            per_bin = [(f"{g:.3g}", f"{k:.3g}") for g, k in zip(bg["by_bin"], bc["by_bin"])]
        rows = "".join(
            f"<tr><td>{lo:.3f} – {hi:.3f}</td><td>{mb['exits']}</td>"
            f"<td>{100 * mb['estimate']:.4g}%</td><td>{100 * mb['upper99']:.4g}%</td>"
            f"<td>{gb}</td><td>{cb}</td></tr>"
            for (lo, hi), mb, (gb, cb) in zip(c["bins_t"], m["by_bin"], per_bin))
        walls = "".join(
            f"<tr><td>{html.escape(w['wall'])}</td><td>{mw['exits']}</td>"
            f"<td>{100 * mw['estimate']:.4g}%</td><td>{100 * mw['upper99']:.4g}%</td></tr>"
            for w, mw in zip(c["physical_walls"], m["by_physical_wall"]))
        examples = ", ".join(f"path {e['path']} at {e['t']:.3f} s (wall {e['wall']})"
                             for e in m["examples"])
        out += [
            f'<h3 id="corridor-{i}">Corridor {i}: t = [{c["t"][0]:g}, {c["t"][1]:g}] s{eps}</h3>',
            f"<p>Left at some tick by <b>{m['exits']}</b> of {m['paths']} paths: "
            f"<b>{100 * m['estimate']:.4g}%</b>, one-sided 99% upper bound (Clopper-Pearson) "
            f"<b>{100 * m['upper99']:.4g}%</b>. {said}</p>",
            "<table><tr><th>time (s)</th><th>exits</th><th>estimate</th><th>99% upper</th>"
            f"<th>Gaussian bound</th><th>Cantelli bound</th></tr>{rows}</table>",
            "<table><tr><th>wall (y = C x)</th><th>exits</th><th>estimate</th>"
            f"<th>99% upper</th></tr>{walls}</table>",
            f"<p>First paths that leave: {html.escape(examples) or 'none'}.</p>"]
    return "\n".join((["<h2>Corridors: probability of leaving</h2>"] + out) if out else [])


def report_html(d, mc, summary: dict, fault_rows=None, no_fault_table: str | None = None
                ) -> str:
    """The page for design `d` (`pipeline.Designed`), its Monte Carlo run `mc` and that
    run's `pipeline.simulation_summary`; `fault_rows` (`sim.fault_sweep.fault_table`) adds
    the fault table, `no_fault_table` says why there is none."""
    from stospline.sim.fault_oracle import evaluate_with_faults
    from stospline.sim.oracle import evaluate_table
    p = d.problem
    faults = mc.faults
    exact = (evaluate_with_faults(p, d.table, faults, path=True)
             if faults.any and summary["faults"]["exact_oracle"] else evaluate_table(p, d.table))
    v = summary["verdict"]
    sat = summary["saturation"]
    bias = summary["simulation_bias"]
    verdict_cls = "agree" if v["agree"] else "disagree"
    axes = plot_axes(p)
    layout = ("state " + str(axes[0]) + " against time" if len(axes) == 1
              else f"phase plane of x{axes[0]} and x{axes[1]}, knot covariance ellipses (2 sd)")
    parts = [
        "<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
        f"<title>stospline report: {html.escape(p.name)}</title>",
        f"<style>{_STYLE}</style><script>{_CHECK}</script></head><body>",
        f"<h1>{html.escape(p.name)}</h1>",
        f'<p class="{verdict_cls}" id="verdict">Verdict: '
        f"{'the Monte Carlo run agrees with the oracle' if v['agree'] else 'DISAGREE'} "
        f"(max |z| {v['max_abs_z']:.3g} against {v['z_limit']:.3g}, {v['correction']} over "
        f"{v['statistics']} statistics at {100 * v['confidence']:g}% jointly; "
        f"{html.escape(v['reason'])}).</p>",
        "<h2>Design</h2>", f"<pre>{html.escape(design_summary_text(d))}</pre>",
        "<h2>Monte Carlo through the compiled C controller</h2>",
        f"<p>{mc.paths} paths, seed {summary['seed']}, {summary['substeps']} plant steps per "
        f"tick (plant-scheme bias in the cost {bias['cost']:.3g}), mean cost "
        f"<b id=\"mc-cost\">{summary['cost']['mc_mean']:.6g}</b>, 95% CI "
        f"[{summary['cost']['ci95'][0]:.6g}, {summary['cost']['ci95'][1]:.6g}], oracle "
        f"<b id=\"oracle-cost\">{summary['cost']['oracle_implemented']:.6g}</b>, "
        f"predicted J0 {summary['cost']['predicted_J0']:.6g}.</p>",
        f"<table>{_verdict_rows(summary)}</table>",
        f"<p id=\"saturation\">Saturation: {100 * sat['tick_fraction']:.4g}% of ticks, "
        f"{100 * sat['path_fraction']:.4g}% of paths"
        + ("" if sat["limited"] else " (the table has no actuator limits)") + ".</p>",
        _faults_text(summary),
        _corridor_text(summary),
        f"<h2>Paths ({html.escape(layout)})</h2>", _img(_corridor(d, mc, exact), "corridor"),
        "<h2>States and inputs against time</h2>", _img(_states(d, mc, exact), "states"),
        *(["<h2>Regions at every tick</h2>", _regions_text(d),
           _img(_regions(d, mc, exact), "regions")] if p.tick_regions else []),
        "<h2>Cost of the paths</h2>",
        _img(_histogram(mc, summary["cost"]["oracle_implemented"]), "cost histogram"),
        *(["<h2>Faults of the loop</h2>",
           f"<p>Each fault at a few levels relative to the plan ({fault_rows[0].paths} paths "
           "each, the same seed, so the rows differ by the fault): the fault oracle's exact "
           "numbers where the fault is linear, '-' where it is not (quantization, missed "
           "ticks), beside Monte Carlo through the compiled C controller. Constraint bias: the "
           "largest |E{C x} - value| at a knot; knot variance: the largest variance of a "
           "constrained output at a knot.</p>", _fault_table(fault_rows)]
          if fault_rows else []),
        *([f'<p id="no-fault-table">No fault table: {html.escape(no_fault_table)}.</p>']
          if no_fault_table and not fault_rows else []),
        "</body></html>",
    ]
    return "\n".join(parts) + "\n"
