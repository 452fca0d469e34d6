"""Band-constrained problems shared by the band designer's tests and the firmware band solver's."""
import tomllib

import numpy as np

from conftest import EXAMPLES
from stospline.problem import parse_problem


def random_band_problem(seed):
    rng = np.random.default_rng(seed)
    n, m = int(rng.integers(2, 4)), int(rng.integers(1, 3))
    A = rng.normal(size=(n, n)) * 0.5
    B = rng.normal(size=(n, m))
    G = rng.normal(size=(n, 2)) * 0.3
    knots = []
    for k, t in enumerate((1.0, 2.0)):
        rows = int(rng.integers(1, 3))
        C = rng.normal(size=(rows, n))
        mid = rng.normal(size=rows)
        width = rng.uniform(0.0, 0.6, size=rows) * (rng.random(rows) < 0.8)
        knots.append({"t": t, "constraint": {"C": C.tolist(), "lower": (mid - width).tolist(),
                                             "upper": (mid + width).tolist()},
                      "penalty": {"C": np.eye(n).tolist(), "target": [0.0] * n,
                                  "weight": float(rng.uniform(0, 2))}})
    return parse_problem({
        "name": "rnd", "x0": rng.normal(size=n).tolist(), "tick_hz": 10,
        "dynamics": {"A": A.tolist(), "B": B.tolist(),
                     "noise": [{"state": 0, "G": G.tolist()}]},
        "cost": {"R": (np.eye(m) * rng.uniform(0.5, 2)).tolist()},
        "knots": knots})


def robot_with_bands(tick_hz=50, rows=2):
    """The robot with E{x + y} in [-0.2, 0.2] (and, with rows=2, E{y} in [0, 1.2]) at t = 3."""
    doc = tomllib.loads((EXAMPLES / "robot_corridor.toml").read_text())
    doc["tick_hz"] = tick_hz
    doc["knots"][0]["constraint"] = {"C": [[1, 0, 1, 0], [0, 0, 1, 0]][:rows],
                                     "lower": [-0.2, 0.0][:rows], "upper": [0.2, 1.2][:rows]}
    return parse_problem(doc)
