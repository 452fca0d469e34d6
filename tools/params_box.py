"""Print what a problem with runtime parameters guarantees over its parameter box: every band
row's margin (nominal, worst case over the box; the same design without the tightening), the
oracle at every vertex of the box, each corridor's exit bounds at the nominal and over the
box, and a Monte Carlo of the compiled C at random parameter draws and at the box's worst
vertex (docs/theory/parameters.md, "Guarantees over the box").

    PYTHONPATH=host .venv/bin/python tools/params_box.py examples/drone_gates.toml \\
        [--draws 8] [--paths 2000] [--seed 20261128]
        [--arith q15|q31|q15-spline|q31-spline]

With --arith q15|q31, also what holds for the fixed-point parametric table as flashed (its
error bound propagated to the mean, `stospline.oracle.fixed_point_margin`): the band rows'
margins and the corridors' bounds over the box less it, and the Monte Carlo runs that
controller (docs/theory/parameters.md, "Fixed-point columns"). With q15-spline|q31-spline the
same for the fixed-point spline parametric table (Q spline gains and spline columns at the
file's spline_tolerance, `stospline.table.spline.qparams`).
"""
import argparse
import sys
import time

import numpy as np

from stospline.harness.exit_stats import clopper_pearson_upper
from stospline.harness.params_loop import (build_params_controller, build_params_qcontroller,
                                           simulate_params)
from stospline.oracle.exit_bound import exit_bounds, exit_bounds_over_box
from stospline.oracle.over_box import band_margins, box_moments, vertices
from stospline.oracle.parametric import check_parametric_options, design_parametric, evaluate_at
from stospline.problem import load_problem
from stospline.table.parametric import parametric_table


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("problem")
    ap.add_argument("--draws", type=int, default=8)
    ap.add_argument("--paths", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=20261128)
    ap.add_argument("--arith", choices=("float32", "q15", "q31", "q15-spline", "q31-spline"),
                    default="float32")
    args = ap.parse_args(argv)
    p = load_problem(args.problem)
    opts = check_parametric_options(p)
    cpu = time.process_time()
    pd = design_parametric(p, discretization=opts.discretization, mode=opts.mode,
                           delay_ticks=opts.delay_ticks)
    print(f"design over the box: {time.process_time() - cpu:.2f} s CPU, "
          f"{len(p.parameters)} parameters, {2 ** len(p.parameters)} vertices")
    if pd.margins:
        _bands(p, pd)
    pf = _fixed(p, pd, args.arith, opts) if args.arith != "float32" else None
    for i, c in enumerate(p.corridors):
        _corridor(p, pd, i, c, args, opts, pf)
    return 0


def _fixed(p, pd, arith, opts):
    """Print the certificate of the Q15/Q31 table as flashed (per tick, or `arith`
    ``q15-spline``/``q31-spline``: with spline gains and columns); return its
    `ParametricFixedPoint`, with ``controller`` set to build its compiled controller."""
    from stospline.oracle.evaluate import evaluate_table
    from stospline.oracle.exit_bound import corridor_ticks
    from stospline.oracle.fixed_point_margin import fixed_point_certificate
    from stospline.problem.parameters import problem_at
    from stospline.oracle.over_box import box_state_range
    from stospline.table.qparams import quantize_parametric
    box = pd.box if pd.box is not None else box_moments(p, pd.table)
    if arith.endswith("-spline"):
        from stospline.harness.params_loop import build_params_qspline_controller
        from stospline.table.spline.qparams import quantize_spline_parametric
        pf, gains, cols = quantize_spline_parametric(pd.table, arith.split("-")[0],
                                                     box_state_range(box),
                                                     opts.spline_tolerance)
        pf.controller = lambda: build_params_qspline_controller(pd.table, pf, gains, cols)
    else:
        pf = quantize_parametric(pd.table, arith, box_state_range(box))
        pf.controller = lambda: build_params_qcontroller(pd.table, pf)
    cert = fixed_point_certificate(p, pd.table, pf, box)
    b = pf.command_error_bound(pd.table)
    shift = cert["bound"].rows(np.eye(p.n)).max(axis=0)
    print(f"{arith.upper()} table as flashed: command error bound (real state) "
          f"{', '.join(f'{v:.3g}' for v in b.max(axis=0))} "
          f"({', '.join(f'{v:.2f}' for v in (b / pf.augmented.u_lsb).max(axis=0))} LSB); "
          f"mean moved by at most {', '.join(f'{v:.3g}' for v in shift)} (per state)")
    for m, d in zip(cert["margins"], pd.margins):
        print(f"  {m.field} row {m.row}: over the box {d.worst:.2e} (double), {m.worst:.2e} "
              f"less the bound -> {'holds' if m.holds else 'VIOLATED'}")
    for i, (c, q) in enumerate(zip(p.corridors, cert["corridors"])):
        double = exit_bounds_over_box(c, box, p.t0, p.tick_hz)
        walls = c.A @ c.C
        flashed, spread = pf.as_flashed(pd.table), 0.0
        lo, hi = corridor_ticks(c, p.t0, p.tick_hz)
        for v in vertices(p.parameters):
            va, vf = (np.einsum("rn,tnm,rm->tr", walls, evaluate_table(
                problem_at(p, v), t, path=True, output=np.eye(p.n)).path_y_cov[lo:hi + 1],
                walls) for t in (pd.table.at(v), flashed.at(v, quantize=True)))
            spread = max(spread, float(np.max(np.abs(np.sqrt(vf) - np.sqrt(va)))))
        print(f"  corridor {i}: worst tick's Cantelli bound over the box "
              f"{double['cantelli'].worst_tick:.4g} (double), "
              f"{q['cantelli'].worst_tick:.4g} (margin less the bound); not covered, the "
              f"rounding's effect on the spread: at the vertices the flashed table's standard "
              f"deviation along a wall differs from the double's by {spread:.2g} at most")
    return pf


def _bands(p, pd) -> None:
    from stospline.design.sensitivity import source_designs
    from stospline.design.tick_qp import design_tick_qp
    plain = design_tick_qp(p)                    # the same design, rows not tightened
    hz, stages = plain.tick_gains()
    table = parametric_table(p, hz, stages, source_designs(p, design_tick_qp))
    untightened = {(m.field, m.row): m for m in band_margins(p, box_moments(p, table))}
    print("band rows: margin at the nominal, worst over the box (where, the parameter that "
          "moves it most), and the worst without the tightening")
    for m in pd.margins:
        u = untightened[m.field, m.row]
        print(f"  {m.field} row {m.row}: nominal {m.nominal:.4f}, over the box {m.worst:.2e} "
              f"(t = {m.t:g}, {m.side}, {m.parameter} moves it {m.moved:.4f}); untightened "
              f"{u.worst:+.4f} ({u.parameter}) -> {'holds' if m.holds else 'VIOLATED'}")
    worst = {False: np.inf, True: np.inf}
    for v in vertices(p.parameters):
        for quantize in worst:
            mean = evaluate_at(p, pd.table, v, path=True, quantize=quantize).path_mean
            for reg in p.tick_regions:
                y = mean[reg.ticks(p.t0, p.tick_hz)] @ reg.C.T
                worst[quantize] = min(worst[quantize], float(np.min(y - reg.lower)),
                                      float(np.min(reg.upper - y)))
    print(f"  oracle at every vertex: smallest region margin {worst[False]:.2e} (double), "
          f"{worst[True]:.2e} (float32 table)")


def _corridor(p, pd, i, c, args, opts, pf=None) -> None:
    box = pd.box if pd.box is not None else box_moments(p, pd.table)
    nominal = exit_bounds(c, box.mean @ c.C.T, c.C @ box.cov @ c.C.T, p.t0, p.tick_hz)
    over = exit_bounds_over_box(c, box, p.t0, p.tick_hz)

    def at(theta):
        mean, cov = box.at(theta)
        return exit_bounds(c, mean @ c.C.T, c.C @ cov @ c.C.T, p.t0, p.tick_hz)

    corners = [(at(v), v) for v in vertices(p.parameters)]
    worst_b, worst_v = max(corners, key=lambda bv: bv[0]["gaussian"].total)
    print(f"corridor {i}: exit bounds over its ticks (worst tick)")
    for name, b in (("nominal", nominal), ("worst vertex", worst_b), ("over the box", over)):
        print(f"  {name:13s} Cantelli {b['cantelli'].total:.4g} ({b['cantelli'].worst_tick:.4g})"
              f"   Gaussian {b['gaussian'].total:.4g} ({b['gaussian'].worst_tick:.4g})")
    print(f"  worst vertex (Gaussian): {dict(zip([q.name for q in p.parameters], worst_v))}")
    if pf is None:
        from stospline import design_problem
        table = design_problem(p, options=opts).table
        ctl = build_params_controller(pd.table, table)
    else:
        print(f"  Monte Carlo of the compiled {pf.augmented.arith.upper()} controller:")
        ctl = pf.controller()
    rng = np.random.default_rng(args.seed)
    lo = np.array([q.lower for q in p.parameters])
    hi = np.array([q.upper for q in p.parameters])
    draws = [("vertex", worst_v)] + [(f"draw {k}", rng.uniform(lo, hi))
                                     for k in range(args.draws)]
    total_exits = total_paths = 0
    cpu = time.process_time()
    for k, (name, theta) in enumerate(draws):
        exits = _exits(p, ctl, c, theta, paths=args.paths, seed=args.seed + k)
        if k:
            total_exits += exits; total_paths += args.paths
        print(f"  MC {name:8s} {exits} of {args.paths} paths left the corridor "
              f"(99 % upper {clopper_pearson_upper(exits, args.paths):.4f}; Gaussian bound "
              f"there {at(theta)['gaussian'].total:.3g})")
    print(f"  MC over {args.draws} random draws: {total_exits} of {total_paths} "
          f"(99 % upper {clopper_pearson_upper(total_exits, total_paths):.4f}); "
          f"{time.process_time() - cpu:.1f} s CPU")


def _exits(p, ctl, c, theta, *, paths: int, seed: int) -> int:
    lo, hi = int(round((c.t[0] - p.t0) * p.tick_hz)), int(round((c.t[1] - p.t0) * p.tick_hz))
    out = np.zeros(paths, bool)

    def observe(j, X):
        if lo <= j <= hi:
            out[:] |= c.exit_wall(X @ c.C.T) >= 0

    simulate_params(p, ctl, theta, paths=paths, seed=seed, observe=observe)
    return int(out.sum())


if __name__ == "__main__":
    sys.exit(main())
