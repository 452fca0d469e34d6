"""Write gains/<name>_params.{c,h}, the sensitivity columns of every example that declares
[[parameters]] (stospline.oracle.parametric.parametric_c_files), byte-for-byte reproducible.

    .venv/bin/python tools/params_tables.py [--out gains/] [--bytes]

--bytes prints, per example, the flash of the float32 per-tick table and of its columns.
"""
import argparse
import sys
from pathlib import Path

from stospline.oracle.parametric import parametric_c_files
from stospline.problem import load_problem

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(ROOT / "gains"))
    ap.add_argument("--bytes", action="store_true")
    args = ap.parse_args(argv)
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
