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
