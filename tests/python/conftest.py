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
                   "robot_narrow_corridor")


def gains_stem(example: str) -> str:
    """The stem `stospline design` gives an example's files: <name>, or <name>_spline when
    the file's [design] table is "spline"."""
    import tomllib
    doc = tomllib.loads((EXAMPLES / f"{example}.toml").read_text())
    return example + ("_spline" if doc.get("design", {}).get("table") == "spline" else "")

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
