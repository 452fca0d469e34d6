"""Monte Carlo through the compiled C (stsp_set_params, stsp_param_step) of the drone through
gates. At the vertex of the parameter box where its altitude band is tightest: the sample mean
altitude at that tick agrees with the oracle at that vertex (99 % two-sided, the sample's own
standard error, fixed seed), the oracle's value there is inside the band, and the same run
disagrees with the nominal's. With the gates drawn in the box and moved during the flight (a
radio update between gates 1 and 2): cost and every knot-mean component agree with the oracle
of that change (`evaluate_switched` at that tick; joint Bonferroni 99 %) and disagree with the
oracles of the change at the wrong point (the tests can fail). The drone's hashes for
tools/arm/count_params.py (tests/c/params_drone_expected.h) are checked here, on the same
design."""
import sys

import numpy as np
import pytest

from conftest import EXAMPLES, REPO
from stospline import design_problem, load_problem
from stospline.harness.params_loop import build_params_controller, simulate_params
from stospline.oracle.parametric import (check_parametric_options, design_parametric,
                                         evaluate_at, evaluate_switched)

sys.path.insert(0, str(REPO / "tests" / "c"))
import params_reference  # noqa: E402

PATHS, SEED = 2000, 20261129
Z99 = 2.5758293035489


@pytest.fixture(scope="module")
def drone(tmp_path_factory):
    p = load_problem(EXAMPLES / "drone_gates.toml")
    opts = check_parametric_options(p)
    pd = design_parametric(p, mode=opts.mode)
    table = design_problem(p, options=opts).table
    ctl = build_params_controller(pd.table, table, build_dir=tmp_path_factory.mktemp("box"))
    return p, pd, table, ctl


def test_altitude_at_the_worst_vertex_agrees_with_the_oracle(drone):
    p, pd, _, ctl = drone
    (m,) = pd.margins
    reg = p.tick_regions[0]
    j = int(round((m.t - p.t0) * p.tick_hz))
    s = reg.C[0] @ pd.box.S[j]                          # the row's sensitivity there
    lo = np.array([q.lower for q in p.parameters])
    hi = np.array([q.upper for q in p.parameters])
    theta = np.where(s > 0, hi, lo) if m.side == "upper" else np.where(s > 0, lo, hi)
    seen = {}

    def observe(tick, X):
        if tick == j:
            seen["z"] = X @ reg.C[0]

    run = simulate_params(p, ctl, theta, paths=PATHS, seed=SEED, observe=observe)
    assert run.worst_status >= 0
    z = seen["z"]
    se = z.std(ddof=1) / np.sqrt(z.size)
    exact = evaluate_at(p, pd.table, theta, quantize=True, path=True).path_mean[j] @ reg.C[0]
    assert exact <= reg.upper[0] + 1e-6
    assert abs(z.mean() - exact) <= Z99 * se, (z.mean(), exact, se)
    nominal = evaluate_at(p, pd.table, pd.table.nominal, quantize=True, path=True).path_mean[j] @ reg.C[0]
    assert abs(z.mean() - nominal) > Z99 * se


def test_gates_moved_during_the_flight_agree_with_the_oracle_of_that_tick(drone):
    """Joint design: the multipliers are latched once, at tick 0, so the change at tick 150
    (stage 1, ticks 100 .. 199) reaches the feed-forward only."""
    p, pd, _, ctl = drone
    pt = pd.table
    assert list(pt.table.stage_start) == [0, 100, 200, 300, 400]
    assert not np.any(pt.table.stage_n_latch[1:])
    rng = np.random.default_rng(SEED)
    lo = np.array([q.lower for q in p.parameters])
    hi = np.array([q.upper for q in p.parameters])
    theta, theta2 = rng.uniform(lo, hi), rng.uniform(lo, hi)
    run = simulate_params(p, ctl, theta, paths=PATHS, seed=SEED, change=(1, theta2, 150))
    assert run.worst_status >= 0
    exact = evaluate_switched(p, pt, theta, 1, theta2, tick=150, quantize=True)
    verdict = run.agreement(exact.J, exact.knot_mean)
    assert verdict.agree, verdict
    wrong = {"at the stage's start": evaluate_switched(p, pt, theta, 1, theta2, quantize=True),
             "from tick 0": evaluate_at(p, pt, theta2, quantize=True),
             "never": evaluate_at(p, pt, theta, quantize=True)}
    for name, m in wrong.items():
        assert not run.agreement(m.J, m.knot_mean).agree, name


def test_drone_hashes_for_the_m4f_bench_are_the_specification(drone):
    _, pd, table, _ = drone
    assert ((REPO / "tests/c/params_drone_expected.h").read_text()
            == params_reference.expected("drone_gates", designed=(table, pd.table))), \
        "regenerate tests/c/params_drone_expected.h with tests/c/params_reference.py " \
        "--example drone_gates"
