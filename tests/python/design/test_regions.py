"""[[regions]]: keeping the expected path inside a region over an interval, as bands on a
dense grid (the paper's open problem f(t) <= E y(t) <= g(t)), on the narrow-corridor robot."""
import tomllib

import numpy as np
import pytest

from stospline.oracle.evaluate import evaluate_table
from stospline.pipeline import design_problem
from stospline.problem import ProblemError, load_problem, parse_problem
from stospline.oracle.region_distance import distance_outside

from conftest import EXAMPLES

FILE = EXAMPLES / "robot_narrow_corridor.toml"


# The corridor's legs (its walls, as bounds on (x, y)); the file's bands keep 0.05 inside them.
LEGS = [(0.0, 3.0, [-np.inf, 0.5], [-0.5, 1.5]), (3.0, 6.0, [-1.5, 0.5], [-0.5, np.inf])]


def test_regions_expand_into_band_knots_merged_with_user_knots():
    p = load_problem(FILE)
    times = [kn.t for kn in p.knots]
    assert len(times) == 60 and times[-1] == 6.0 and 3.0 in times
    k3 = times.index(3.0)
    lo, hi = p.knots[k3].constraint.bounds
    assert p.knots[k3].constraint.C.shape[0] == 2 and lo[0] == hi[0] == 0.0
    assert p.knots[k3].penalty.weight == 7.0          # the user's knot kept its penalty
    assert all(p.stages[i] is p.stages[0] for i in range(len(times)))


def test_dense_bands_keep_expected_path_inside_at_every_tick():
    banded = load_problem(FILE)
    doc = tomllib.loads(FILE.read_text())
    doc.pop("regions")
    doc["knots"][0]["constraint"] = {"C": [[1, 0, 1, 0]], "value": [0.0]}
    free = parse_problem(doc)
    worst = {}
    for name, prob in (("banded", banded), ("free", free)):
        d = design_problem(prob, mode="joint")
        m = evaluate_table(prob, d.table)
        assert m.J == pytest.approx(d.design.J0, rel=1e-6)       # float32 table
        worst[name] = distance_outside(m.path_t, m.path_mean[:, [0, 2]], LEGS).max()
    assert worst["banded"] == 0.0
    assert worst["free"] > 0.01       # the unconstrained design cuts the corner


@pytest.mark.parametrize("edit, field", [
    (lambda r: r.update(t=[3.0, 2.0]), "regions[0].t"),
    (lambda r: r.update(every=0.0), "regions[0].every"),
    (lambda r: r.update(lower=[2.0, -6.0]), "regions[0].lower"),
    (lambda r: r.update(every=0.07), "regions[0].every"),      # off the 20 Hz tick grid
])
def test_bad_regions_are_rejected(edit, field):
    doc = tomllib.loads(FILE.read_text())
    edit(doc["regions"][0])
    with pytest.raises(ProblemError) as err:
        parse_problem(doc)
    assert err.value.field == field, str(err.value)
