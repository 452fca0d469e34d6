#!/usr/bin/env python3
"""Standard normal numbers in C: the harness's generator against numpy's C library, in the
same run.

Times, per number, filling a 2^19-double buffer from C (one call, no Python per number):

* **ours**: `stospline/harness/normals.c` (xoshiro256++ words through a 256-layer ziggurat, inlined);
* **numpy zig + our xoshiro**: numpy's ``random_standard_normal`` (its ziggurat, from
  ``numpy/random/lib/libnpyrandom.a``, found through ``numpy.get_include()``) with the same
  xoshiro256++ behind a ``bitgen_t``: the cost of numpy's ziggurat and its per-word indirect
  call;
* **numpy C PCG64 / SFC64 / PCG64DXSM**: ``random_standard_normal`` on numpy's own bit
  generators (their ``ctypes.bit_generator``), what a switch to numpy's library would run;
* **numpy Generator**: ``Generator.standard_normal(out=...)`` from Python.

Rounds interleave the variants (CPU time of two fills each); prints the median time per
number and the median over rounds of each one's ratio to ours.

    PYTHONPATH=host .venv/bin/python tools/bench/normal_generators.py [--rounds 25]
"""
from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

SIM = Path(__file__).resolve().parents[2] / "host" / "stospline" / "harness"

_CDEF = """
double numpy_normals(void *bitgen, double *out, size_t n);
double numpy_normals_xoshiro(uint64_t *s, double *out, size_t n);
void harness_normals(uint64_t *state, double *out, size_t count);
"""

_SOURCE = r"""
#include <stdint.h>
#include <stddef.h>
#include "numpy/random/distributions.h"
void harness_normals(uint64_t *state, double *out, size_t count);
double numpy_normals(void *bg, double *out, size_t n) {
    bitgen_t *b = (bitgen_t *)bg; size_t i;
    for (i = 0; i < n; ++i) out[i] = random_standard_normal(b);
    return out[0];
}
static uint64_t rotl(uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }
static uint64_t xo_next(void *st) {          /* xoshiro256++, as normals.c */
    uint64_t *s = (uint64_t *)st;
    const uint64_t out = rotl(s[0] + s[3], 23) + s[0];
    const uint64_t t = s[1] << 17;
    s[2] ^= s[0]; s[3] ^= s[1]; s[1] ^= s[2]; s[0] ^= s[3]; s[2] ^= t; s[3] = rotl(s[3], 45);
    return out;
}
static double xo_double(void *st) { return (double)(xo_next(st) >> 11) * 0x1p-53; }
static uint32_t xo_u32(void *st) { return (uint32_t)(xo_next(st) >> 32); }
double numpy_normals_xoshiro(uint64_t *s, double *out, size_t n) {
    bitgen_t b; size_t i;
    b.state = s; b.next_uint64 = xo_next; b.next_uint32 = xo_u32; b.next_double = xo_double;
    b.next_raw = xo_next;
    for (i = 0; i < n; ++i) out[i] = random_standard_normal(&b);
    return out[0];
}
"""


def build(tmp: str):
    """The bench module: our normals.c and numpy's libnpyrandom.a in one cffi module."""
    import importlib.util
    import cffi
    ffib = cffi.FFI()
    ffib.cdef(_CDEF)
    ffib.set_source("_normal_bench", _SOURCE, sources=[str(SIM / "normals.c")],
                    include_dirs=[np.get_include(), str(SIM)],
                    library_dirs=[str(Path(np.__file__).parent / "random" / "lib")],
                    libraries=["npyrandom", "m"], extra_compile_args=["-O3", "-std=c99"])
    path = ffib.compile(tmpdir=tmp)
    spec = importlib.util.spec_from_file_location("_normal_bench", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.ffi, mod.lib


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=25)
    args = ap.parse_args()
    size = 1 << 19
    with tempfile.TemporaryDirectory() as tmp:
        ffi, lib = build(tmp)
        out = np.empty(size)
        pout = ffi.from_buffer("double[]", out)
        words = [np.array([1, 2, 3, 4], np.uint64), np.array([5, 6, 7, 8], np.uint64)]
        ours, theirs = (ffi.from_buffer("uint64_t[]", w) for w in words)
        variants = {"ours": lambda: lib.harness_normals(ours, pout, size),
                    "numpy zig + our xoshiro": lambda: lib.numpy_normals_xoshiro(theirs, pout,
                                                                                 size)}
        bitgens = [getattr(np.random, name)(1) for name in ("PCG64", "SFC64", "PCG64DXSM")]
        for bg in bitgens:
            c = ffi.cast("void *", bg.ctypes.bit_generator.value)
            variants[f"numpy C {type(bg).__name__}"] = (
                lambda c=c: lib.numpy_normals(c, pout, size))
        rng = np.random.default_rng(1)
        variants["numpy Generator"] = lambda: rng.standard_normal(out=out)
        times = {k: [] for k in variants}
        for _ in range(args.rounds):
            for name, fill in variants.items():
                start = time.process_time()
                fill()
                fill()
                times[name].append((time.process_time() - start) / (2 * size) * 1e9)
        print(f"standard normal numbers from C, {size} per fill, {args.rounds} rounds, "
              f"numpy {np.__version__}, {os.cpu_count()} CPUs reported")
        print(f"{'generator':26s} {'ns/number':>10s} {'ratio to ours':>14s}")
        base = times["ours"]
        for name, ts in times.items():
            ratio = statistics.median(t / b for t, b in zip(ts, base))
            print(f"{name:26s} {statistics.median(ts):10.2f} {ratio:14.2f}")


if __name__ == "__main__":
    main()
