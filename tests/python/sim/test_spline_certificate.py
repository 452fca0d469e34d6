"""The spline certificate (`stospline.refine.spline_certificate.certificate`) measures the spline
against the per-tick law it compresses: the design's gains at the ticks in double precision
(`table_of(design, quantize=False)`). For a zero-order-hold design that is the design's own
law; for a continuous-time design it is the sampled law, not the continuous one, whose
difference (8e-4 of the robot's cost) is the cost of sampling, not of the spline."""
import pytest

import stospline
from stospline.oracle.evaluate import evaluate_table
from stospline.refine.spline_certificate import _cov_change
from stospline.table.format import table_of


def _relative(a, b):
    return (a - b) / abs(b)


@pytest.mark.parametrize("discretization", ["continuous", "exact-zoh"])
def test_the_excess_is_over_the_sampled_table_the_spline_compresses(robot_problem,
                                                                     discretization):
    d = stospline.design_problem(robot_problem, discretization=discretization,
                                 table="spline")
    cert, J = d.certificate, d.implemented.J
    sampled = evaluate_table(robot_problem, table_of(d.design, quantize=False), path=False)
    assert cert["excess_over_law"] == _relative(J, sampled.J)
    assert cert["knot_cov_change"] == _cov_change(sampled, d.implemented)
    assert cert["excess_over_J0"] == _relative(J, d.design.J0)    # unchanged: over J0
    if discretization == "continuous":
        # The continuous law is cheaper by the cost of sampling; the certificate does not
        # count it against the spline (against the continuous law it would be 8.4e-4).
        assert _relative(J, d.law.J) > 5e-4
        # What is left: the re-solved latch meets the knot constraints that the sampled
        # table's latch misses by its sampling error (6.7e-4), at -5.9e-5 of the cost.
        assert abs(cert["excess_over_law"]) < 1e-4
    else:
        assert sampled.J == d.law.J and abs(cert["excess_over_law"]) < 1e-7
