/* Unit tests of the fixed-point spline gains (firmware/src/stsp_qspline.c) on a hand-made
 * table Q, against tests/c/qspline_reference.py (exact rationals, independent of the
 * firmware and of the host's stospline.table.spline.fixed_point): every gain of every tick, bit for bit;
 * the exact value at the format's extremes (int16/int32 coefficients alternating between the
 * type's ends, 512-tick spans, shifts 1 and 30), where the int64 sum is largest; the basis
 * numerators sum to 6 D^3; the layout check refuses each broken rule. Built for Q15 and Q31,
 * each also under ASan + UBSan (a signed overflow aborts). */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "stospline/stsp_controller.h"
#include "stsp_qspline.h"

#ifndef STSP_ARITH_FIXED_POINT
#error "test_qspline.c tests the STSP_ARITH_Q15/Q31 builds"
#endif

#include "qspline_table_q.h"

static void every_gain_of_every_tick(void **state)
{
    static const int64_t expected[N_TICKS][NU * NZ] = QSPLINE_EXPECTED;
    const stsp_qspline_t q = table_q();
    uint32_t t;
    (void)state;
    assert_int_equal(stsp_qspline_check(&q, stage_start, NS, NU, NZ), STSP_OK);
    for (t = 0u; t < N_TICKS; ++t) {
        const uint32_t s = (t < stage_start[1]) ? 0u : 1u;
        stsp_scalar_t g[NU * NZ];
        uint32_t i;
        memset(g, 0x5a, sizeof g); /* every element written */
        stsp_qspline_gains(&q, stage_start, s, NU, NZ, t - stage_start[s], g);
        for (i = 0u; i < (NU * NZ); ++i) {
            assert_int_equal((int64_t)g[i], expected[t][i]);
        }
    }
}

static void exact_at_the_extremes(void **state)
{
#if defined(STSP_ARITH_Q15)
    static const int64_t expected[12] = QSPLINE_EXTREME_Q15;
    const stsp_scalar_t lo = INT16_MIN;
    const stsp_scalar_t hi = INT16_MAX;
#else
    static const int64_t expected[12] = QSPLINE_EXTREME_Q31;
    const stsp_scalar_t lo = INT32_MIN;
    const stsp_scalar_t hi = INT32_MAX;
#endif
    static const uint32_t ticks[6] = {0u, 1u, 255u, 511u, 512u, 1023u};
    static const uint32_t shifts[2] = {1u, 30u};
    const stsp_scalar_t c[5] = {lo, hi, lo, hi, lo};
    uint32_t a;
    uint32_t b;
    (void)state;
    for (a = 0u; a < 2u; ++a) {
        for (b = 0u; b < 6u; ++b) {
            uint32_t p[4];
            const uint32_t sigma = stsp_qspline_basis(9u, ticks[b], p);
            assert_int_equal(stsp_qspline_value(&c[sigma], p, 27u + shifts[a]),
                             expected[(a * 6u) + b]);
        }
    }
}

static void basis_sums_to_six_d_cubed(void **state)
{
    uint32_t k;
    (void)state;
    for (k = 0u; k <= STSP_QSPLINE_MAX_SPAN_LOG2; ++k) {
        const uint32_t D = (uint32_t)1u << k;
        uint32_t tau;
        for (tau = 0u; tau < (2u * D); ++tau) {
            uint32_t p[4];
            assert_int_equal(stsp_qspline_basis(k, tau, p), tau >> k);
            assert_int_equal((uint64_t)p[0] + p[1] + p[2] + p[3], 6u * D * D * D);
            assert_true(p[1] <= (4u * D * D * D));
        }
    }
}

static void check_refuses_broken_layouts(void **state)
{
    stsp_qspline_t q = table_q();
    static const uint8_t big_k[NS] = {10u, 0u};
    (void)state;
    assert_int_equal(stsp_qspline_check(NULL, stage_start, NS, NU, NZ), STSP_ERR_NULL);
    q.coef = NULL;
    assert_int_equal(stsp_qspline_check(&q, stage_start, NS, NU, NZ), STSP_ERR_NULL);
    q = table_q();
    q.span_log2 = big_k; /* 1024-tick spans */
    assert_int_equal(stsp_qspline_check(&q, stage_start, NS, NU, NZ), STSP_ERR_BAD_DIMS);
    q = table_q();
    q.n_coef = 47u;
    assert_int_equal(stsp_qspline_check(&q, stage_start, NS, NU, NZ), STSP_ERR_BAD_DIMS);
    q.n_coef = 48u;
    assert_int_equal(stsp_qspline_check(&q, stage_start, NS, NU, NZ - 1u), STSP_ERR_BAD_DIMS);
    shift[4] = 0u;
    assert_int_equal(stsp_qspline_check(&q, stage_start, NS, NU, NZ), STSP_ERR_BAD_DIMS);
    shift[4] = 31u;
    assert_int_equal(stsp_qspline_check(&q, stage_start, NS, NU, NZ), STSP_ERR_BAD_DIMS);
    shift[4] = 30u;
    col[1] = 0u; /* not increasing in the row */
    assert_int_equal(stsp_qspline_check(&q, stage_start, NS, NU, NZ), STSP_ERR_BAD_DIMS);
    col[1] = 2u;
    coef_start[1] = 17u; /* stage 0: 17 coefficients for 3 entries of 6 */
    assert_int_equal(stsp_qspline_check(&q, stage_start, NS, NU, NZ), STSP_ERR_BAD_DIMS);
    coef_start[1] = 18u;
    row_start[2] = 2u; /* row_start[3] = 4: nondecreasing, but stage 0 then has 2 entries */
    assert_int_equal(stsp_qspline_check(&q, stage_start, NS, NU, NZ), STSP_ERR_BAD_DIMS);
    row_start[2] = 3u;
    row_start[1] = 4u; /* decreasing */
    assert_int_equal(stsp_qspline_check(&q, stage_start, NS, NU, NZ), STSP_ERR_BAD_DIMS);
    row_start[1] = 2u;
    assert_int_equal(stsp_qspline_check(&q, stage_start, NS, NU, NZ), STSP_OK);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(every_gain_of_every_tick),
        cmocka_unit_test(exact_at_the_extremes),
        cmocka_unit_test(basis_sums_to_six_d_cubed),
        cmocka_unit_test(check_refuses_broken_layouts),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
