"""``stospline`` command line: a thin layer over `stospline.pipeline`.

Exit status: 0 success, 2 bad problem file or infeasible problem (message names the field),
1 anything else.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .problem import ProblemError, load_problem
from .strict import dumps, quiet_numerics

__all__ = ["main"]


def _options(args, problem) -> dict:
    """Design options: command line first, then the file's [design] table, then defaults."""
    return {"mode": args.mode or problem.options.get("mode", "stagewise"),
            "discretization": args.discretization
            or problem.options.get("discretization", "exact-zoh")}


@quiet_numerics
def _design(args) -> int:
    from .pipeline import design_problem, design_summary, generated_files, write_outputs
    problem = load_problem(args.problem)
    d = design_problem(problem, noise=not args.ignore_noise, **_options(args, problem))
    arith = args.arith or problem.options.get("arith", "float32")
    files = generated_files(d, Path(args.problem).name, arith, with_c=bool(args.out))
    if args.out:
        written = write_outputs(args.out, files)
    if args.json:
        print(files[next(k for k in files if k.endswith(".json"))], end="")
    else:
        from .summary_text import design_summary_text
        print(design_summary_text(d, arith), end="")
        for path in written if args.out else []:
            print(f"wrote {path}")
    return 0


def _start(arg: str | None):
    """``--x0 "a,b,..."`` as floats (None: the problem's x0)."""
    if arg is None:
        return None
    try:
        return [float(v) for v in arg.replace(" ", "").split(",")]
    except ValueError:
        raise ProblemError("--x0", f"expected comma-separated numbers, got {arg!r}") from None


@quiet_numerics
def _simulate(args) -> int:
    from .pipeline import design_problem, simulate_problem, simulation_summary, start_from
    problem = load_problem(args.problem)
    x0 = _start(args.x0)
    d = design_problem(problem, noise=not args.ignore_noise, **_options(args, problem))
    if x0 is not None:
        d = start_from(d, x0)
    mc = simulate_problem(d, paths=args.paths, seed=args.seed, substeps=args.substeps)
    s = simulation_summary(d, mc, seed=args.seed, substeps=args.substeps)
    _report_simulation(s, args.json)
    sat = s["saturation"]
    if sat["tick_fraction"] > 0:
        print(f"stospline: warning: the controller saturated (STSP_WARN_SATURATED) on "
              f"{100 * sat['tick_fraction']:.4g}% of ticks, on {100 * sat['path_fraction']:.4g}% "
              f"of paths; the oracle and predicted numbers assume no saturation (the design "
              f"ignores the actuator limits), so they do not predict this run", file=sys.stderr)
    return 0


def _report_simulation(s: dict, as_json: bool) -> None:
    if as_json:
        print(dumps(s), flush=True)
        return
    sat = s["saturation"]
    c = s["cost"]
    print(f"{s['name']}: {s['paths']} paths, seed {s['seed']}, compiled C controller at "
          f"{s['tick_hz']} Hz, plant {s['substeps']} substeps/tick, from x0 = {s['x0']}")
    print(f"  cost  MC {c['mc_mean']:.6g}  95% CI [{c['ci95'][0]:.6g}, {c['ci95'][1]:.6g}]"
          f"   oracle {c['oracle_implemented']:.6g}   predicted J0 {c['predicted_J0']:.6g}")
    bias = s["simulation_bias"]
    ratio = ("n/a MC standard errors (all paths alike)" if bias["cost_over_stderr"] is None
             else f"{bias['cost_over_stderr']:.3g} MC standard errors")
    print(f"  plant-scheme bias in cost {bias['cost']:.3g} = {ratio}")
    if sat["limited"]:
        print(f"  actuator limits: saturated on {100 * sat['tick_fraction']:.4g}% of ticks "
              f"({100 * sat['path_fraction']:.4g}% of paths); commands issued within "
              f"[{', '.join(f'{v:.6g}' for v in sat['u_low'])}] .. "
              f"[{', '.join(f'{v:.6g}' for v in sat['u_high'])}]")
    fmt = lambda v: "[" + ", ".join(f"{x:+.5f}" for x in v) + "]"  # noqa: E731
    for k, kn in enumerate(s["knots"]):
        print(f"  knot {k} (t = {kn['t']:g}): state mean, MC     {fmt(kn['mc_mean'])}")
        print(f"  {'':>15}state mean, oracle {fmt(kn['oracle_mean'])}   "
              f"z {'[' + ', '.join(_z_text(z) for z in kn['z']) + ']'}")
    sys.stdout.flush()   # the saturation warning (stderr) comes after the numbers it qualifies


def _z_text(z) -> str:
    """A z-score, or "n/a" when it is undefined (zero standard error; JSON null)."""
    return "n/a" if z is None else f"{z:+.2f}"


@quiet_numerics
def _plot(args) -> int:
    from .pipeline import design_problem, simulate_problem
    from .plot import plot_corridor
    problem = load_problem(args.problem)
    d = design_problem(problem, **_options(args, problem))
    mc = simulate_problem(d, paths=args.paths, seed=args.seed, substeps=args.substeps)
    plot_corridor(d, mc, args.out)
    print(f"wrote {args.out}")
    return 0


def _version() -> str:
    from . import __version__
    return __version__


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="stospline", description=__doc__.splitlines()[0])
    ap.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = ap.add_subparsers(dest="command", required=True)

    p = sub.add_parser("design", help="solve the design, write C gain tables and a summary")
    p.add_argument("problem", help="problem file (TOML)")
    p.add_argument("--out", help="directory for <name>.c, <name>.h, <name>.json")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.add_argument("--ignore-noise", action="store_true",
                   help="design as if there were no noise (the paper's Remark 2)")
    p.add_argument("--arith", default=None, metavar="{float32,q15,q31}",
                   help="arithmetic of the generated tables: float32 (default), or fixed-point "
                        "Q15/Q31 written as <name>_<arith>.{c,h,json} (docs/firmware.md). "
                        "Default: the file's [design] arith")
    p.set_defaults(func=_design)

    p = sub.add_parser("simulate", help="Monte Carlo with the compiled C controller in the loop")
    p.add_argument("problem")
    p.add_argument("--paths", type=int, default=10000)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--substeps", type=int, default=2, help="plant steps per controller tick")
    p.add_argument("--json", action="store_true")
    p.add_argument("--ignore-noise", action="store_true")
    p.add_argument("--x0", help="start the plant from this state instead of the problem's "
                                "(comma-separated; write --x0=-5,0,1,0 when it starts with a minus); the tables stay the design's and the "
                                "controller latches from what it measures")
    p.set_defaults(func=_simulate)

    p = sub.add_parser("plot", help="figure: corridor, one realisation, MC mean, controls")
    p.add_argument("problem")
    p.add_argument("--out", required=True, help="PNG file")
    p.add_argument("--paths", type=int, default=100)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--substeps", type=int, default=2)
    p.set_defaults(func=_plot)
    for name, sp in sub.choices.items():
        sp.add_argument("--discretization", choices=["exact-zoh", "continuous"],
                        default=None,
                        help="exact-zoh (default): optimal for the held control at the tick "
                             "rate; continuous: sample the continuous-time gains. Default: "
                             "the file's [design] discretization")
        sp.add_argument("--mode", choices=["stagewise", "joint"], default=None,
                        help="stagewise (default): re-plan the multipliers at every stage "
                             "start; joint: one multiplier vector for all knots, latched at t0 "
                             "(needed for bands). Default: the file's [design] mode")
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if getattr(args, "arith", None) not in (None, "float32", "q15", "q31"):
        print(f"stospline: error: --arith must be one of ['float32', 'q15', 'q31'], "
              f"got {args.arith!r}", file=sys.stderr)
        return 2
    try:
        return args.func(args)
    except ProblemError as exc:
        print(f"stospline: error in {args.problem}: {exc}", file=sys.stderr)
        return 2
    except FileNotFoundError as exc:
        print(f"stospline: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
