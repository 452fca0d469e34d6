"""Figures in the spirit of the paper's Figure 1."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["plot_corridor", "corridor_figure", "Labels", "oracle_with_path"]


@dataclass(frozen=True)
class Labels:
    """What the figure calls the paths' run and the prediction beside it, and its title
    (None: the problem's name, J0 and the run's mean cost with its 95 % interval)."""
    run: str = "Monte Carlo"
    oracle: str = "oracle"
    title: str | None = None


def oracle_with_path(d, faults):
    """The oracle of ``d.table`` with its mean path, for the figures: in the loop with
    `faults` where they have an exact oracle, else without them."""
    from stospline.oracle.evaluate import evaluate_table
    from stospline.oracle.faults import evaluate_with_faults, has_exact_oracle
    if faults.any and has_exact_oracle(d.table, faults):
        return evaluate_with_faults(d.problem, d.table, faults, path=True)
    return evaluate_table(d.problem, d.table)


def _walls(ax, problem) -> None:
    for wall in problem.plot.get("walls", []):
        w = np.asarray(wall, dtype=float)
        ax.plot(w[:, 0], w[:, 1], color="0.2", lw=2)


def plot_axes(problem) -> list[int]:
    """The states drawn: ``[plot] axes``, else the phase plane of states 0 and 1, or state 0
    against time when there is only one state."""
    return list(problem.plot.get("axes", [0, 1] if problem.n >= 2 else [0]))


def plot_corridor(d, mc, out: str | Path, exact=None, labels: Labels = Labels()) -> None:
    """`corridor_figure` written to `out` (a file name or a binary stream)."""
    import matplotlib.pyplot as plt
    fig = corridor_figure(d, mc, exact, labels)
    fig.savefig(out, dpi=110)
    plt.close(fig)


def corridor_figure(d, mc, exact=None, labels: Labels = Labels()):
    """Corridor with start and end, one realisation, the Monte Carlo mean path beside the
    oracle's exact mean, and the control signals of the realisation; in the phase plane of two
    states, or one state against time (`plot_axes`). `mc`: a run of the linear harness
    (`MonteCarloResult`) or of a [plant] model (`PlantRun`); `exact`: the oracle of
    ``d.table`` with its path, when the caller has it already; `labels`: the names drawn.
    Returns the matplotlib figure."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from stospline.oracle.evaluate import evaluate_table

    p = d.problem
    axes = plot_axes(p)
    exact = evaluate_table(p, d.table) if exact is None else exact
    if len(axes) == 1:
        return _plot_against_time(d, mc, exact, axes[0], plt, labels)
    ia, ib = axes
    last = p.knots[-1].constraint
    end = None if last is None or last.is_band else last.value
    fig, axs = plt.subplots(2, 2, figsize=(10, 8.5))
    (a_setup, a_real), (a_mean, a_u) = axs
    for ax, title in ((a_setup, "start and goal"), (a_real, f"one realisation ({labels.run})"),
                      (a_mean, f"mean path ({mc.paths} paths)")):
        _walls(ax, p)
        ax.plot(p.x0[ia], p.x0[ib], "o", color="tab:green", ms=8, label="start")
        if end is not None and len(end) == p.n:
            ax.plot(end[ia], end[ib], "s", color="tab:red", ms=8, label="goal")
        ax.set_aspect("equal")
        ax.set_title(title)
        ax.grid(alpha=0.3)
    a_setup.legend(loc="upper left")
    a_real.plot(mc.sample_x[:, ia], mc.sample_x[:, ib], color="tab:blue", lw=1)
    _exiting_paths(a_real, mc, ia, ib)
    a_mean.plot(mc.mean_x[:, ia], mc.mean_x[:, ib], color="tab:blue", lw=2, label=labels.run)
    a_mean.plot(exact.path_mean[:, ia], exact.path_mean[:, ib], "--", color="tab:orange",
                lw=1.5, label=f"{labels.oracle} (exact)")
    angle = np.linspace(0.0, 2 * np.pi, 73)
    for k, kn in enumerate(p.knots):
        a_mean.plot(exact.knot_mean[k][ia], exact.knot_mean[k][ib], "k+", ms=10)
        # The knot's 2-sd covariance ellipse in the plotted plane (oracle, exact).
        cov = exact.knot_cov[k][np.ix_([ia, ib], [ia, ib])]
        w, vec = np.linalg.eigh(cov)
        ring = vec @ (2 * np.sqrt(np.maximum(w, 0.0))[:, None] * np.vstack([np.cos(angle),
                                                                           np.sin(angle)]))
        a_mean.plot(exact.knot_mean[k][ia] + ring[0], exact.knot_mean[k][ib] + ring[1],
                    color="0.3", lw=0.8, label="knot covariance, 2 sd" if k == 0 else None)
    a_mean.legend(loc="upper left", fontsize=8)
    return _controls_and_title(d, mc, a_u, fig, labels)


def _exiting_paths(ax, mc, ia: int, ib: int, most: int = 20) -> None:
    """The recorded paths that leave a corridor (`mc.record_exit_tick`), in red up to their exit,
    with the exit point marked: the realisations a corridor report is about. A run that
    records no paths (a model's) has none."""
    if getattr(mc, "record_exit_tick", None) is None or getattr(mc, "record_x", None) is None:
        return
    ticks = mc.record_exit_tick
    kept = ticks.shape[1]
    first = np.where(ticks >= 0, ticks, np.iinfo(np.int32).max)
    first = first.min(axis=0)
    out = np.flatnonzero(first < np.iinfo(np.int32).max)
    for q in out[:most]:
        j = int(first[q])
        ax.plot(mc.record_x[:j + 1, q, ia], mc.record_x[:j + 1, q, ib], color="tab:red",
                lw=0.6, alpha=0.7)
        ax.plot(mc.record_x[j, q, ia], mc.record_x[j, q, ib], "x", color="tab:red", ms=5)
    ax.set_title(f"one realisation; {len(out)} of the {kept} recorded paths leave a corridor "
                 f"(red, {min(len(out), most)} drawn to their exit)", fontsize=9)


def _controls_and_title(d, mc, a_u, fig, labels: Labels):
    """The controls of the realisation with the stage starts, and the title: `fig`, laid
    out."""
    p = d.problem
    styles = ["-", "--", ":", "-."]
    for i in range(mc.sample_u.shape[1]):
        a_u.plot(mc.sample_t[:-1], mc.sample_u[:, i], styles[i % 4], color="k", lw=1,
                 label=f"u{i + 1}")
    for kn in p.knots[:-1]:
        a_u.axvline(kn.t, color="0.6", lw=0.8)
    a_u.set_xlabel("t [s]")
    a_u.set_title("control signals of the realisation")
    a_u.legend()
    a_u.grid(alpha=0.3)
    fig.suptitle(labels.title or f"{p.name}: J0 = {d.design.J0:.4g}, MC mean cost "
                                 f"{mc.cost_mean_ci(0.95)[0]:.4g} ± "
                                 f"{mc.cost_mean_ci(0.95)[1]:.2g}")
    fig.tight_layout()
    return fig


def _plot_against_time(d, mc, exact, i: int, plt, labels: Labels):
    """One state against time: a realisation, the Monte Carlo mean beside the oracle's mean
    with its +-2 standard deviation band, the knots' targets, and the controls."""
    p = d.problem
    fig, (a_x, a_u) = plt.subplots(2, 1, figsize=(9, 7.5), sharex=True)
    t = mc.sample_t
    sd = np.sqrt(exact.path_var[:, i])
    a_x.fill_between(exact.path_t, exact.path_mean[:, i] - 2 * sd,
                     exact.path_mean[:, i] + 2 * sd, color="tab:orange", alpha=0.2,
                     label=f"{labels.oracle}: mean +- 2 sd")
    a_x.plot(t, mc.sample_x[:, i], color="0.5", lw=0.8, label="one realisation")
    a_x.plot(t, mc.mean_x[:, i], color="tab:blue", lw=2,
             label=f"{labels.run}: mean of {mc.paths} paths")
    a_x.plot(exact.path_t, exact.path_mean[:, i], "--", color="tab:orange", lw=1.5,
             label=f"{labels.oracle}: mean (exact)")
    for k, kn in enumerate(p.knots):
        a_x.plot(kn.t, exact.knot_mean[k][i], "k+", ms=10)
    a_x.set_ylabel(f"x{i}")
    a_x.legend(loc="best", fontsize=8)
    a_x.grid(alpha=0.3)
    for kn in p.knots[:-1]:
        a_x.axvline(kn.t, color="0.6", lw=0.8)
    return _controls_and_title(d, mc, a_u, fig, labels)
