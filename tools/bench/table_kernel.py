"""The table kernels against their numpy references: the composition of a stage's tick maps,
and the exact evaluation of a fixed-point spline stage with its error.

Usage: PYTHONPATH=host .venv/bin/python tools/bench/table_kernel.py [--ticks 6000] [--repeat 50]

Prints, for random affine blocks of the patrol's shape (a stage of `--ticks` ticks, n = 4
states, 4 multipliers: blocks 4 x 9), the median time of `stospline.table.kernels.
affine_compose` (C) and of `spline_latch._affine_product_numpy`, their ratio and the largest
difference of the results relative to their largest entry. Then, for a Q15 spline stage of the
patrol's shape (`--ticks` ticks, 18 entries, spans of 128 ticks, smooth coefficients), the
median time of `kernels.qspline_stage` (C, evaluated in full) and of `qspline._stage_gains`
plus numpy's error, their ratio, and whether the integers and errors are identical. BLAS on one
thread.
"""
from __future__ import annotations

import argparse
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from stospline.table.spline import fixed_point as qspline  # noqa: E402
from stospline.table.kernels import affine_compose, qspline_stage  # noqa: E402
from stospline.table.spline.latch import _affine_product_numpy  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_util import median_time  # noqa: E402


def _median(work, repeat: int) -> float:
    return median_time(work, repeat, warm_up=True)[0]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ticks", type=int, default=6000)
    ap.add_argument("--repeat", type=int, default=50)
    args = ap.parse_args()
    for name in ("ticks", "repeat"):
        if getattr(args, name) < 1:
            ap.error(f"--{name} must be at least 1, not {getattr(args, name)}")
    if args.ticks > 2_000_000:      # 36 doubles a tick, the numpy products twice that
        ap.error(f"--ticks {args.ticks} would hold {args.ticks * 36 * 8 * 3 / 1e9:.1f} GB of "
                 f"blocks; at most 2000000")
    rng = np.random.default_rng(0)
    P = rng.normal(size=(args.ticks, 4, 9)) * 0.1
    P[:, :, :4] += 0.99 * np.eye(4)
    if affine_compose(P) is None:
        raise SystemExit("the table kernel is not available on this host")
    c = _median(lambda: affine_compose(P), args.repeat)
    py = _median(lambda: _affine_product_numpy(P), args.repeat)
    a, b = affine_compose(P), _affine_product_numpy(P)
    print(f"{args.ticks} ticks, blocks 4x9: C {c * 1e3:.3f} ms, numpy {py * 1e3:.3f} ms, "
          f"ratio {py / c:.1f}x; largest difference {np.abs(a - b).max() / np.abs(b).max():.1e} "
          f"of the largest entry")

    k, E = 7, 18
    nb = ((args.ticks - 1) >> k) + 4
    x = np.linspace(0.0, 3.0, nb)
    C = np.array([np.round(20000 * np.sin(x + e)) for e in range(E)], dtype=np.int64)
    shift = np.full(E, 12)
    YT = qspline._stage_gains(k, C, shift, args.ticks).T + rng.normal(size=(E, args.ticks))
    numerators = qspline.basis_numerators(k, np.arange(args.ticks))

    def numpy_stage():
        G = qspline._stage_gains(k, C, shift, args.ticks, numerators)
        return G, np.abs(G.T - YT).max(axis=1)
    c = _median(lambda: qspline_stage(k, C, shift, YT), args.repeat)
    py = _median(numpy_stage, args.repeat)
    (G, err), (G_np, err_np) = qspline_stage(k, C, shift, YT), numpy_stage()
    same = np.array_equal(G, G_np) and np.array_equal(err, err_np)
    print(f"{args.ticks} ticks, Q15 spline stage of {E} entries, spans of {1 << k}: "
          f"C {c * 1e3:.3f} ms, numpy {py * 1e3:.3f} ms, ratio {py / c:.1f}x; "
          f"integers and errors identical: {same}")


if __name__ == "__main__":
    main()
