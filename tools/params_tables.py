"""Write gains/<name>_params.{c,h}, the sensitivity columns of every example that declares
[[parameters]] (stospline.oracle.parametric.parametric_c_files), byte-for-byte reproducible.

    .venv/bin/python tools/params_tables.py [--out gains/] [--bytes] [--fixed] [--spline]

--bytes prints, per example, the flash of the float32 per-tick table and of its columns.
--spline writes, instead, the spline parametric controllers of the examples in SPLINE
(`spline_files`): gains/<name>_spline.{c,h}, the float32 spline gain table at the file's
spline_tolerance, and gains/<name>_spline_params.{c,h}, its columns as B-splines on the same
knots (format 2), byte for byte what `stospline design examples/<name>.toml --table spline
--out DIR` writes (the same code, `stospline.pipeline.spline_parametric_files`); with --bytes it prints, for every example with [[parameters]], the bytes of
the per-tick and the spline forms (table and columns), the columns' largest fit error and
their effect on the command over the box; with --certify, the guarantees over the box of the
spline table as flashed against the per-tick design's (stospline.refine.spline_params).
--fixed writes, instead, the Q15/Q31 parametric controllers of the examples in FIXED
(`fixed_point_files`): gains/<name>_<arith>.{c,h}, the gain table quantized with the columns
over the whole box, and gains/<name>_<arith>_params.{c,h}, its columns, byte for byte what
`stospline design examples/<name>.toml --arith <arith> --out DIR` writes (the same code,
`stospline.oracle.parametric.fixed_parametric`), and the Q15/Q31 spline parametric controllers
(`fixed_spline_files`): gains/<name>_<arith>_spline.{c,h}, the Q spline gain table in the
scales of the law with the columns, and gains/<name>_<arith>_spline_params.{c,h}, its columns
as integer B-splines on the gain spline's spans (format 2,
stospline.table.spline.qparams); with --bytes it prints their columns' flash and error bound.
"""
import argparse
import sys
from pathlib import Path

import numpy as np

from stospline.oracle.parametric import parametric_c_files
from stospline.problem import load_problem

ROOT = Path(__file__).resolve().parents[1]
FIXED = ("robot_goal",)       # the examples with Q15/Q31 parametric controllers in gains/
SPLINE = ("robot_goal",)      # the examples with spline parametric controllers in gains/


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(ROOT / "gains"))
    ap.add_argument("--bytes", action="store_true")
    ap.add_argument("--fixed", action="store_true")
    ap.add_argument("--spline", action="store_true")
    ap.add_argument("--certify", action="store_true")
    args = ap.parse_args(argv)
    if args.spline:
        for path in sorted((ROOT / "examples").glob("*.toml")):
            problem = load_problem(path)
            if not problem.parameters or (path.stem not in SPLINE and not args.bytes):
                continue
            files, sp = spline_files(problem, path.name)
            if path.stem in SPLINE:
                for fname, text in files.items():
                    (Path(args.out) / fname).write_text(text)
            if args.bytes:
                print(path.stem, _spline_flash(sp))
            if args.certify:
                print(path.stem, _certificate(problem, sp))
        return 0
    if args.fixed:
        for name in FIXED:
            for arith, (files, pf) in fixed_point_files(name).items():
                for fname, text in files.items():
                    (Path(args.out) / fname).write_text(text)
                if args.bytes:
                    print(f"{name} {arith}: columns {pf.column_bytes()} B, error bound "
                          f"{_bound(pf)}")
            for arith, (files, (pf, gains, cols)) in fixed_spline_files(name).items():
                for fname, text in files.items():
                    (Path(args.out) / fname).write_text(text)
                if args.bytes:
                    print(f"{name} {arith} spline: {_qspline_flash(pf, gains, cols)}")
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


def fixed_point_files(name: str, spline: bool = False) -> dict:
    """``{arith: (files, pf)}`` for Q15 and Q31: the C of example `name`'s fixed-point
    parametric controller and its `stospline.table.qparams.ParametricFixedPoint`, as
    `stospline design examples/<name>.toml --arith <arith> --out DIR` writes them
    (`stospline.oracle.parametric.fixed_parametric`); with `spline`, of its fixed-point
    spline parametric controller, ``pf`` then ``(pf, gains, cols)``
    (`stospline.oracle.parametric.fixed_spline_parametric`)."""
    from stospline.oracle.parametric import fixed_parametric, fixed_spline_parametric
    from stospline.options import resolve_options
    make = fixed_spline_parametric if spline else fixed_parametric
    problem = load_problem(ROOT / "examples" / f"{name}.toml")
    out = {}
    for arith in ("q15", "q31"):
        files, parts, _ = make(problem, f"{name}.toml", resolve_options(problem, arith=arith))
        out[arith] = (files, parts)
    return out


def fixed_spline_files(name: str) -> dict:
    """`fixed_point_files` of the fixed-point spline parametric controllers."""
    return fixed_point_files(name, spline=True)


def _qspline_flash(pf, gains, cols) -> str:
    from stospline.table.spline.fixed_point import q_spline_bytes
    from stospline.table.spline.qparams import column_flash_bytes
    cols_b = column_flash_bytes(pf, cols)
    return (f"gain spline {q_spline_bytes(gains)} B, columns {cols_b} B (per-tick columns "
            f"{pf.column_bytes()} B); columns' largest fit error {cols.error.max():.3g} LSB "
            f"({cols.relative.max():.2g} of the column's peak); error bound {_bound(pf)}")


def _bound(pf) -> str:
    """The error bound over the box per input: its largest over the ticks, in command LSB
    and in command units."""
    return (f"{', '.join(f'{b:.2f}' for b in pf.bound_lsb.max(axis=0))} command LSB "
            f"({', '.join(f'{b:.2g}' for b in pf.bound.max(axis=0))})")


def spline_files(problem, source_name: str):
    """``(files, sp)``: the C of the spline gain table and of its spline columns, as
    `stospline design FILE --table spline --out DIR` writes them (the same code:
    `stospline.pipeline.design_files` and `spline_parametric_files`)."""
    from stospline.options import resolve_options
    from stospline.pipeline import design_files, design_problem, spline_parametric_files
    d = design_problem(problem, options=resolve_options(problem, table="spline"))
    files, sp = spline_parametric_files(d, source_name)
    gains = design_files(d, source_name)[0]
    return {**{n: t for n, t in gains.items() if not n.endswith(".json")}, **files}, sp


def _spline_flash(sp) -> str:
    from stospline.table.flash import flash_bytes
    pt = sp.per_tick
    P = len(pt.parameters)
    tick_table = flash_bytes(pt.table.quantized())
    tick_cols = 4 * (3 * P + pt.S_k0.size + pt.S_lambda0.size)
    spl_table = flash_bytes(sp.table)
    spl_cols = 4 * (3 * P + sp.columns.coef.size + sp.columns.S_lambda0.size)
    peak = np.abs(pt.S_k0).max(axis=0)
    rel = float((sp.columns.error / np.where(peak > 0, peak, 1.0)).max())
    return (f"per-tick: table {tick_table} B + columns {tick_cols} B = "
            f"{tick_table + tick_cols} B; spline: table {spl_table} B + columns {spl_cols} B = "
            f"{spl_table + spl_cols} B ({(tick_table + tick_cols) / (spl_table + spl_cols):.1f}x "
            f"smaller); columns' largest error {sp.columns.error.max():.3g} "
            f"({rel:.2g} of the column's peak), on the command over the box "
            f"{sp.columns.box_error.max():.3g}")


def _certificate(problem, sp) -> str:
    from stospline.refine.spline_params import certify_over_box
    c = certify_over_box(problem, sp)
    parts = []
    for key in ("per_tick", "per_tick_float32", "spline_design_columns", "spline"):
        e = c[key]
        band = ("no bands" if e["worst_band_margin"] is None else
                f"worst band margin over the box {e['worst_band_margin']:.3g} "
                f"({'holds' if e['bands_hold'] else 'BROKEN'})")
        cor = "; ".join(f"corridor {k}: Cantelli over the box, worst tick "
                        f"{b['worst_tick']:.9f}, sum {b['total']:.3g}"
                        for k, b in enumerate(e["corridors"]))
        parts.append(f"{key}: {band}" + (f"; {cor}" if cor else ""))
    return " | ".join(parts)


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
