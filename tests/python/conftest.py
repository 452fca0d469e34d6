import os
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
EXAMPLES = REPO / "examples"
GAINS = REPO / "gains"
# Examples whose spline tables (`--table spline`, <name>_spline.*) are shipped beside the
# per-tick ones (tools/regen_gains.sh).
SPLINE_EXAMPLES = ("robot_corridor", "robot_corridor_eps01", "robot_bands", "investment",
                   "quadrotor", "population", "coupled_axes", "robot_monotone",
                   "robot_narrow_corridor", "robot_position_sensor")


def gains_stem(example: str) -> str:
    """The stem `stospline design` gives an example's files: <name>, or <name>_spline when
    the file's [design] table is "spline"."""
    import tomllib
    doc = tomllib.loads((EXAMPLES / f"{example}.toml").read_text())
    return example + ("_spline" if doc.get("design", {}).get("table") == "spline" else "")

# The files with the longest tests (seconds of one xdist worker, measured), longest first.
# tools/test.sh runs pytest with `--dist loadfile --no-loadscope-reorder`: the workers take
# these first, then the other files by their number of tests (xdist's own order), so that they
# end on short files together instead of one worker running a long file alone at the end.
LONGEST_FILES = (
    # gains/ regenerated in full, three times and four times (in subprocesses): a worker each
    "tests/python/table/test_gains_regenerate_elsewhere_blas.py",
    "tests/python/table/test_gains_regenerate_elsewhere.py",
    "tests/python/sim/test_qspline_monte_carlo.py",
    "tests/python/cli/test_corridor_design_command.py",
    "tests/python/board/test_board_hil.py",
    "tests/python/package/test_library_doc.py",
    "tests/python/package/test_wheel_install.py",
    "tests/python/board/test_board_microbit.py",
    "tests/python/cli/test_hostile_inputs.py",
    "tests/python/package/test_import_graph.py",
    "tests/python/cli/test_cli_end_to_end.py",
    "tests/python/cli/test_report.py",
    "tests/python/cli/test_budget_vs_measured.py",
)
_missing = [f for f in LONGEST_FILES if not (REPO / f).is_file()]
if _missing:
    raise pytest.UsageError(f"tests/python/conftest.py: LONGEST_FILES: no file {_missing[0]}")


@pytest.hookimpl(trylast=True)             # after pytest's own reordering within files
def pytest_collection_modifyitems(config, items):
    """`LONGEST_FILES` first, in that order, then the other files by their number of tests,
    most first; each file's tests stay together and in order."""
    def file_of(item):
        return item.nodeid.split("::", 1)[0]
    count = {}
    for item in items:
        count[file_of(item)] = count.get(file_of(item), 0) + 1
    rank = {f: i for i, f in enumerate(LONGEST_FILES)}
    items.sort(key=lambda item: (rank.get(file_of(item), len(rank)), -count[file_of(item)]))


# cffi builds go to the repository's build tree, never to the user's cache (~/.cache), also in
# the CLI subprocesses the tests start (they inherit the environment).
os.environ.setdefault("STOSPLINE_CACHE_DIR", str(REPO / "build" / "cffi"))


@pytest.fixture(scope="session")
def robot_problem():
    from stospline.problem import load_problem
    return load_problem(EXAMPLES / "robot_corridor.toml")


@pytest.fixture(scope="session")
def robot(robot_problem):
    """The continuous-time robot design, sampled at 1 kHz, evaluated by the oracle."""
    from stospline.pipeline import design_problem
    return design_problem(robot_problem, discretization="continuous")


@pytest.fixture(scope="session")
def robot_zoh(robot_problem):
    """The default product: the exact zero-order-hold design at 1 kHz."""
    from stospline.pipeline import design_problem
    return design_problem(robot_problem)


@pytest.fixture(scope="session")
def robot_controller(robot, tmp_path_factory):
    from stospline.harness.controller import build_controller
    return build_controller(robot.table)
