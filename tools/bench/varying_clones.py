"""The time-varying C loops with and without their AVX2 clones: the same bits, and the time.

Usage: .venv/bin/python tools/bench/varying_clones.py [--repeat 3]

``varying_kernel.c`` compiles its tick loops twice where GCC and glibc allow it (x86-64,
``target_clones("avx2", "default")``) and the loader picks the AVX2 copy on a CPU that has it.
This builds the kernels a second time with ``-DSTSP_TV_NO_CLONES`` (the default copy only) and
runs the dense benchmark problem of `varying_design.py` (noise varying, the segment operators)
through both: the design's gains and the oracle's cost and path variances must be equal bit
for bit (the clones add no FMA and reorder no sum). Prints a hash of each and the CPU time of
the design and of one oracle pass with each (medians of `--repeat`, after a warm-up; run on a
CPU with AVX2, else both are the default copy).
"""
from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse                                      # noqa: E402
import hashlib                                       # noqa: E402
import sys                                           # noqa: E402
import time                                          # noqa: E402
from pathlib import Path                             # noqa: E402

import numpy as np                                   # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from varying_design import dense_chain               # noqa: E402

from stospline.cache import KERNEL_CFLAGS, build_kernel_sources, load_module   # noqa: E402
from stospline.design import kernels, varying        # noqa: E402
from stospline.design.zoh import design_zoh          # noqa: E402
from stospline.oracle.evaluate import evaluate_table  # noqa: E402
from stospline.table.format import table_of          # noqa: E402


def run(module, problem, repeat: int):
    """Hash of the design's gains and the oracle's J and path variances, and the median CPU
    times of the design and of one oracle pass, with the kernels of `module`."""
    kernels._load = lambda: module
    varying._CACHE.clear()
    design = design_zoh(problem)
    table = table_of(design, quantize=False)
    moments = evaluate_table(problem, table, path=True)
    digest = hashlib.sha256()
    for stage in design.stages:
        digest.update(np.ascontiguousarray(stage.K).tobytes())
        digest.update(np.ascontiguousarray(stage.k0).tobytes())
    digest.update(np.float64(moments.J).tobytes())
    digest.update(np.ascontiguousarray(moments.path_var).tobytes())
    times = []
    for _ in range(repeat):
        c = time.process_time()
        design_zoh(problem)
        c1 = time.process_time()
        evaluate_table(problem, table, path=False)
        times.append((c1 - c, time.process_time() - c1))
    return digest.hexdigest()[:16], np.median(np.array(times), axis=0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    problem = dense_chain(True)
    clones = kernels.load_kernels()
    plain = load_module(build_kernel_sources("_stsp_kernels", kernels._SOURCES, kernels._CDEF,
                                             KERNEL_CFLAGS + ["-DSTSP_TV_NO_CLONES"]))
    results = {name: run(mod, problem, args.repeat)
               for name, mod in (("default only", plain), ("with AVX2 clones", clones))}
    print("| build | hash of gains, J, path variances | design CPU | oracle pass CPU |")
    print("|---|---|---|---|")
    for name, (digest, (t_design, t_oracle)) in results.items():
        print(f"| {name} | {digest} | {t_design * 1e3:.0f} ms | {t_oracle * 1e3:.0f} ms |")
    same = len({digest for digest, _ in results.values()}) == 1
    print(f"\nbit-identical: {same}")
    if not same:
        sys.exit(1)


if __name__ == "__main__":
    main()
