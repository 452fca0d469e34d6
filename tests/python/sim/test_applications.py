"""The worked applications (docs/applications/): each example designs, and Monte Carlo through
its compiled C controller agrees with the exact oracle (99 % jointly over the cost and every
knot mean, fixed seeds), with the plant steps chosen automatically. Each also shows the
feature it is there for."""
import numpy as np
import pytest

import stospline
from stospline.pipeline import simulate_problem, simulation_summary

from conftest import EXAMPLES

PATHS, SEED = 3000, 20261124


def _run(name: str):
    p = stospline.load_problem(EXAMPLES / f"{name}.toml")
    d = stospline.design_problem(p, **{k: v for k, v in p.options.items()
                                       if k in ("mode", "discretization")})
    mc = simulate_problem(d, paths=PATHS, seed=SEED)
    return p, d, simulation_summary(d, mc, seed=SEED)


def test_quadrotor_gravity_hover_hold_and_delay():
    p, d, s = _run("quadrotor")
    assert s["verdict"]["agree"], s["verdict"]
    np.testing.assert_array_equal(p.stages[0].f, [0.0, -9.81])            # gravity: a drift
    assert p.u_min[0] > 0 and d.table.u_hold[0] == np.float32(9.81)      # hover safe command
    # Designed for the one-tick delay ([design] delay_ticks = 1): the law is fed [z, zdot, a].
    assert d.table.delay_ticks == 1 and d.table.dims[0] == 3
    assert s["cost"]["oracle_implemented"] == pytest.approx(s["cost"]["predicted_J0"], rel=1e-8)
    # ... and beats the ordinary design run a tick late (the fault oracle).
    from stospline.problem.faults import Faults
    from stospline.oracle.faults import evaluate_with_faults
    plain = stospline.design_problem(p, delay_ticks=0)
    late = evaluate_with_faults(p, plain.table, Faults(delay_ticks=1))
    assert d.implemented.J < late.J
    assert s["saturation"]["tick_fraction"] == 0


def test_investment_time_varying_rate():
    p, d, s = _run("investment")
    assert p.stages[0].varying is not None                 # the interest rate varies
    assert s["verdict"]["agree"], s["verdict"]
    for k, target in enumerate([60.0, 100.0]):
        assert d.implemented.knot_constraint[k][0] == pytest.approx(target, abs=1e-4)


def test_population_smoothing_knots():
    p, d, s = _run("population")
    assert sum(kn.constraint is None for kn in p.knots) == 7   # penalty-only (smoothing)
    assert s["verdict"]["agree"], s["verdict"]
    assert d.implemented.knot_constraint[-1][0] == pytest.approx(40.0, abs=1e-4)


def test_coupled_axes_twelve_states_twenty_stages():
    p, d, s = _run("coupled_axes")
    assert (p.n, p.m, len(p.knots)) == (12, 6, 20)
    assert s["verdict"]["agree"], s["verdict"]
