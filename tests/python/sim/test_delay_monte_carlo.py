"""Monte Carlo through the compiled C controller of a table designed for a one-tick delay (fed
``[x; the command being applied]``, its output applied at the next tick) agrees with the exact
oracle of that loop, and disagrees with the oracle of another law, the ordinary one run a tick
late, so the check can tell the two apart. Fixed seed; 99 % jointly (`compare_to_oracle`)."""
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

import stospline
from stospline.errors import ProblemError
from stospline.problem.faults import Faults
from stospline.problem.reader import parse_problem
from stospline.harness.controller import build_controller
from stospline.oracle.faults import evaluate_with_faults
from stospline.harness.montecarlo import compare_to_oracle, simulate
from stospline.oracle.evaluate import evaluate_table

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from support.problems import BASE, edit  # noqa: E402

PATHS, SEED, SUBSTEPS = 20000, 20261124, 2


@pytest.fixture(scope="module")
def delayed():
    """BASE (10 Hz: a tick of delay is large next to the Monte Carlo error) with a nonzero
    safe command, which the actuator applies over the first tick."""
    p = parse_problem(tomllib.loads(edit(BASE, ("tick_hz = 10", "tick_hz = 10\nu_hold = 0.5"))))
    d = stospline.design_problem(p, delay_ticks=1)
    return p, d, build_controller(d.table)


def test_monte_carlo_through_c_agrees_with_the_oracle(delayed):
    p, d, ctl = delayed
    mc = simulate(p, ctl, paths=PATHS, seed=SEED, substeps=SUBSTEPS, faults=Faults())
    assert mc.worst_status == 0
    assert np.all(mc.sample_u[0] == np.float32(0.5))     # the first tick applies the safe command
    exact = evaluate_table(p, d.table, propagator="euler", substeps=SUBSTEPS, path=False)
    agree = compare_to_oracle(mc, exact.J, exact.knot_mean, knot_covs=exact.knot_cov)
    assert agree.ok, agree.verdict
    ordinary = stospline.design_problem(p, delay_ticks=0).table
    late = evaluate_with_faults(p, ordinary, Faults(delay_ticks=1), propagator="euler",
                                substeps=SUBSTEPS)
    other = compare_to_oracle(mc, late.J, late.knot_mean, knot_covs=late.knot_cov)
    assert not other.ok, other.verdict


def test_the_pipeline_verdict_agrees(delayed):
    _, d, _ = delayed
    mc = stospline.simulate_problem(d, paths=4000, seed=SEED)
    s = stospline.simulation_summary(d, mc, seed=SEED)
    assert s["verdict"]["agree"], s["verdict"]
    assert s["cost"]["oracle_implemented"] == pytest.approx(s["cost"]["predicted_J0"], rel=1e-5)


def test_a_delay_fault_on_top_is_refused(delayed):
    p, _, ctl = delayed
    with pytest.raises(ProblemError) as exc:
        simulate(p, ctl, paths=2, seed=1, substeps=1, faults=Faults(delay_ticks=1))
    assert exc.value.field == "faults.delay_ticks"
