"""One budget for everything: corridors, worker processes, the tick-grid QP and the library.

Each run beyond the limits is refused before any work, in one line naming the key that costs
most (exit status 2 on the command line, BudgetError in the library).
"""
import subprocess
import sys
import tomllib

import numpy as np
import pytest

import stospline
from conftest import EXAMPLES
from stospline import budget
from stospline.budget import BudgetError
from stospline.pipeline import simulation_estimate
from stospline.problem.reader import parse_problem


def robot_corridors(count: int) -> str:
    """The robot with its corridor repeated `count` times."""
    text = (EXAMPLES / "robot_corridor.toml").read_text()
    i = text.index("[[corridors]]")
    return text[:i] + text[i:] * count


def cli(tmp_path, text, *args):
    src = tmp_path / "p.toml"
    src.write_text(text)
    return subprocess.run([sys.executable, "-m", "stospline", args[0], str(src), *args[1:],
                           "--quiet"], capture_output=True, text=True, timeout=120)


def refused(r, key: str) -> str:
    """The run was refused in one line naming `key`; that line."""
    assert r.returncode == 2 and r.stdout == "", (r.returncode, r.stderr)
    lines = r.stderr.splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert f": {key}: " in lines[0], lines[0]
    return lines[0]


def test_corridors_are_counted_and_named(tmp_path):
    """3 000 corridors over 2 000 paths: the paths' exit watch alone is ~30 min."""
    line = refused(cli(tmp_path, robot_corridors(3000), "simulate", "--paths", "2000"),
                   "corridors")
    assert "3000 corridors (18000 walls)" in line


def test_corridor_terms_grow_with_the_corridors():
    one, many = (parse_problem(tomllib.loads(robot_corridors(k))) for k in (1, 300))
    e1, e300 = (budget.estimate(p, command="simulate", paths=2000) for p in (one, many))

    def watch(e):
        return sum(t.seconds for t in e.terms if t.what.startswith("the paths' exit watch"))
    assert watch(e300) == pytest.approx(300 * watch(e1), rel=0.05)
    assert e300.seconds > 120 > e1.seconds


def test_forced_workers_are_counted_in_memory(tmp_path):
    line = refused(cli(tmp_path, robot_corridors(1), "simulate", "--paths", "600000",
                       "--workers", "1024", "--force-workers", "--max-memory", "1",
                       "--max-time", "1e6"), "--workers")
    assert "1024 Monte Carlo worker processes" in line


def test_workers_beyond_the_cores_are_limited_with_a_note(tmp_path):
    from stospline.harness.montecarlo import default_workers, usable_workers
    cores = default_workers()
    assert usable_workers(1024) == cores and usable_workers(1024, force=True) == 1024
    assert usable_workers(None) == cores and usable_workers(1) == 1
    r = cli(tmp_path, robot_corridors(1), "simulate", "--paths", "20", "--workers", "1024",
            "--substeps", "1")
    assert r.returncode == 0, r.stderr
    assert f"--workers 1024 limited to the {cores} cores" in r.stderr


def test_library_simulation_has_the_budget(robot_zoh):
    """A billion paths through the library: refused at once naming `paths`, for its time (its
    memory does not grow with the paths)."""
    with pytest.raises(BudgetError) as exc:
        stospline.simulate_problem(robot_zoh, paths=10 ** 9, seed=0)
    assert exc.value.field == "paths" and "max_time raises it" in str(exc.value)
    flat = simulation_estimate(robot_zoh, paths=10 ** 9, substeps=1, workers=2)
    assert flat.bytes == simulation_estimate(robot_zoh, paths=10 ** 4, substeps=1,
                                             workers=2).bytes < 1024 ** 3
    with pytest.raises(BudgetError) as exc:
        stospline.simulate_problem(robot_zoh, paths=20_000, seed=0, max_time=1)
    assert exc.value.field == "paths" and "max_time raises it" in str(exc.value)
    with pytest.raises(BudgetError) as exc:
        stospline.simulate_problem(robot_zoh, paths=600_000, seed=0, workers=1024,
                                   force_workers=True, max_time=1e9)
    assert exc.value.field == "workers"


@pytest.mark.parametrize("bad", [0, -1, float("nan"), "4", True, 1e7])
def test_library_limits_are_checked(robot_zoh, bad):
    with pytest.raises(stospline.ProblemError) as exc:
        stospline.simulate_problem(robot_zoh, paths=10, seed=0, max_memory=bad)
    assert exc.value.field == "max_memory"


def test_library_design_has_the_budget():
    doc = tomllib.loads((EXAMPLES / "robot_corridor.toml").read_text())
    with pytest.raises(BudgetError) as exc:
        stospline.design_problem(parse_problem({**doc, "tick_hz": 2_000_000}))
    assert exc.value.field == "tick_hz"
    with pytest.raises(BudgetError) as exc:
        stospline.design_problem(parse_problem(doc), max_time=0.5)
    assert exc.value.field == "max_time" and "--" not in str(exc.value)


def test_rows_between_ticks_are_counted():
    doc = tomllib.loads((EXAMPLES / "robot_monotone.toml").read_text())
    doc["tick_hz"] = 4000
    plain = budget.estimate(parse_problem(doc), mode="joint")
    region = doc["regions"][0]
    region.update(C=[[1, 0, 0, 0]], lower=[-6.0], upper=[-1.0], between_ticks=True)
    between = budget.estimate(parse_problem(doc), mode="joint")

    def qp(e):
        return next(t for t in e.terms if t.what.startswith("regions"))
    assert qp(between).seconds > 3 * qp(plain).seconds


@pytest.mark.parametrize("error", [
    MemoryError(), SystemError("gstrf was called with invalid arguments"),
    RuntimeError("SUPERLU_MALLOC fails for buf in intCalloc()")])
def test_superlu_out_of_memory_is_a_budget_error(monkeypatch, error):
    from scipy.sparse import identity
    from stospline.design import tick_qp

    def fail(M, *a, **k):
        raise error
    monkeypatch.setattr("scipy.sparse.linalg.splu", fail)
    with pytest.raises(BudgetError) as exc:
        tick_qp._lu(identity(3, format="csc"))
    assert exc.value.field == "tick_hz" and "ran out of memory" in str(exc.value)
    assert "\n" not in str(exc.value)


def test_a_singular_matrix_is_not_called_memory(monkeypatch):
    from scipy.sparse import identity
    from stospline.design import tick_qp

    def fail(M, *a, **k):
        raise RuntimeError("Factor is exactly singular")
    monkeypatch.setattr("scipy.sparse.linalg.splu", fail)
    with pytest.raises(RuntimeError, match="singular"):
        tick_qp._lu(identity(2, format="csc"))
