"""Noise-free limit: the design for y'' = u through points is the clamped/natural cubic spline."""
import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from stospline.design.continuous import design_continuous
from stospline.oracle.evaluate import evaluate_continuous
from stospline.problem import parse_problem


def spline_problem(times, values, y0, v0):
    return parse_problem({
        "name": "spline", "t0": 0.0, "x0": [y0, v0], "tick_hz": 10,
        "dynamics": {"A": [[0.0, 1.0], [0.0, 0.0]], "B": [[0.0], [1.0]]},
        "cost": {"R": [[1.0]]},
        "knots": [{"t": t, "constraint": {"C": [[1.0, 0.0]], "value": [v]}}
                  for t, v in zip(times, values)],
    })


@pytest.mark.parametrize("times, values, v0", [
    ([1.0, 2.0, 3.0, 4.0], [1.0, -0.5, 2.0, 0.0], 0.5),
    ([0.5, 1.7, 2.0, 3.6, 5.0], [0.3, 1.0, 0.8, -1.2, 0.4], -1.0),
])
def test_noise_free_design_is_the_clamped_natural_cubic_spline(times, values, v0):
    y0 = 0.2
    problem = spline_problem(times, values, y0, v0)
    design = design_continuous(problem)
    m = evaluate_continuous(problem, design, points_per_stage=41)
    ref = CubicSpline([0.0] + times, [y0] + values, bc_type=((1, v0), (2, 0.0)))
    np.testing.assert_allclose(m.path_mean[:, 0], ref(m.path_t), rtol=0, atol=1e-8)
    np.testing.assert_allclose(m.path_mean[:, 1], ref(m.path_t, 1), rtol=0, atol=1e-8)
    # The optimal cost is the spline's energy: y'' is linear on each piece, so
    # integral of y''^2 over a piece of length h is h (a^2 + a b + b^2) / 3.
    breaks = np.array([0.0] + times)
    a, b = ref(breaks[:-1], 2), ref(breaks[1:], 2)
    energy = float(np.sum(np.diff(breaks) * (a * a + a * b + b * b) / 3))
    assert design.J0 == pytest.approx(energy, rel=1e-9)
