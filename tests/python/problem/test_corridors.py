"""``[[corridors]]``: parsing, every bad value named by its field, the write-back, the wall
attribution, and the robot example's corridor against its drawn walls."""
import tomllib

import numpy as np
import pytest

from stospline.cli import main
from stospline.problem import ProblemError, parse_problem
from stospline.problem.corridors import corridor_ticks

from support.problems import BASE

GOOD = """
[[corridors]]
t = [0.0, 2.0]
C = [[1, 0], [0, 1]]
polygons = [{ A = [[1, 0], [-1, 0]], b = [1.2, 0.2] }, { A = [[0, 1]], b = [0.5] }]
epsilon = 0.05
"""


def parsed(extra: str):
    return parse_problem(tomllib.loads(BASE + extra))


def test_parses_and_writes_back():
    p = parsed(GOOD)
    (c,) = p.corridors
    assert c.t == (0.0, 2.0) and c.p == 2 and c.epsilon == 0.05
    assert [A.shape for A, _ in c.polygons] == [(2, 2), (1, 2)]
    assert list(c.row_start) == [0, 2, 3]
    assert corridor_ticks(c, p.t0, p.tick_hz) == (0, 20)
    back = parse_problem(tomllib.loads(p.to_toml())).corridors
    assert len(back) == 1 and back[0].t == c.t and back[0].epsilon == c.epsilon
    for (A, b), (A2, b2) in zip(c.polygons, back[0].polygons):
        assert np.array_equal(A, A2) and np.array_equal(b, b2)
    assert parsed("").corridors == ()


BAD = [
    ("t = [0.0, 2.0]", "t = [0.0, 3.0]", "corridors[0].t", "<= 2"),
    ("t = [0.0, 2.0]", "t = [0.05, 2.0]", "corridors[0].t", "whole number of ticks"),
    ("t = [0.0, 2.0]", "t = [1.5, 1.0]", "corridors[0].t", "start <= end"),
    ("C = [[1, 0], [0, 1]]", "C = [[1, 0, 0]]", "corridors[0].C", "expected 2"),
    ("b = [1.2, 0.2]", "b = [1.2]", "corridors[0].polygons[0].b", "expected 2"),
    ("A = [[0, 1]]", "A = [[0, 0]]", "corridors[0].polygons[1].A[0]", "all zeros"),
    ("A = [[0, 1]]", "A = [[1]]", "corridors[0].polygons[1].A", "expected 2"),
    ("b = [0.5] }", "b = [0.5], c = 1 }", "corridors[0].polygons[1].c", "unknown key"),
    ("epsilon = 0.05", "epsilon = 1.0", "corridors[0].epsilon", "(0, 1)"),
    ("epsilon = 0.05", "epsilon = nan", "corridors[0].epsilon", "finite"),
    ("epsilon = 0.05", "epsilon = \"1%\"", "corridors[0].epsilon", "number"),
    ("epsilon = 0.05", "eps = 0.05", "corridors[0].eps", "did you mean 'epsilon'"),
    ("polygons = [{ A = [[1, 0], [-1, 0]], b = [1.2, 0.2] }, { A = [[0, 1]], b = [0.5] }]",
     "polygons = []", "corridors[0].polygons", "non-empty"),
    ("C = [[1, 0], [0, 1]]\n", "", "corridors[0].C", "is required"),
]


@pytest.mark.parametrize("old,new,field,reason", BAD, ids=[b[2] + ":" + b[3] for b in BAD])
def test_bad_values_name_the_field(old, new, field, reason):
    assert old in GOOD
    with pytest.raises(ProblemError) as err:
        parsed(GOOD.replace(old, new))
    assert err.value.field == field and reason in err.value.reason, str(err.value)


def test_not_an_array_of_tables():
    doc = tomllib.loads(BASE)
    doc["corridors"] = 3
    with pytest.raises(ProblemError) as err:
        parse_problem(doc)
    assert err.value.field == "corridors"


def test_cli_exits_2(tmp_path, capsys):
    f = tmp_path / "bad.toml"
    f.write_text(BASE + GOOD.replace("epsilon = 0.05", "epsilon = -1"))
    assert main(["design", str(f), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "corridors[0].epsilon: must be a probability in (0, 1)" in err
    assert not (tmp_path / "out").exists()


def test_wall_attribution():
    p = parsed(GOOD)
    (c,) = p.corridors
    Y = np.array([[1.0, 3.0], [1.3, 0.0], [1.3, 0.7], [1.3, 0.55], [-0.5, 0.9]])
    # inside polygon 0; inside polygon 1; 0.1 past x <= 1.2 (wall 0), 0.2 past y <= 0.5;
    # 0.1 past x <= 1.2, 0.05 past y <= 0.5 (wall 2); 0.3 past x >= -0.2 (wall 1), 0.4 past y.
    assert list(c.exit_wall(Y)) == [-1, -1, 0, 2, 1]


def test_robot_corridor_matches_the_drawn_walls(robot_problem):
    """Points just inside and just outside each drawn wall segment are classified so."""
    (c,) = robot_problem.corridors
    assert c.t == (0.0, 6.0) and np.array_equal(c.C, [[1, 0, 0, 0], [0, 0, 1, 0]])
    for wall in robot_problem.plot["walls"]:
        for (x0, y0), (x1, y1) in zip(wall[:-1], wall[1:]):
            for s in np.linspace(0.05, 0.95, 7):
                pt = np.array([x0 + s * (x1 - x0), y0 + s * (y1 - y0)])
                normal = np.array([y1 - y0, x0 - x1]) / np.hypot(x1 - x0, y1 - y0)
                a, b = pt + 1e-3 * normal, pt - 1e-3 * normal
                inside = (c.exit_wall(a) < 0)[0], (c.exit_wall(b) < 0)[0]
                assert inside[0] != inside[1], (wall, pt)
    assert (c.exit_wall(np.array([[-5.0, 1.0], [-1.0, 5.0], [-1.0, 1.0]])) < 0).all()
