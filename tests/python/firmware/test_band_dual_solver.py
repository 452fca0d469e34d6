"""The firmware's exact band-dual solver (firmware/src/stsp_bandqp.c), compiled through cffi,
against the host's OSQP solution: from perturbed start states the target recomputes the
multipliers so that a started trajectory still meets its bands."""
from pathlib import Path

import numpy as np
import pytest

from stospline.design.bands import design_bands, solve_band_dual
from support.band_problems import random_band_problem, robot_with_bands

ROOT = Path(__file__).resolve().parents[3]
SRC = ROOT / "firmware" / "src" / "stsp_bandqp.c"

CDEF = """
typedef int... stsp_bandqp_status_t;
typedef struct { uint16_t q; uint16_t nx; const double *Nt; const double *mt; const double *W;
                 const double *lo; const double *hi; ...; } stsp_bandqp_t;
typedef struct { ...; } stsp_bandqp_work_t;
stsp_bandqp_status_t stsp_bandqp_solve(const stsp_bandqp_t *qp, const float *x0, double *lam,
                                       stsp_bandqp_work_t *work, uint32_t *candidates);
"""


@pytest.fixture(scope="module")
def bandqp():
    # Through the build cache (stospline.cache): built in a private directory and renamed into
    # place, so that parallel test workers building the same module at once do not race.
    from stospline.cache import cached_build, compile_cffi, load_module, source_key
    header = ROOT / "firmware/include/stospline/stsp_bandqp.h"
    key = source_key([SRC.read_bytes(), CDEF, header.read_bytes()])
    name = f"_stsp_bandqp_{key}"

    def build(out: Path) -> Path:
        return compile_cffi(out, name, CDEF, '#include "stospline/stsp_bandqp.h"',
                            sources=[SRC], include_dirs=[ROOT / "firmware" / "include"],
                            cflags=["-std=c99", "-O2"])

    return load_module(cached_build(key, name, build))


def solve_c(mod, base_stage0, lo, hi, x0):
    ffi, lib = mod.ffi, mod.lib
    q, n = base_stage0.N0.shape[1], base_stage0.N0.shape[0]
    arrays = [np.ascontiguousarray(a, dtype=float) for a in
              (base_stage0.N0.T, base_stage0.m0, base_stage0.W0, lo, hi)]
    qp = ffi.new("stsp_bandqp_t *", {"q": q, "nx": n})
    ptrs = [ffi.from_buffer("double[]", a) for a in arrays]
    qp.Nt, qp.mt, qp.W, qp.lo, qp.hi = ptrs
    lam = np.zeros(q)
    cand = ffi.new("uint32_t *")
    work = ffi.new("stsp_bandqp_work_t *")
    x = np.ascontiguousarray(x0, dtype=np.float32)
    status = lib.stsp_bandqp_solve(qp, ffi.from_buffer("float[]", x),
                                   ffi.from_buffer("double[]", lam), work, cand)
    return status, lam, cand[0]


@pytest.mark.parametrize("seed", range(8))
def test_target_solver_matches_host_from_perturbed_x0(bandqp, seed):
    problem = random_band_problem(seed)
    b = design_bands(problem)
    st0 = b.base.stages[0]
    if st0.N0.shape[1] > 8:
        pytest.skip("more rows than the target solver takes")
    band_rows = int(np.sum(b.lower != b.upper))
    rng = np.random.default_rng(100 + seed)
    for trial in range(5):
        x0 = (problem.x0 + 0.5 * rng.normal(size=problem.n)).astype(np.float32)
        e = st0.N0.T @ x0.astype(float) + st0.m0
        host = solve_band_dual(e, st0.W0, b.lower, b.upper)
        status, lam, cand = solve_c(bandqp, st0, b.lower, b.upper, x0)
        assert status == 0
        assert cand <= 3 ** band_rows                     # the proven bound
        scale = max(1.0, np.abs(host.lam).max())
        np.testing.assert_allclose(lam, host.lam, rtol=0, atol=1e-7 * scale)
        y = e - st0.W0 @ lam
        assert np.all(y >= b.lower - 1e-9) and np.all(y <= b.upper + 1e-9)


def test_target_solver_on_robot_bands_and_bad_inputs(bandqp):
    problem = robot_with_bands()
    b = design_bands(problem)
    st0 = b.base.stages[0]
    status, lam, cand = solve_c(bandqp, st0, b.lower, b.upper, problem.x0)
    assert status == 0 and cand <= 3 ** 2
    np.testing.assert_allclose(lam, b.solution.lam, atol=1e-7 * np.abs(lam).max())
    bad = problem.x0.copy()
    bad[1] = np.nan
    status, lam, _ = solve_c(bandqp, st0, b.lower, b.upper, bad)
    assert status == -3 and not np.any(lam)


@pytest.mark.parametrize("seed", range(6))
def test_target_solver_on_non_symmetric_p_matrices(bandqp, seed):
    """A spline table's W' (not symmetric, a P-matrix: `stospline.table.spline.band`): the
    C solver's Gaussian-elimination path against the host's numpy enumeration, and both
    against the conditions (a P-matrix: the solution is unique). W' = SPD + a skew-symmetric
    part (x'W'x = x'(SPD)x > 0: every principal submatrix positive definite in that sense, so a
    P-matrix); q = 2..7 rows, some of them equalities."""
    from types import SimpleNamespace
    from stospline.table.spline.band import is_p_matrix, solve_band_lcp
    rng = np.random.default_rng(700 + seed)
    q, n = 2 + seed, 3
    G = rng.normal(size=(q, q))
    S = rng.normal(size=(q, q))
    skew = (0.05 + 0.03 * seed) * np.linalg.norm(G, 2) ** 2 * (S - S.T) / q
    W = G @ G.T + 0.5 * np.eye(q) + skew
    assert not np.array_equal(W, W.T) and is_p_matrix(W)[0]
    Nt, mt = rng.normal(size=(q, n)), rng.normal(size=q)
    a, b = rng.normal(scale=2, size=q), rng.normal(scale=2, size=q)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    eq = rng.random(q) < 0.3
    lo[eq] = hi[eq]
    stage = SimpleNamespace(N0=Nt.T, m0=mt, W0=W)
    active_seen = set()
    for trial in range(10):
        x0 = (3 * rng.normal(size=n)).astype(np.float32)
        e = Nt @ x0.astype(float) + mt
        status, lam, cand = solve_c(bandqp, stage, lo, hi, x0)
        assert status == 0 and 1 <= cand <= 3 ** int(np.sum(~eq))
        host, active = solve_band_lcp(e, W, lo, hi)
        np.testing.assert_allclose(lam, host, rtol=0, atol=1e-10 * max(1.0, np.abs(host).max()))
        y = e - W @ lam
        tol = 1e-9 * (1 + np.abs(hi))
        assert np.all(y >= lo - tol) and np.all(y <= hi + tol)
        at_hi, at_lo = np.abs(y - hi) <= tol, np.abs(y - lo) <= tol
        assert np.all(lam[~eq & ~at_hi] <= 1e-12) and np.all(lam[~eq & ~at_lo] >= -1e-12)
        active_seen.update(int(v) for v in active[~eq])
    assert active_seen >= {-1, 1} or q < 3        # both bounds reached somewhere
