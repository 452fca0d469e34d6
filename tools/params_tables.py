"""Write gains/<name>_params.{c,h}, the sensitivity columns of every example that declares
[[parameters]] (stospline.oracle.parametric.parametric_c_files), byte-for-byte reproducible.

    .venv/bin/python tools/params_tables.py [--out gains/] [--bytes] [--fixed]

--bytes prints, per example, the flash of the float32 per-tick table and of its columns.
--fixed writes, instead, the Q15/Q31 parametric controllers of the examples in FIXED
(`fixed_point_files`): gains/<name>_<arith>.{c,h}, the gain table quantized with the columns
over the whole box, and gains/<name>_<arith>_params.{c,h}, its columns, byte for byte what
`stospline design examples/<name>.toml --arith <arith> --out DIR` writes (the same code,
`stospline.oracle.parametric.fixed_parametric`); with --bytes it prints their columns' flash
and error bound.
"""
import argparse
import sys
from pathlib import Path

from stospline.oracle.parametric import parametric_c_files
from stospline.problem import load_problem

ROOT = Path(__file__).resolve().parents[1]
FIXED = ("robot_goal",)       # the examples with Q15/Q31 parametric controllers in gains/


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(ROOT / "gains"))
    ap.add_argument("--bytes", action="store_true")
    ap.add_argument("--fixed", action="store_true")
    args = ap.parse_args(argv)
    if args.fixed:
        for name in FIXED:
            for arith, (files, pf) in fixed_point_files(name).items():
                for fname, text in files.items():
                    (Path(args.out) / fname).write_text(text)
                if args.bytes:
                    print(f"{name} {arith}: columns {pf.column_bytes()} B, error bound "
                          f"{', '.join(f'{b:.2f}' for b in pf.bound_lsb.max(axis=0))} "
                          f"command LSB")
        return 0
    for path in sorted((ROOT / "examples").glob("*.toml")):
        problem = load_problem(path)
        if not problem.parameters:
            continue
        files = parametric_c_files(problem, source_name=path.name)
        for name, text in files.items():
            (Path(args.out) / name).write_text(text)
        if args.bytes:
            print(path.stem, _flash(problem))
    return 0


def fixed_point_files(name: str) -> dict:
    """``{arith: (files, pf)}`` for Q15 and Q31: the C of example `name`'s fixed-point
    parametric controller and its `stospline.table.qparams.ParametricFixedPoint`, as
    `stospline design examples/<name>.toml --arith <arith> --out DIR` writes them
    (`stospline.oracle.parametric.fixed_parametric`)."""
    from stospline.oracle.parametric import fixed_parametric
    from stospline.options import resolve_options
    problem = load_problem(ROOT / "examples" / f"{name}.toml")
    out = {}
    for arith in ("q15", "q31"):
        files, pf, _ = fixed_parametric(problem, f"{name}.toml",
                                        resolve_options(problem, arith=arith))
        out[arith] = (files, pf)
    return out


def _flash(problem) -> str:
    from stospline.oracle.parametric import check_parametric_options, design_parametric
    from stospline.table.flash import flash_bytes
    opts = check_parametric_options(problem)
    pt = design_parametric(problem, discretization=opts.discretization, mode=opts.mode,
                           delay_ticks=opts.delay_ticks).table
    table = flash_bytes(pt.table.quantized())
    P = len(pt.parameters)
    columns = 4 * (3 * P + pt.S_k0.size + pt.S_lambda0.size)
    return f"table {table} B, {P} parameter columns {columns} B (+{100 * columns / table:.1f} %)"


if __name__ == "__main__":
    sys.exit(main())
