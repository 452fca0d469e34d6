"""The tick-grid QP (regions at every tick beyond 8 binding rows) as the tick rate grows.

Usage: .venv/bin/python tools/bench/tick_qp.py [--rates 100,1000,2000,5000]
           [--example examples/robot_monotone.toml]

For each rate, in a fresh process (so that the peak memory is the design's): the example
with its tick_hz replaced, designed by `stospline.design.tick_qp.design_tick_qp` alone (no
tables, no oracle): ticks, QP variables and rows, interior-point iterations, exact KKT
corrections, active region rows, J0, wall time (`time.perf_counter`) and peak resident memory
(`ru_maxrss`, which includes the interpreter and numpy/scipy, ~35 MB). BLAS pinned to one
thread. Figures are in docs/evidence/every-tick.md.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

CHILD = """
import json, resource, sys, time
from dataclasses import replace
import stospline
from stospline.design.tick_qp import design_tick_qp
p = replace(stospline.load_problem(sys.argv[1]), tick_hz=int(sys.argv[2]))
t = time.perf_counter()
d = design_tick_qp(p)
t = time.perf_counter() - t
print(json.dumps({"ticks": len(d.K), "variables": d.stats["variables"],
                  "rows": d.stats["rows"], "ipm": d.ipm_iterations, "corrections": d.rounds,
                  "active": d.summary_terms()["tick_qp"]["active_region_rows"],
                  "J0": d.J0, "seconds": t,
                  "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rates", default="100,1000,2000,5000")
    ap.add_argument("--example", default=str(ROOT / "examples" / "robot_monotone.toml"))
    args = ap.parse_args()
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1",
               MKL_NUM_THREADS="1")
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT / "host"), env.get("PYTHONPATH", "")])
    print(f"{Path(args.example).name}: design_tick_qp alone, one process per rate")
    print("| rate | ticks | variables | rows | interior-point iterations | corrections | "
          "active region rows | J0 | time | peak memory |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for rate in (int(r) for r in args.rates.split(",")):
        out = subprocess.run([sys.executable, "-c", CHILD, args.example, str(rate)], env=env,
                             capture_output=True, text=True, check=True)
        r = json.loads(out.stdout.strip().splitlines()[-1])
        print(f"| {rate} Hz | {r['ticks']} | {r['variables']} | {r['rows']} | {r['ipm']} | "
              f"{r['corrections']} | {r['active']} | {r['J0']:.10g} | {r['seconds']:.2f} s | "
              f"{r['peak_mb']:.0f} MB |")


if __name__ == "__main__":
    main()
