"""Monte Carlo through the compiled fixed-point controller running a Q15/Q31 spline table (the
firmware evaluates the spline's integer gains at every tick, stsp_qspline_t; bit for bit the
host's `stospline.table.spline.fixed_point.evaluate_q`, test_qspline_controller.py), with the re-solved
latch maps as stored; states rounded to the Q format, commands times their LSB
(`CompiledController.real_stepper`). The cost, knot
means and knot variances agree with the exact oracle of that law (integer gains and latch maps
in real units, the plant's scheme), 99 % jointly; and the same run rejects the oracle of the
law with the gains frozen at each span's start (the check has power). Fixed seeds. The
command's rounding and the state's are not in the oracle: below the run's resolution.

4000 paths: z-scores grow as the square root of the paths, and at 2000 paths the frozen law's
worst |z| is already 44 against the joint limit of 3.44 (17 statistics, 99 %), so 4000 keep a
wide margin of power at a fifth of the cost of 20 000."""
from dataclasses import replace

import numpy as np
import pytest

import stospline
from stospline.pipeline import fixed_point_spline
from stospline.problem.faults import Faults
from stospline.harness.controller import build_controller
from stospline.harness.montecarlo import compare_to_oracle, simulate
from stospline.oracle.evaluate import evaluate_table
from stospline.table.spline.fixed_point import dequantized

PATHS, SEED, SUBSTEPS = 4000, 20261126, 2


@pytest.fixture(scope="module")
def robot_spline(robot_problem):
    return stospline.design_problem(robot_problem, table="spline")


def _frozen_at_span_starts(law, ft):
    """The law with every gain held at its value at its span's first tick."""
    K, k0, L = (np.array(a) for a in (law.K, law.k0, law.L))
    start = ft.stage_start.astype(int)
    for s in range(ft.n_stages):
        D = 1 << int(ft.spline.span_log2[s])
        for a in range(start[s], start[s + 1], D):
            b = min(a + D, start[s + 1])
            K[a:b], k0[a:b], L[a:b] = K[a], k0[a], L[a]
    return replace(law, K=K, k0=k0, L=L)


@pytest.mark.parametrize("arith", ["q15", "q31"])
def test_monte_carlo_agrees_with_the_q_splines_oracle_and_has_power(robot_problem,
                                                                  robot_spline, arith):
    p = robot_problem
    ft, _ = fixed_point_spline(robot_spline, arith, tolerance=1e-3)   # spans of 256 ticks
    mc = simulate(p, build_controller(ft), paths=PATHS, seed=SEED,
                  substeps=SUBSTEPS, faults=Faults())
    assert mc.worst_status == 0
    law = dequantized(ft)
    own = evaluate_table(p, law, propagator="euler", substeps=SUBSTEPS, path=False)
    agree = compare_to_oracle(mc, own.J, own.knot_mean, knot_covs=own.knot_cov)
    assert agree.ok, agree.verdict
    frozen = evaluate_table(p, _frozen_at_span_starts(law, ft), propagator="euler",
                            substeps=SUBSTEPS, path=False)
    other = compare_to_oracle(mc, frozen.J, frozen.knot_mean, knot_covs=frozen.knot_cov)
    assert not other.ok, other.verdict
