#!/usr/bin/env python3
"""The fault table of every shipped example (docs/evidence/faults.md): each fault of the loop
at a few levels relative to the plan (`stospline.harness.fault_sweep.default_levels`), the fault
oracle's exact numbers where the fault is linear beside Monte Carlo through the compiled C
controller, with the same seed for every row.

    .venv/bin/python tools/reports/fault_tables.py [--paths 2000] [--seed 1] [--out FILE]

Prints Markdown (to --out, atomically, when given). About a minute on 2 cores (the seven shipped examples).
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from stospline.atomic import write_file  # noqa: E402
from stospline.pipeline import design_problem, fault_sweep, plan_substeps  # noqa: E402
from stospline.problem import load_problem  # noqa: E402
from stospline.harness.fault_sweep import fault_table_markdown  # noqa: E402
from stospline.harness.montecarlo import faults_unsupported  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--paths", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    parts = ["# Faults of the loop: what each costs on the shipped examples\n",
             "How the faults are modelled, and which have an exact oracle: "
             "[problem-file guide, `[faults]`](../guide/problem-file.md#faults-faults-of-the-loop)."
             " The agreement of the fault oracle with Monte Carlo through the C controller is "
             "tested in `tests/python/sim/test_faults.py` (cost, knot means and knot variances,"
             " 99 % jointly, and the fault-free oracle rejected on the same runs).\n",
             f"## Fault tables ({args.paths} paths per row, seed {args.seed})\n",
             "Command: `.venv/bin/python tools/reports/fault_tables.py --paths "
             f"{args.paths} --seed {args.seed}`. Levels relative to the plan: sensor noise "
             "and the quantizer's step as fractions of each state's range (max |mean| + 3 sd "
             "over the plan), actuator noise as a fraction of each input's largest command "
             "in the fault-free run. '-': no exact oracle (quantization, missed ticks). "
             "Constraint bias: the largest |E{C x} - value| at a knot (for bands, outside "
             "the band); knot variance: the largest variance of a constrained output at a "
             "knot. The Monte Carlo bias includes the sampling error of the mean (the 'none' "
             "row shows its size). Every row uses the same plant noise (common random "
             "numbers), so rows differ by the fault, not by the sample.\n"]
    for path in sorted((ROOT / "examples").glob("*.toml")):
        problem = load_problem(path)
        d = design_problem(problem, **{k: v for k, v in problem.options.items()
                                       if k in ("mode", "discretization")})
        why_not = faults_unsupported(problem, d.table)
        if why_not:
            parts.append(f"### {path.relative_to(ROOT)}\n\nNo fault table: {why_not}.\n")
            continue
        substeps = plan_substeps(d, paths=args.paths, seed=args.seed).substeps
        rows = fault_sweep(d, paths=args.paths, seed=args.seed, substeps=substeps)
        parts.append(f"### {path.relative_to(ROOT)} ({problem.tick_hz} Hz, "
                     f"{d.table.n_ticks} ticks, {substeps} plant steps per tick)\n")
        parts.append(fault_table_markdown(rows))
        print(f"{path.name}: done", file=sys.stderr)
    text = "\n".join(parts)
    if args.out:
        write_file(args.out, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))
    else:
        print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
