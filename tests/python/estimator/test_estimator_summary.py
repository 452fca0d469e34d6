"""The design summary's ``estimator`` entry: present with a [measurement] table (the estimator
loop's exact cost and knot moments), absent without one, and a reason for a table the
estimator loop cannot run."""
import copy

import numpy as np
import pytest
from test_estimator_oracle import DOC

from stospline.estimator.oracle import evaluate_estimator
from stospline.pipeline import design_problem, design_summary
from stospline.problem.reader import parse_problem
from stospline.strict import dumps


def test_the_summary_reports_the_estimator_loop():
    problem = parse_problem(copy.deepcopy(DOC))
    d = design_problem(problem)
    est = design_summary(d)["estimator"]
    loop = evaluate_estimator(problem, d.table)
    assert est["oracle_J"] == pytest.approx(loop.moments.J, rel=1e-8)
    assert est["every"] == 2
    assert len(est["knots"]) == 2
    np.testing.assert_allclose(est["knots"][-1]["mean"], loop.moments.knot_mean[-1], atol=1e-8)
    assert max(abs(v) for v in est["knots"][-1]["constraint_violation"]) < 1e-6
    dumps(est)                                   # strict JSON: no NaN or Infinity


def test_no_measurement_no_entry_and_a_delay_table_gets_a_reason():
    doc = copy.deepcopy(DOC)
    del doc["measurement"]
    assert "estimator" not in design_summary(design_problem(parse_problem(doc)))
    doc = copy.deepcopy(DOC)
    doc["design"] = {"delay_ticks": 1}
    est = design_summary(design_problem(parse_problem(doc)))["estimator"]
    assert "one-tick delay" in est["not_evaluated"]


def test_a_spline_tables_summary_is_the_loop_with_the_filters_gain_spline():
    """``--table spline``: the entry's figures are the loop as flashed (the filter's gains as
    their spline, fitted to the table's tolerance), the per-sample filter's cost only as
    ``per_sample_oracle_J``. A loose tolerance makes the two loops' costs differ far beyond
    the comparison's tolerance, so the per-sample figures in their place fail it."""
    from stospline.estimator.ctable import estimator_table
    problem = parse_problem(copy.deepcopy(DOC))
    d = design_problem(problem, table="spline", spline_tolerance=1e-2)
    est = design_summary(d)["estimator"]
    per_sample = evaluate_estimator(problem, d.table)
    gains, pred = estimator_table(problem, d.table, per_sample,
                                  spline_tolerance=1e-2).per_tick()
    flashed = evaluate_estimator(problem, d.table, gains=gains, predictor=pred)
    assert abs(flashed.moments.J - per_sample.moments.J) > 1e-6 * per_sample.moments.J
    assert est["filter_gains"] == "spline"
    assert est["oracle_J"] == pytest.approx(flashed.moments.J, rel=1e-9)
    assert est["per_sample_oracle_J"] == pytest.approx(per_sample.moments.J, rel=1e-9)
    np.testing.assert_allclose(np.asarray(est["knots"][-1]["error_cov"], float),
                               flashed.knot_error_cov[-1], rtol=1e-6)
    assert est["gain_spline"]["oracle_J"] == pytest.approx(est["oracle_J"], rel=1e-9)
    dumps(est)
