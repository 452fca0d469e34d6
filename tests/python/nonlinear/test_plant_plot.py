"""``stospline plot`` of a [plant] problem draws the Monte Carlo on the model itself beside the
oracle of the linearisation, and says so: the figure's lines are the model run's mean path
(`run_on_model`, the same paths, seed and substeps; ``auto`` decided on the model) and the
oracle's; with faults, the fault oracle and the faults are named; a fault the model cannot
take is refused in one line, exit 2, nothing written."""
import numpy as np
import pytest
from conftest import EXAMPLES

import stospline.report.plot as plot_module
from stospline.cli import main
from stospline.nonlinear.iterate import fit_plant
from stospline.nonlinear.simulate import run_on_model
from stospline.pipeline import design_problem
from stospline.problem.faults import parse_faults
from stospline.problem.toml_writer import document_to_toml
from stospline.report.plot import oracle_with_path
from support.plant_sources import LINEAR, linear_doc

RUN, ORACLE = "Monte Carlo on the [plant] model", "oracle of the linearisation"


@pytest.fixture
def figures(monkeypatch):
    """The figures `plot` draws, kept for the test to read."""
    drawn = []
    original = plot_module.corridor_figure

    def keep(*args, **kwargs):
        drawn.append(original(*args, **kwargs))
        return drawn[-1]
    monkeypatch.setattr(plot_module, "corridor_figure", keep)
    return drawn


def _mean_panel(fig):
    return next(ax for ax in fig.axes if ax.get_title().startswith("mean path"))


def _line(ax, label: str):
    return next(line for line in ax.get_lines() if line.get_label() == label)


def test_the_unicycle_plot_is_the_model_run(tmp_path, figures):
    out = tmp_path / "u.png"
    assert main(["plot", str(EXAMPLES / "nonlinear" / "robot_unicycle.toml"), "--paths", "8",
                 "--seed", "3", "--substeps", "1", "--out", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    (fig,) = figures
    title = fig._suptitle.get_text()
    assert title.startswith(f"robot_unicycle: {RUN} (8 paths, 1 substeps") and ORACLE in title
    assert "MC mean cost" not in title
    ax = _mean_panel(fig)
    assert {RUN, f"{ORACLE} (exact)"} <= {t.get_text() for t in ax.get_legend().get_texts()}
    assert any(RUN in a.get_title() for a in fig.axes)        # the realisation's panel
    assert _line(ax, RUN).get_xdata().size == 6001            # every tick, t = 0 .. 6 s


def test_the_lines_are_the_model_run_and_the_fault_oracle(tmp_path, figures):
    (tmp_path / "model.c").write_text(LINEAR)
    doc = linear_doc()
    (tmp_path / "p.toml").write_text(document_to_toml(doc))
    out = tmp_path / "f.svg"
    assert main(["plot", str(tmp_path / "p.toml"), "--paths", "50", "--seed", "4",
                 "--substeps", "auto", "--fault", "delay_ticks=1", "--out", str(out)]) == 0
    assert out.stat().st_size > 0
    (fig,) = figures
    title = fig._suptitle.get_text()
    assert "faults around the model: delay_ticks=1" in title
    problem, fit = fit_plant(doc, tmp_path)
    faults = parse_faults({"delay_ticks": 1}, 2, 1)
    d = design_problem(problem)
    r = run_on_model(d, fit.model, paths=50, seed=4, substeps="auto", faults=faults)
    assert r.choice is not None and f"{r.run.substeps} substeps per tick" in title
    ax = _mean_panel(fig)
    np.testing.assert_allclose(_line(ax, RUN).get_ydata(), r.run.mean_x[:, 1], rtol=1e-12)
    oracle = oracle_with_path(d, faults)
    drawn = _line(ax, f"fault {ORACLE} (exact)").get_ydata()
    np.testing.assert_allclose(drawn, oracle.path_mean[:, 1], rtol=1e-12)
    # The fault oracle, not the fault-free one: the delay moves the predicted path.
    assert not np.allclose(drawn, oracle_with_path(d, parse_faults({}, 2, 1)).path_mean[:, 1])


@pytest.mark.parametrize("argv, field", [
    (["--fault", "plant_B_scale=0.9"], "--fault plant_B_scale"),
    (["--fault", "sensor_noise=-1"], "--fault sensor_noise"),
])
def test_bad_inputs_are_refused_before_any_run(tmp_path, capsys, argv, field):
    (tmp_path / "model.c").write_text(LINEAR)
    (tmp_path / "p.toml").write_text(document_to_toml(linear_doc()))
    out = tmp_path / "f.png"
    rc = main(["plot", str(tmp_path / "p.toml"), "--paths", "20", "--out", str(out)] + argv)
    err = capsys.readouterr().err
    assert rc == 2 and f": {field}:" in err and len(err.strip().splitlines()) == 1
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["model.c",
                                                                                "p.toml"]
