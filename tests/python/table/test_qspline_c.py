"""The firmware's fixed-point spline evaluation (firmware/src/stsp_qspline.c) against the host's
mirror (`stospline.table.spline.fixed_point.evaluate_q`), bit for bit, at every tick of the robot's Q15
and Q31 spline tables and of a random table at the format's extremes; its layout check takes
both; and the compiled per-tick Q controller on the spline's gains is the host's integer law.
(The controller does not run these tables yet: this is the evaluation it will call.)"""
import numpy as np
import pytest

from stospline.cache import cached_build, compile_cffi, load_module, source_key
from stospline.firmware_files import firmware_dir
from stospline.pipeline import design_problem, fixed_point_spline
from stospline.table.spline.fixed_point import MAX_SPAN_LOG2, QSplineGains, evaluate_q

SCALAR = {"q15": ("int16_t", np.int16), "q31": ("int32_t", np.int32)}
CDEF = """
typedef struct {
    uint32_t n_entries; uint32_t n_coef;
    const uint8_t *span_log2; const uint16_t *row_start; const uint8_t *col;
    const uint8_t *shift; const uint32_t *coef_start; const %(s)s *coef; ...;
} stsp_qspline_t;
int every_tick(const stsp_qspline_t *sp, const uint32_t *stage_start, uint32_t n_stages,
               uint32_t nu, uint32_t nz, %(s)s *out);
"""
SOURCE = """
#include "stsp_qspline.h"
int every_tick(const stsp_qspline_t *sp, const uint32_t *stage_start, uint32_t n_stages,
               uint32_t nu, uint32_t nz, stsp_scalar_t *out)
{
    const stsp_status_t st = stsp_qspline_check(sp, stage_start, n_stages, nu, nz);
    uint32_t s;
    if (st != STSP_OK) {
        return (int)st;
    }
    for (s = 0u; s < n_stages; ++s) {
        uint32_t t;
        for (t = stage_start[s]; t < stage_start[s + 1u]; ++t) {
            stsp_qspline_gains(sp, stage_start, s, nu, nz, t - stage_start[s],
                               &out[t * nu * nz]);
        }
    }
    return 0;
}
"""


def _module(arith):
    fw = firmware_dir()
    srcs = [fw / "src" / "stsp_qspline.c"]
    cdef = CDEF % {"s": SCALAR[arith][0]}
    flags = ["-std=c99", "-O2", "-Wall", "-Wextra", "-Werror",
             f"-DSTSP_ARITH_{arith.upper()}"]
    key = source_key([cdef, SOURCE, *flags, *(p.read_bytes() for p in srcs),
                      (fw / "src" / "stsp_qspline.h").read_bytes(),
                      (fw / "src" / "stsp_internal.h").read_bytes(),
                      *(p.read_bytes() for p in sorted((fw / "include").rglob("*.h")))])
    mod = f"_qspline_{arith}_{key}"
    path = cached_build(key, mod, lambda out: compile_cffi(
        out, mod, cdef, SOURCE, sources=srcs,
        include_dirs=[fw / "include", fw / "src"], cflags=flags))
    return load_module(path)


def _c_gains(sp: QSplineGains, stage_start):
    mod = _module(sp.arith)
    ffi, lib = mod.ffi, mod.lib
    start = np.ascontiguousarray(stage_start, dtype=np.uint32)
    nz = sp.nx + 1 + sp.n_latch
    out = np.full((int(start[-1]), sp.nu, nz), 77, dtype=SCALAR[sp.arith][1])
    keep = [np.ascontiguousarray(a) for a in (sp.span_log2, sp.row_start, sp.col, sp.shift,
                                              sp.coef_start, sp.coef)]
    c = ffi.new("stsp_qspline_t *")
    c.n_entries, c.n_coef = sp.n_entries, sp.coef.size
    for name, arr in zip(("span_log2", "row_start", "col", "shift", "coef_start", "coef"),
                         keep):
        setattr(c, name, ffi.cast(ffi.typeof(getattr(c, name)), ffi.from_buffer(arr)))
    st = lib.every_tick(c, ffi.cast("uint32_t *", ffi.from_buffer(start)),
                        sp.n_stages, sp.nu, nz,
                        ffi.cast(f"{SCALAR[sp.arith][0]} *", ffi.from_buffer(out)))
    assert st == 0
    return out


@pytest.fixture(scope="module")
def qtables(robot_problem):
    d = design_problem(robot_problem, table="spline")
    return {a: fixed_point_spline(d, a)[0] for a in SCALAR}


@pytest.mark.parametrize("arith", SCALAR)
def test_c_evaluates_the_robots_tables_bit_for_bit(qtables, arith):
    ft = qtables[arith]
    G = _c_gains(ft.spline, ft.stage_start).astype(np.int64)
    n = ft.dims[0]
    np.testing.assert_array_equal(G[:, :, :n], ft.K)
    np.testing.assert_array_equal(G[:, :, n], ft.k0)
    np.testing.assert_array_equal(G[:, :, n + 1:], ft.L)


@pytest.mark.parametrize("arith", SCALAR)
def test_c_evaluates_random_tables_at_the_extremes_bit_for_bit(arith):
    """Random layouts, 512-tick spans among others, coefficients over the type's whole range
    and shifts that keep every gain in it (6 max|c| / 2^s <= 2^(bits-1) - 1)."""
    rng = np.random.default_rng(13)
    bits = 16 if arith == "q15" else 32
    for _ in range(20):
        ns, nu, nx, n_latch = (int(rng.integers(1, 4)), int(rng.integers(1, 3)),
                               int(rng.integers(1, 4)), int(rng.integers(0, 3)))
        ticks = rng.integers(1, 1500, ns)
        start = np.r_[0, np.cumsum(ticks)]
        logs = rng.integers(0, MAX_SPAN_LOG2 + 1, ns)
        counts, cols, shifts, coefs = [], [], [], []
        for s in range(ns):
            stride = -(-int(ticks[s]) // (1 << int(logs[s]))) + 3
            for _i in range(nu):
                mine = np.sort(rng.choice(nx + 1 + n_latch,
                                          int(rng.integers(0, nx + 2 + n_latch)), replace=False))
                counts.append(mine.size)
                cols.append(mine)
                shifts.append(rng.integers(3, 31, mine.size))
                coefs.append(rng.integers(-2 ** (bits - 1), 2 ** (bits - 1),
                                          (mine.size, stride)).ravel())
        sp = QSplineGains(span_log2=logs, row_start=np.r_[0, np.cumsum(counts)],
                          col=np.concatenate(cols), shift=np.concatenate(shifts),
                          coef_start=np.r_[0, np.cumsum([c.size for c in
                                                         _per_stage(coefs, nu, ns)])],
                          coef=np.concatenate(coefs), arith=arith, nu=nu, nx=nx,
                          n_latch=n_latch)
        K, k0, L = evaluate_q(sp, start)
        G = _c_gains(sp, start).astype(np.int64)
        np.testing.assert_array_equal(G, np.concatenate([K, k0[:, :, None], L], axis=2))


def _per_stage(coefs, nu, ns):
    return [np.concatenate(coefs[s * nu:(s + 1) * nu]) for s in range(ns)]


@pytest.mark.parametrize("arith", SCALAR)
def test_compiled_q_law_on_the_splines_gains_is_the_hosts_and_within_the_bound(qtables, arith):
    """The spline's integer gains in the per-tick form (`replace(table, spline=None)`: the
    same integers at every tick) through the compiled Q controller: bit for bit the host's
    integer law (`law_q`) at 100 000 random in-range samples, and within the table's error
    bound of the design's double law. Together with the evaluation's equality above, this is
    the law the controller will run once it evaluates the splines itself."""
    from dataclasses import replace

    from stospline.harness.controller import build_controller
    from stospline.harness.fixed_point_error import random_q_samples
    from stospline.table.qformat import latch_q, law_double, law_q
    ft = qtables[arith]
    ctl = build_controller(replace(ft, spline=None))
    rng = np.random.default_rng(20261125)
    tick, ls, t_latch, X, XL = random_q_samples(ft, 100_000, rng)
    U, status = ctl.pair_steps(t_latch, XL, tick, X)
    assert status.min() >= 0
    V = latch_q(ft, np.maximum(ls, 0), XL)
    np.testing.assert_array_equal(U.astype(np.int64), law_q(ft, tick, X, V))
    err = np.abs(U * ft.u_lsb - law_double(ft, tick, X * ft.x_lsb, XL * ft.x_lsb))
    assert (err / ft.bound[tick]).max() <= 1.0
