"""The centre-line knob of `design.corridor_design`: strips of a polygon, the stage polygons
of the robot's mean path, and the running cost it adds."""
import numpy as np

from stospline.design.corridor_design import stage_polygons, strip_weights_problem, strips
from stospline.pipeline import design_problem
from stospline.oracle.exit_bound import corridor_outputs


def test_strips_pair_opposite_walls():
    A = np.array([[0.0, -1.0], [0.0, 2.0], [1.0, 0.0]])
    b = np.array([0.0, 4.0, 0.0])                  # 0 <= y <= 2 (scaled), x <= 0
    ((a, c),) = strips(A, b)
    np.testing.assert_allclose(a, [0, -1])
    assert c == -1.0                                # -y = -1: the centre line y = 1


def test_robot_stages_and_cost(robot_problem, robot_zoh):
    p = robot_problem
    (c,) = p.corridors
    ((ym, _),) = corridor_outputs(p, robot_zoh.table)
    polys = stage_polygons(p, c, ym)
    assert polys == [0, 1]                          # the horizontal leg, then the vertical
    q = strip_weights_problem(p, c, polys, 5.0)
    x = np.array([-3.0, 0.7, 1.5, -0.2])
    for k, (want_dy, want_dx) in enumerate(((0.5, 0.0), (0.0, 2.0))):
        st, base = q.stages[k], p.stages[k]
        extra = x @ (st.Q - base.Q) @ x + 2 * (st.q - base.q) @ x + st.rho - base.rho
        assert np.isclose(extra, 5.0 * (want_dy ** 2 + want_dx ** 2))
    r = strip_weights_problem(p, c, polys, 0.0, rate_weight=3.0)
    extra = x @ (r.stages[0].Q - p.stages[0].Q) @ x
    assert np.isclose(extra, 3.0 * (0.7 ** 2 + 0.2 ** 2))      # the velocities (x', y')
    d = design_problem(q)
    assert d.implemented.J > robot_zoh.implemented.J   # in its own cost, with the extra term
