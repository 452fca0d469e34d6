"""Spline tables of the shipped examples with time-varying stage data (investment: the
interest rate varies) and designed for a one-tick delay (quadrotor: the controller is fed
``[z, zdot, the thrust being applied]``).

* The summary's certificate holds: the oracle's cost of the law as the firmware evaluates it
  within 1e-7 of the per-tick law it compresses and of J0, the latch maps re-solved exactly
  (residual < 1e-11 in float64) and, rounded to float32, within one float32 epsilon of the
  constraints' values, the knot covariances unchanged to 1e-6, every stored gain within the
  tolerance, and the flash and ratio those of the tables;
* the compiled C controller computes, every tick of the plan, the command of the host's
  evaluation of the spline (`stospline.table.spline.fit.command`), bit for bit;
* Monte Carlo through the compiled controller of a coarse spline (gains that move a lot
  within a span) agrees with its oracle and rejects the oracle of a controller that would
  freeze the gains at each span's start. Fixed seeds; 99 % jointly (`compare_to_oracle`),
  as `test_spline_monte_carlo.py`. 4000 paths: the frozen controller's worst |z| is 138
  (investment) and 92 (quadrotor) against joint limits of 3.09 and 3.36.
"""
from dataclasses import replace

import numpy as np
import pytest

import stospline
from stospline.problem import load_problem
from stospline.harness.controller import build_controller
from stospline.oracle.evaluate import evaluate_table
from stospline.refine.spline_certificate import _cov_change, constraint_residual
from stospline.table.flash import flash_bytes
from stospline.table.format import table_of
from stospline.table.spline.fit import command, max_relative_error
from stospline.table.spline.compress import compress
from stospline.table.spline.latch import resolve_latch
from stospline.design.varying import mean_maps

from conftest import EXAMPLES
from test_spline_monte_carlo import assert_agrees_and_rejects_frozen

EPS32 = float(np.finfo(np.float32).eps)
PATHS, SEED, SUBSTEPS = 4000, 20261127, 2
# A coarse spline per example for the Monte Carlo: (tolerance, spans per stage at most).
# The quadrotor's last tick outputs the safe command (its decision would be applied after the
# plan), a jump its last stage's spline needs a few more spans for.
COARSE = {"investment": (0.1, 4), "quadrotor": (0.2, 12)}


@pytest.fixture(scope="module", params=["investment", "quadrotor"])
def example(request):
    problem = load_problem(EXAMPLES / f"{request.param}.toml")
    return request.param, problem, stospline.design_problem(problem, table="spline")


def test_what_the_examples_exercise(example):
    name, problem, d = example
    if name == "investment":
        assert all(st.varying is not None for st in problem.stages)
        assert d.table.delay_ticks == 0
    else:
        assert d.table.delay_ticks == 1 and d.table.dims[0] == problem.n + problem.m


def test_the_certificate_holds(example):
    _, p, d = example
    cert, J = d.certificate, d.implemented.J
    exact = table_of(d.design, quantize=False)
    per_tick = table_of(d.design)
    law = evaluate_table(p, exact, path=False)
    assert cert["oracle_J"] == J
    assert cert["excess_over_law"] == (J - law.J) / abs(law.J)
    assert cert["excess_over_J0"] == (J - d.design.J0) / abs(d.design.J0)
    assert abs(cert["excess_over_law"]) < 1e-7 and abs(cert["excess_over_J0"]) < 1e-7
    # The re-solve is exact before rounding; rounded to float32, the residual is at the
    # float32 floor: below one epsilon of the constraints' largest value.
    sp = d.table.spline
    Lam, lam0 = resolve_latch(p, d.table, sp, varying_maps=mean_maps)
    exact_latch = evaluate_table(p, replace(d.table, Lambda=Lam, lambda0=lam0), path=False)
    assert constraint_residual(p, exact_latch) < 1e-11
    scale = max(float(np.abs(kn.constraint.value).max()) for kn in p.knots
                if kn.constraint is not None)
    assert cert["constraint_residual"] == constraint_residual(p, d.implemented)
    assert cert["constraint_residual"] <= EPS32 * scale
    assert cert["knot_cov_change"] == _cov_change(law, d.implemented) <= 1e-6
    assert max_relative_error(sp, exact) <= cert["spline_tolerance"]
    assert cert["flash_bytes"] == flash_bytes(d.table)
    assert cert["per_tick_flash_bytes"] == flash_bytes(per_tick)
    assert cert["compression_ratio"] == flash_bytes(per_tick) / flash_bytes(d.table) > 1


def test_the_c_spline_law_is_the_evaluated_one_bit_for_bit(example):
    """Every tick of the plan, on states around the planned mean (the delayed law's third
    entry the thrust being applied), latches included: the compiled command equals the
    host's evaluation in the firmware's order, clipped to the table's limits as the firmware
    clips it; most ticks are not clipped."""
    _, p, d = example
    t = d.table
    step = build_controller(t, fixed_shape=False).stepper(1)
    n, m, n_latch = t.dims
    mom = evaluate_table(p, t, path=True)
    rng = np.random.default_rng(11)
    v = np.zeros(n_latch, dtype=np.float32)
    mismatches = clipped = 0
    for tick in range(t.n_ticks):
        x = mom.path_mean[tick] + 0.3 * rng.normal(size=p.n) * np.sqrt(mom.path_var[tick] + 1)
        if n > p.n:                                     # the command being applied
            x = np.concatenate([x, mom.path_u_mean[tick - 1] if tick else t.u_hold])
        x = x.astype(np.float32)
        s = t.stage_of_tick(tick)
        if tick == t.stage_start[s] and t.stage_n_latch[s] > 0:
            v = np.zeros(n_latch, dtype=np.float32)
            for c in range(int(t.stage_n_latch[s])):
                acc = np.float32(t.lambda0[s, c])
                for j in range(n):
                    acc = np.float32(acc + np.float32(t.Lambda[s, c, j] * x[j]))
                v[c] = acc
        u, status = step(tick, x[None, :])
        assert status[0] == 0
        want = command(t.spline, t.stage_start, tick, x, v)
        limited = np.clip(want, t.u_min, t.u_max).astype(np.float32)
        clipped += int(not np.array_equal(limited, want))
        mismatches += int(not np.array_equal(u[0].view(np.uint32), limited.view(np.uint32)))
    assert mismatches == 0 and clipped <= t.n_ticks // 100


def test_monte_carlo_agrees_with_the_oracle_and_has_power(example):
    name, p, d = example
    exact = table_of(d.design, quantize=False)
    per_tick = table_of(d.design)
    tol, spans = COARSE[name]
    spline, K, k0, L, Lam, lam0 = compress(p, exact, per_tick, tol, max_spans=spans,
                                           initial_spans=2, varying_maps=mean_maps)
    table = replace(per_tick.with_arrays(K=K, k0=k0, L=L, Lambda=Lam, lambda0=lam0),
                    spline=spline)
    assert_agrees_and_rejects_frozen(p, table, paths=PATHS, seed=SEED, substeps=SUBSTEPS)
