"""Work is bounded and announced (and MemoryError is one line, not a traceback).

Before: ``tick_hz = 10^9`` over 1 s or n = 200 died in MemoryError asking for 15-193 GiB;
10^7 ticks, 20 000 knots and a region grid of 200 000 points ran past 120 s with no progress
and no way to know how long. Now `stospline.budget` estimates memory and time from the sizes
before anything is allocated, refuses what exceeds the limits with one line naming the key
and the estimate, and long runs show progress bars on a terminal.
"""
import dataclasses
import io
import subprocess
import sys
import time

import numpy as np
import pytest

from conftest import EXAMPLES
from stospline import budget, progress
from stospline.cli import main


def cart(n=2, hz=10, knots=((1.0, True),), mode="stagewise", regions="") -> str:
    """A chain of n integrators (one input) with the given knots (t, constrained?)."""
    A = np.eye(n, k=1).tolist()
    B = np.zeros((n, 1))
    B[-1] = 1
    C = np.eye(n)[:1].tolist()
    lines = ['name = "big"', f"x0 = {[0.0] * n}", f"tick_hz = {hz}", f'[design]\nmode = "{mode}"',
             f"[dynamics]\nA = {A}\nB = {B.tolist()}", "[cost]\nR = [[1]]"]
    for t, con in knots:
        what = (f"constraint = {{ C = {C}, value = [1.0] }}" if con else
                f"penalty = {{ C = {C}, target = [1.0], weight = 1.0 }}")
        lines.append(f"[[knots]]\nt = {t!r}\n{what}")
    return "\n".join(lines) + "\n" + regions


def refuse(tmp_path, text, *extra, command="design"):
    """Run the CLI on `text`: it must refuse within seconds with one line, writing nothing."""
    src = tmp_path / "big.toml"
    src.write_text(text)
    out = tmp_path / "o"
    args = [command, str(src), *extra] + (["--out", str(out)] if command == "design" else [])
    t = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "stospline.cli", *args], capture_output=True,
                       text=True, timeout=300)
    elapsed = time.perf_counter() - t
    assert r.returncode == 2 and r.stdout == "", r.stderr
    assert r.stderr.count("\n") == 1 and "Traceback" not in r.stderr, r.stderr
    assert elapsed < 60, elapsed
    assert not out.exists()
    return r.stderr


def test_a_billion_ticks_is_refused_by_the_firmware_limit(tmp_path):
    """10^9 ticks: each array would exceed what a 32-bit target holds (limits.py), before
    any estimate."""
    err = refuse(tmp_path, cart(hz=10 ** 9))
    assert ": tick_hz: " in err and "32-bit target" in err


def test_thirty_million_ticks_is_refused_by_memory(tmp_path):
    """Within the firmware's limits, but the tables' C text alone needs more than 4 GiB."""
    err = refuse(tmp_path, cart(hz=3 * 10 ** 7))
    assert "tick_hz: the design needs ~" in err and "GiB of memory (limit 4 GiB" in err


def test_n_200_is_refused_naming_x0(tmp_path):
    err = refuse(tmp_path, cart(n=200))
    assert "error in" in err and ": x0: " in err and "n = 200 states" in err


def test_ten_million_ticks_is_refused_beyond_the_time_limit(tmp_path):
    """10^7 ticks fit in 4 GiB but take minutes: estimated beyond --max-time 60."""
    err = refuse(tmp_path, cart(hz=5 * 10 ** 6, knots=((1.0, True), (2.0, True))),
                 "--max-time", "60")
    assert ": tick_hz: the design would take ~" in err and "(limit 1 min;" in err


def test_too_many_paths_is_refused_naming_the_option(tmp_path):
    err = refuse(tmp_path, cart(), "--paths", str(10 ** 9), command="simulate")
    # the memory does not grow with the paths; the time does
    assert err.startswith("stospline: error: --paths: the simulate would take ~")


def test_region_grid_is_bounded_at_parse_time(tmp_path):
    """200 000 band points: refused while parsing (scanning every knot for every point would
    take hours), naming the region's grid spacing."""
    grid = ("[[regions]]\nt = [0.0, 1.0]\nevery = 5e-6\nC = [[0, 1]]\nlower = [-10.0]\n"
            "upper = [10.0]\n")
    err = refuse(tmp_path, cart(hz=200000, mode="joint", regions=grid))
    assert "regions[0].every: gives 199999 band points" in err


def test_region_grid_beyond_the_stage_limit_is_refused_fast():
    """10 000 band points would be 10 000 stages (the firmware takes 256): refused in seconds,
    before the points are merged into knots."""
    import tomllib
    from stospline.problem import ProblemError, parse_problem
    grid = ("[[regions]]\nt = [0.0, 1.0]\nevery = 1e-4\nC = [[0, 1]]\nlower = [-10.0]\n"
            "upper = [10.0]\n")
    t = time.perf_counter()
    with pytest.raises(ProblemError, match="regions"):
        parse_problem(tomllib.loads(cart(hz=10000, mode="joint", regions=grid)))
    assert time.perf_counter() - t < 20


@pytest.fixture(scope="module")
def small():
    import tomllib
    from stospline.problem import parse_problem
    return parse_problem(tomllib.loads(cart(knots=((1.0, True), (2.0, False)))))


def test_estimate_names_the_key_that_grows(small):
    """Stretch one size at a time (without the parser's limits): the largest term follows it."""
    many_knots = dataclasses.replace(small, knots=small.knots * 10000,
                                     stages=small.stages * 10000)
    many_knots = dataclasses.replace(many_knots, knots=tuple(
        dataclasses.replace(kn, t=0.1 * (i + 1)) for i, kn in enumerate(many_knots.knots)))
    est = budget.estimate(many_knots)
    assert est.top("seconds").key == "knots" and est.seconds > 120
    with pytest.raises(budget.BudgetError) as info:
        budget.check(many_knots, max_seconds=60)
    assert info.value.field == "knots" and "20000 stages" in info.value.reason
    fast = budget.estimate(dataclasses.replace(small, tick_hz=10 ** 6))
    assert fast.top("seconds").key == "tick_hz"


def test_estimate_grows_with_each_size(small):
    base = budget.estimate(small)
    for bigger, key in [(dataclasses.replace(small, tick_hz=1000), "tick_hz")]:
        est = budget.estimate(bigger)
        assert est.seconds > base.seconds and est.bytes > base.bytes, key
    sim = budget.estimate(small, command="simulate", paths=10 ** 6)
    assert sim.top("bytes").key == "--paths" and sim.seconds > base.seconds


def test_robot_estimate_is_plausible():
    """The robot (6000 ticks) designs in seconds and ~100 MiB here
    (tools/bench/calibrate_budget.py): the estimate must be of that order."""
    from stospline.problem import load_problem
    est = budget.estimate(load_problem(EXAMPLES / "robot_corridor.toml"))
    assert 1 < est.seconds < 30 and 50e6 < est.bytes < 1e9


def test_a_plant_model_run_is_estimated_at_the_model_loop_rate():
    """A Monte Carlo on a [plant] model runs its own loop in one process, several times
    slower per path-tick than the linear harness: its estimate is the model loop's
    (tools/bench/model_loop.py), whatever --workers says."""
    from stospline.problem import load_problem
    p = load_problem(EXAMPLES / "robot_corridor.toml")
    linear = budget.estimate(p, command="simulate", paths=10 ** 5, substeps=2, workers=2)
    model = budget.estimate(p, command="simulate", paths=10 ** 5, substeps=2, workers=2,
                            model=True)
    run = model.top("seconds")
    assert "[plant] model" in run.what
    T = int(np.sum(p.ticks_per_stage))
    assert run.seconds == pytest.approx(
        10 ** 5 * T * (budget.MODEL_PATH_TICK + 2 * budget.MODEL_PATH_STEP))
    assert model.seconds > 3 * linear.seconds


def test_a_sensor_run_is_estimated_at_the_sensor_loop_rate(tmp_path, capsys):
    """A [measurement] problem's Monte Carlo is the sensor loop, ~15x the full-state
    harness's CPU per path-tick on the robot (tools/bench/sensor_loop_rate.py): its estimate
    adds the sensor loop's own terms to the full state's, and exceeds the same problem's
    full-state estimate several times over (the full-state constants overstate its 28 ns
    per path-tick, so the ratio of the estimates is below the measured 15). corridor-design's
    bound follows: at --max-time 3000 the full-state estimate of a 10^6-path certification
    fits and the sensor loop's is refused, naming --certify, before any design."""
    from stospline import corridor_search as cs
    from stospline.harness.sensor_blocks import SENSOR_BLOCK_PATHS
    from stospline.problem import load_problem
    src = EXAMPLES / "robot_corridor_position_sensor.toml"
    p = load_problem(src)
    full = dataclasses.replace(p, measurement=None)
    paths, T = 10 ** 5, int(np.sum(p.ticks_per_stage))
    sensor, state = (budget.estimate(q, command="simulate", paths=paths, substeps=1, workers=2)
                     for q in (p, full))
    run, base = (next(t for t in e.terms if t.what.startswith("Monte Carlo"))
                 for e in (sensor, state))
    assert "sensor loop" in run.what and "sensor" not in base.what
    blocks = -(-paths // SENSOR_BLOCK_PATHS)
    c_work = base.seconds - (budget.SIM_TICK * T + budget.SIM_BLOCK) * -(-paths // 512)
    assert run.seconds == pytest.approx(
        (budget.SENSOR_TICK * T + budget.SIM_BLOCK) * blocks
        + budget.SENSOR_PATH_TICK * paths * T + c_work)
    assert run.seconds > 3 * base.seconds
    counts = dict(grid=1, search_paths=10000, certify_paths=10 ** 6, workers=2)
    assert cs.work_estimate(full, **counts).seconds < 3000 < cs.work_estimate(p, **counts).seconds
    out = tmp_path / "o"
    assert main(["corridor-design", str(src), "--strip", "40", "--rate", "5", "--search",
                 "10000", "--certify", "1000000", "--max-time", "3000", "--out",
                 str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--certify" in err[0], err
    assert not out.exists()


def test_a_plant_model_run_holds_every_path():
    """The model's loop keeps every path in memory: the docs' linear model grew by 2.2 kB per
    path from 10^4 to 2.10^5 paths (max RSS of `stospline simulate --substeps 4`), and the
    estimate grows by at least that."""
    from stospline.cli import load_problem
    import tempfile
    from pathlib import Path
    from support.plant_sources import LINEAR, LINEAR_TOML
    with tempfile.TemporaryDirectory() as where:
        (Path(where) / "model.c").write_text(LINEAR)
        (Path(where) / "p.toml").write_text(LINEAR_TOML)
        p = load_problem(Path(where) / "p.toml")
    small, big = (budget.estimate(p, command="simulate", paths=paths, substeps=4, model=True)
                  for paths in (10 ** 4, 2 * 10 ** 5))
    assert big.bytes - small.bytes >= 1.9e5 * 2.2e3
    assert big.top("bytes").what.startswith("Monte Carlo on the [plant] model")


def test_a_long_model_run_is_refused_before_it_starts(tmp_path):
    """`simulate` on the unicycle model with 10^5 paths: ~11 min at the model loop's rate,
    refused at --max-time 60 naming --paths."""
    import shutil
    for name in ("robot_unicycle.toml", "unicycle.c"):
        shutil.copy(EXAMPLES / "nonlinear" / name, tmp_path / name)
    r = subprocess.run([sys.executable, "-m", "stospline.cli", "simulate",
                        str(tmp_path / "robot_unicycle.toml"), "--paths", "100000",
                        "--substeps", "2", "--max-time", "60"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and r.stdout == "", r.stderr
    assert "--paths" in r.stderr and "[plant] model" in r.stderr, r.stderr


class _Tty(io.StringIO):
    def isatty(self):
        return True


@pytest.mark.parametrize("quiet", [False, True])
def test_progress_on_a_terminal_unless_quiet(tmp_path, monkeypatch, quiet):
    monkeypatch.setattr(progress, "DELAY", 0.0)
    err = _Tty()
    monkeypatch.setattr(sys, "stderr", err)
    argv = ["design", str(EXAMPLES / "robot_corridor.toml"), "--out", str(tmp_path)]
    assert main(argv + (["--quiet"] if quiet else [])) == 0
    text = err.getvalue()
    if quiet:
        assert text == ""
    else:
        assert "design" in text and "oracle" in text and "tick" in text
    assert not progress.enabled() or not quiet


def test_no_progress_when_stderr_is_not_a_terminal(tmp_path, monkeypatch):
    monkeypatch.setattr(progress, "DELAY", 0.0)
    err = io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    assert main(["design", str(EXAMPLES / "robot_corridor.toml"), "--out", str(tmp_path)]) == 0
    assert err.getvalue() == ""
