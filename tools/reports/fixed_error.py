#!/usr/bin/env python3
"""Report (docs/guide/firmware.md, "Fixed-point variants"): the largest |u_fixed - u_double| of the
compiled Q15/Q31 controllers over 10^6 random in-range states of the robot design, next to
the table's documented bound, and the closed-loop distance to the float32 controller.

    .venv/bin/python tools/reports/fixed_error.py [--samples N] [--seed S]

The same computation as tests/python/firmware/test_fixed_point.py (which asserts on it),
both through `stospline.harness.fixed_point_error`: for each sample a random tick, a random latch
state and a random state over the whole Q range; a fresh C instance latches at the tick's
latch stage and is stepped at the tick; u_double is the design's law in double precision at
the same real states.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from stospline.table.qformat import latch_q, law_double, law_q
from stospline.harness.fixed_point_error import noise_free_closed_loop, random_q_samples
from stospline.harness.controller import build_controller
from stospline.pipeline import design_problem, fixed_point_table
from stospline.problem import load_problem

ROOT = Path(__file__).resolve().parents[2]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=1_000_000)
    ap.add_argument("--seed", type=int, default=20260601)
    args = ap.parse_args()
    problem = load_problem(ROOT / "examples" / "robot_corridor.toml")
    d = design_problem(problem)
    f32 = build_controller(d.table)
    xf, _, _ = noise_free_closed_loop(problem, f32, lambda x: x.astype(np.float32),
                                      lambda U: U.astype(float))
    print(f"robot_corridor (exact-ZOH design, {d.table.n_ticks} ticks), {args.samples} samples, "
          f"seed {args.seed}")
    for arith in ("q15", "q31"):
        ft = fixed_point_table(d, arith)
        ctl = build_controller(ft)
        rng = np.random.default_rng(args.seed)
        tick, ls, t_latch, X, XL = random_q_samples(ft, args.samples, rng)
        U, status = ctl.pair_steps(t_latch, XL, tick, X)
        V = latch_q(ft, np.maximum(ls, 0), XL)
        exact = np.array_equal(U.astype(np.int64), law_q(ft, tick, X, V))
        err = np.abs(U * ft.u_lsb - law_double(ft, tick, X * ft.x_lsb, XL * ft.x_lsb))
        ratio = err / ft.bound[tick]
        F = ft.frac_bits
        xq, _, _ = noise_free_closed_loop(
            problem, ctl,
            lambda x: np.clip(np.floor(x / ft.x_lsb + 0.5), -(1 << F), (1 << F) - 1
                              ).astype(ctl.dtype),
            lambda U_: U_ * ft.u_lsb)
        print(f"{arith}: x_exp {ft.x_exp.tolist()} (states within +-"
              f"{np.ldexp(1.0, ft.x_exp.astype(int)).tolist()}), u_exp {ft.u_exp.tolist()} "
              f"(LSB {ft.u_lsb.tolist()}), v_exp {ft.v_exp.tolist()}")
        print(f"  C == Python integer model on every sample: {exact}; statuses "
              f"{sorted(set(np.unique(status).tolist()))}")
        for i in range(ft.dims[1]):
            print(f"  u[{i}]: max |u_fixed - u_double| {err[:, i].max():.4e}   documented bound "
                  f"(max over ticks) {ft.bound[:, i].max():.4e} = "
                  f"{ft.bound_lsb[:, i].max():.3f} LSB   max/bound {err[:, i].max() / ft.bound[:, i].max():.3f}")
        print(f"  worst sample / its own tick's bound: {ratio.max():.3f}")
        print(f"  noise-free closed loop: max |x_{arith} - x_float32| "
              f"{np.abs(xq - xf).max():.3e}, final state {np.round(xq[-1], 7).tolist()} "
              f"(float32 {np.round(xf[-1], 7).tolist()})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
