/* Unit tests of the fixed-point (Q15/Q31) controller variants on hand-made tables, checked
 * against a reference written here in int64 with floor division (not the firmware's biased
 * shift). Built for STSP_ARITH_Q15 and STSP_ARITH_Q31, the Q15 build fixed to 2/1/2, and under
 * ASan + UBSan (CMakeLists.txt), where a signed overflow in the law or the latch aborts: the
 * extreme-value test drives every row to its largest allowed sum with states at +-2^F. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "stospline/stsp_controller.h"
#include "test_support.h"

#ifndef STSP_ARITH_FIXED_POINT
#error "test_fixedpoint.c tests the STSP_ARITH_Q15/Q31 builds"
#endif

#include "table_a.h"

#define F STSP_Q_FRAC_BITS
#define ONE ((int64_t)1 << F)
#define QMAX ((stsp_scalar_t)(ONE - 1))
#define QMIN ((stsp_scalar_t)(-ONE))

static const int8_t x_exp[NX] = {2, -3};
static const int8_t u_exp[NU] = {4};
static const int8_t v_exp[N_LATCH] = {1, 0};

/* Gains as fractions of 2^F so that both variants use the same table shape. Tick 0: K = (1, 0)
 * units, nothing else: the rounding test. Row sums stay well below 2^F - 1. */
static stsp_scalar_t K[NT * NU * NX], k0[NT * NU], L[NT * NU * N_LATCH];
static stsp_scalar_t Lambda[NS * N_LATCH * NX], lambda0[NS * N_LATCH];
static stsp_scalar_t no_min[NU], no_max[NU], zero_hold[NU];

static stsp_scalar_t frac(double f)
{
    return (stsp_scalar_t)(int64_t)(f * (double)ONE + ((f >= 0.0) ? 0.5 : -0.5));
}

static void fill_gains(void)
{
    static const double kf[NT * NX] = {0.0, 0.0, 0.11, -0.21, 0.12, -0.22, 0.13, -0.23,
                                       0.14, -0.24};
    static const double k0f[NT] = {0.0, 0.05, -0.06, 0.07, -0.08};
    static const double lf[NT * N_LATCH] = {0.0, 0.0, 0.2, 0.0, 0.25, 0.0, 0.1, -0.1, 0.15, -0.15};
    static const double lamf[NS * N_LATCH * NX] = {0.3, 0.4, 0.0, 0.0, -0.35, 0.15, 0.05, 0.3};
    static const double lam0f[NS * N_LATCH] = {-0.1, 0.0, 0.2, -0.25};
    uint32_t i;
    for (i = 0u; i < NT * NX; ++i) {
        K[i] = frac(kf[i]);
    }
    K[0] = 1; /* tick 0: u = rhu(x0 / 2^F) */
    for (i = 0u; i < NT; ++i) {
        k0[i] = frac(k0f[i]);
    }
    for (i = 0u; i < NT * N_LATCH; ++i) {
        L[i] = frac(lf[i]);
    }
    for (i = 0u; i < NS * N_LATCH * NX; ++i) {
        Lambda[i] = frac(lamf[i]);
    }
    for (i = 0u; i < NS * N_LATCH; ++i) {
        lambda0[i] = frac(lam0f[i]);
    }
    no_min[0] = QMIN;
    no_max[0] = QMAX;
}

static stsp_table_t make_table_limited(const stsp_scalar_t *lo, const stsp_scalar_t *hi)
{
    stsp_table_t t = table_header(NX, NU, N_LATCH, NS, NT, 10u);
    t.stage_start = stage_start; t.stage_n_latch = stage_n_latch;
    t.K = K; t.k0 = k0; t.L = L; t.Lambda = Lambda; t.lambda0 = lambda0;
    t.u_min = lo; t.u_max = hi; t.u_hold = zero_hold;
    t.x_exp = x_exp; t.u_exp = u_exp; t.v_exp = v_exp;
    t.crc32 = stsp_table_crc32(&t);
    return t;
}

static stsp_table_t make_table(void)
{
    return make_table_limited(no_min, no_max);
}

/* The safe command in Q units: a table with u_min > 0 and u_hold inside is valid, one with
 * u_hold outside the limits is refused, and a refused step (a tick past the plan) writes
 * u_hold. */
static void test_safe_command(void **state)
{
    stsp_scalar_t lo[NU], hi[NU], hold[NU];
    const stsp_scalar_t x[NX] = {0, 0};
    stsp_scalar_t u[NU];
    stsp_ctrl_t c;
    stsp_table_t t;
    (void)state;
    lo[0] = frac(0.125); hi[0] = frac(0.75); hold[0] = frac(0.25);
    t = make_table_limited(lo, hi);
    t.u_hold = hold;
    t.crc32 = stsp_table_crc32(&t);
    assert_int_equal(stsp_init(&c, &t), STSP_OK);
    u[0] = 0;
    assert_int_equal(stsp_step(&c, NT, x, u), STSP_ERR_TICK_RANGE);
    assert_int_equal(u[0], hold[0]);
    hold[0] = frac(0.875);                                 /* above u_max */
    t.crc32 = stsp_table_crc32(&t);
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_VALUES);
    hold[0] = frac(0.0625);                                /* below u_min */
    t.crc32 = stsp_table_crc32(&t);
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_VALUES);
}

static int setup(void **state)
{
    (void)state;
    fill_gains();
    return 0;
}

/* floor(a / 2^F + 1/2) by integer division (C truncates toward zero; step down if negative). */
static int64_t ref_round(int64_t sum)
{
    const int64_t a = sum + ONE / 2;
    int64_t q = a / ONE;
    if ((a % ONE) != 0 && a < 0) {
        q -= 1;
    }
    return q;
}

static void ref_latch(const stsp_table_t *t, uint32_t s, const stsp_scalar_t *x, int64_t *v)
{
    uint32_t c, j;
    for (c = 0u; c < N_LATCH; ++c) {
        int64_t sum = (int64_t)t->lambda0[s * N_LATCH + c] * ONE;
        for (j = 0u; j < NX; ++j) {
            sum += (int64_t)t->Lambda[(s * N_LATCH + c) * NX + j] * x[j];
        }
        v[c] = (c < t->stage_n_latch[s]) ? ref_round(sum) : 0;
    }
}

static int64_t ref_law(const stsp_table_t *t, uint32_t tick, const stsp_scalar_t *x,
                       const int64_t *v)
{
    int64_t sum = (int64_t)t->k0[tick] * ONE;
    uint32_t j;
    for (j = 0u; j < NX; ++j) {
        sum += (int64_t)t->K[tick * NX + j] * x[j];
    }
    for (j = 0u; j < N_LATCH; ++j) {
        sum += (int64_t)t->L[tick * N_LATCH + j] * v[j];
    }
    return ref_round(sum);
}

/* Seeded LCG: states over the whole Q range, the ends included now and then. */
static uint64_t lcg_state = 12345u;
static stsp_scalar_t random_q(void)
{
    uint32_t r;
    lcg_state = lcg_state * 6364136223846793005ull + 1442695040888963407ull;
    r = (uint32_t)(lcg_state >> 32);
    if ((r & 15u) == 0u) {
        return ((r & 16u) != 0u) ? QMAX : QMIN;
    }
#if F == 15
    return (stsp_scalar_t)(int16_t)(uint16_t)(r >> 8);
#else
    return (stsp_scalar_t)r;
#endif
}

static void test_law_matches_reference(void **state)
{
    stsp_table_t t = make_table();
    uint32_t trial;
    (void)state;
    for (trial = 0u; trial < 2000u; ++trial) {
        stsp_ctrl_t c;
        stsp_scalar_t xl[NX], x[NX], u[NU];
        int64_t v[N_LATCH];
        uint32_t tick;
        assert_int_equal(stsp_init(&c, &t), STSP_OK);
        for (tick = 0u; tick < NT; ++tick) {
            x[0] = random_q();
            x[1] = random_q();
            if (tick == 0u || tick == stage_start[1]) {
                memcpy(xl, x, sizeof xl);
                ref_latch(&t, (tick == 0u) ? 0u : 1u, xl, v);
            }
            assert_int_equal(stsp_step(&c, tick, x, u), STSP_OK);
            assert_true((int64_t)u[0] == ref_law(&t, tick, x, v));
        }
    }
}

static void test_rounding_is_half_up(void **state)
{
    stsp_table_t t = make_table();
    stsp_ctrl_t c;
    /* tick 0: u = rhu(x0 / 2^F); x0 = +-2^(F-1) is a tie: up for both signs. */
    stsp_scalar_t x[NX], u[NU];
    (void)state;
    assert_int_equal(stsp_init(&c, &t), STSP_OK);
    x[1] = 0;
    x[0] = (stsp_scalar_t)(ONE / 2);
    assert_int_equal(stsp_step(&c, 0u, x, u), STSP_OK);
    assert_int_equal(u[0], 1);
    x[0] = (stsp_scalar_t)(-ONE / 2);
    assert_int_equal(stsp_step(&c, 0u, x, u), STSP_WARN_TICK_REPEATED);
    assert_int_equal(u[0], 0);
    x[0] = (stsp_scalar_t)(-ONE / 2 - 1);
    assert_int_equal(stsp_step(&c, 0u, x, u), STSP_WARN_TICK_REPEATED);
    assert_int_equal(u[0], -1);
    x[0] = QMIN;
    assert_int_equal(stsp_step(&c, 0u, x, u), STSP_WARN_TICK_REPEATED);
    assert_int_equal(u[0], -1);
}

/* Extreme table: every law row and latch row at the largest allowed absolute sum 2^F - 1,
 * states at the Q range ends in every sign pattern: the result matches the reference and
 * stays within +-(2^F - 1); under UBSan an accumulator overflow would abort. */
static stsp_scalar_t xk[NT * NU * NX], xk0[NT * NU], xl_[NT * NU * N_LATCH];
static stsp_scalar_t xlam[NS * N_LATCH * NX], xlam0[NS * N_LATCH];

static stsp_table_t make_extreme(int sign)
{
    stsp_table_t t = make_table();
    const stsp_scalar_t q4 = (stsp_scalar_t)(sign * (ONE / 4));
    const stsp_scalar_t q8 = (stsp_scalar_t)(sign * (ONE / 8));
    const stsp_scalar_t q2 = (stsp_scalar_t)(sign * (ONE / 2));
    uint32_t i;
    for (i = 0u; i < NT; ++i) {
        xk[i * NX] = q4;
        xk[i * NX + 1u] = (stsp_scalar_t)-q4;
        xk0[i] = q4;
        xl_[i * N_LATCH] = q8;
        xl_[i * N_LATCH + 1u] = (stsp_scalar_t)(-(q8 - sign)); /* 3/4 + 1/8 + 1/8 - 1 LSB */
    }
    for (i = 0u; i < NS * N_LATCH; ++i) {
        xlam0[i] = q2;
        xlam[i * NX] = (stsp_scalar_t)-q4;
        xlam[i * NX + 1u] = (stsp_scalar_t)(q4 - sign); /* 1/2 + 1/4 + 1/4 - 1 LSB */
    }
    t.K = xk; t.k0 = xk0; t.L = xl_; t.Lambda = xlam; t.lambda0 = xlam0;
    t.crc32 = stsp_table_crc32(&t);
    return t;
}

static void test_extreme_rows_do_not_overflow(void **state)
{
    int sign;
    (void)state;
    for (sign = -1; sign <= 1; sign += 2) {
        stsp_table_t t = make_extreme(sign);
        uint32_t pattern;
        for (pattern = 0u; pattern < 16u; ++pattern) {
            stsp_ctrl_t c;
            stsp_scalar_t x[NX], xl[NX], u[NU];
            int64_t v[N_LATCH];
            uint32_t tick;
            xl[0] = (pattern & 1u) ? QMAX : QMIN;
            xl[1] = (pattern & 2u) ? QMAX : QMIN;
            x[0] = (pattern & 4u) ? QMAX : QMIN;
            x[1] = (pattern & 8u) ? QMAX : QMIN;
            assert_int_equal(stsp_init(&c, &t), STSP_OK);
            for (tick = 0u; tick < NT; ++tick) {
                const stsp_scalar_t *xs = (tick == 0u || tick == 3u) ? xl : x;
                if (tick == 0u || tick == 3u) {
                    ref_latch(&t, (tick == 0u) ? 0u : 1u, xl, v);
                }
                assert_int_equal(stsp_step(&c, tick, xs, u), STSP_OK);
                assert_true((int64_t)u[0] == ref_law(&t, tick, xs, v));
                assert_true((int64_t)u[0] <= (int64_t)QMAX && (int64_t)u[0] >= -(int64_t)QMAX);
            }
            /* The largest latch magnitude is reached: |v| = 2^F - 1 for some pattern. */
            if ((pattern & 3u) == 2u) {
                assert_true(v[0] == (int64_t)QMAX || v[0] == -(int64_t)QMAX);
            }
        }
    }
}

static void test_row_sum_over_limit_is_refused(void **state)
{
    stsp_ctrl_t c;
    stsp_table_t t = make_extreme(1);
    (void)state;
    assert_int_equal(stsp_init(&c, &t), STSP_OK);
    xk0[2] = (stsp_scalar_t)(xk0[2] + 1); /* law row at tick 2: 2^F */
    t.crc32 = stsp_table_crc32(&t);
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_VALUES);
    {
        stsp_scalar_t x[NX] = {0, 0}, u[NU] = {7};
        assert_int_equal(stsp_step(&c, 0u, x, u), STSP_ERR_NOT_INITIALIZED);
        assert_int_equal(u[0], 7);
    }
    t = make_extreme(-1);
    assert_int_equal(stsp_init(&c, &t), STSP_OK);
    xlam0[3] = (stsp_scalar_t)(xlam0[3] - 1); /* latch row (stage 1, c = 1): 2^F */
    t.crc32 = stsp_table_crc32(&t);
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_VALUES);
    t = make_extreme(-1);
    xl_[NT * N_LATCH - 1u] = QMIN; /* one huge entry */
    t.crc32 = stsp_table_crc32(&t);
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_VALUES);
}

static void test_wrong_variant_and_scales_are_refused(void **state)
{
    stsp_ctrl_t c;
    stsp_table_t t = make_table();
    int8_t bad_exp[NX] = {2, -3};
    (void)state;
    t.scalar_kind = STSP_SCALAR_FLOAT32;
    t.crc32 = stsp_table_crc32(&t);
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_VERSION);
    t.scalar_kind = (STSP_SCALAR_KIND == STSP_SCALAR_Q15) ? STSP_SCALAR_Q31 : STSP_SCALAR_Q15;
    t.crc32 = stsp_table_crc32(&t);
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_VERSION);

    t = make_table();
    t.x_exp = bad_exp;
    bad_exp[1] = (int8_t)(STSP_Q_EXP_MAX + 1);
    t.crc32 = stsp_table_crc32(&t);
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_VALUES);
    bad_exp[1] = (int8_t)(-STSP_Q_EXP_MAX);
    t.crc32 = stsp_table_crc32(&t);
    assert_int_equal(stsp_init(&c, &t), STSP_OK);

    t = make_table();
    t.u_exp = NULL;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_NULL);
    t = make_table();
    t.v_exp = NULL;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_NULL);
}

/* The band dual is a float32 feature (binary32 multipliers from a double solver): a fixed-point
 * build refuses a table with band_qp, even one that is valid in every other respect and whose
 * band dual meets the float32 contract (q = stage_n_latch[0], no later latch, nx the table's,
 * W > 0, lo <= hi), with STSP_ERR_BAD_DIMS and the CRC recomputed over the band data, so that
 * the refusal is not a CRC failure; the instance stays not ready. */
static void test_band_table_is_refused(void **state)
{
    static const uint16_t joint_stage_n_latch[NS] = {2u, 0u};
    static const double Nt[2 * NX] = {1.0, 0.0, 0.0, 1.0};
    static const double mt[2] = {0.0, 0.0};
    static const double W[2 * 2] = {2.0, 0.5, 0.5, 1.0};
    static const double lo[2] = {0.5, -1.0};
    static const double hi[2] = {0.5, 1.0};
    const stsp_bandqp_t qp = {2u, (uint16_t)NX, Nt, mt, W, lo, hi, stsp_bandqp_solve_f32};
    const stsp_scalar_t x[NX] = {0, 0};
    stsp_scalar_t u[NU] = {7};
    stsp_ctrl_t c;
    stsp_table_t t = make_table();
    (void)state;
    t.stage_n_latch = joint_stage_n_latch;
    t.crc32 = stsp_table_crc32(&t);
    assert_int_equal(stsp_init(&c, &t), STSP_OK); /* the joint layout alone is valid */

    t.band_qp = &qp;
    t.crc32 = stsp_table_crc32(&t);
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_DIMS);
    assert_int_equal(stsp_step(&c, 0u, x, u), STSP_ERR_NOT_INITIALIZED);
    assert_int_equal(u[0], 7);
    assert_int_equal(stsp_init_expect(&c, &t, NX, NU), STSP_ERR_BAD_DIMS);
    /* Without the CRC update as well: the dimension check comes first. */
    t.crc32 ^= 1u;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_DIMS);

    t.band_qp = NULL;
    t.crc32 = stsp_table_crc32(&t);
    assert_int_equal(stsp_init(&c, &t), STSP_OK);
}

/* A fixed-point spline table (stsp_qspline_t) in a program without the spline code (this test
 * does not link stsp_spline.c: nothing refers to stsp_spline_code) is refused, with its
 * per-tick arrays (a valid Q table otherwise) or without them (K, k0, L NULL: BAD_DIMS, not
 * STSP_ERR_NULL), the CRC recomputed over the spline data; stsp_verify() of an instance whose
 * table gains a spline afterwards reports the header change. tests/c/test_qspline_ctrl.c runs
 * such tables with the code linked. */
static void test_spline_table_is_refused(void **state)
{
    static const uint8_t span_log2[NS] = {1u, 0u};
    static const uint16_t row_start[NS * NU + 1u] = {0u, 1u, 2u};
    static const uint8_t col[2] = {0u, 2u};
    static const uint8_t shift[2] = {3u, 3u};
    static const uint32_t coef_start[NS + 1u] = {0u, 5u, 10u};
    static const stsp_scalar_t coef[10] = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10};
    const stsp_qspline_t sp = {2u, 10u, span_log2, row_start, col, shift, coef_start, coef, NULL};
    const stsp_scalar_t x[NX] = {0, 0};
    stsp_scalar_t u[NU] = {7};
    stsp_ctrl_t c;
    stsp_table_t t = make_table();
    (void)state;
    t.spline = &sp;
    t.crc32 = stsp_table_crc32(&t);
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_DIMS);
    assert_int_equal(stsp_step(&c, 0u, x, u), STSP_ERR_NOT_INITIALIZED);
    assert_int_equal(u[0], 7);
    t.K = NULL;
    t.k0 = NULL;
    t.L = NULL;
    t.crc32 = stsp_table_crc32(&t);
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_DIMS);

    t = make_table();
    assert_int_equal(stsp_init(&c, &t), STSP_OK);
    t.spline = &sp;
    assert_int_equal(stsp_verify(&c), STSP_ERR_TABLE_CHANGED);
}

static void test_crc_covers_scales_and_kind(void **state)
{
    stsp_ctrl_t c;
    stsp_table_t t = make_table();
    const uint32_t crc = t.crc32;
    int8_t exps[N_LATCH] = {1, 0};
    stsp_table_t k = t;
    (void)state;
    t.v_exp = exps;
    assert_int_equal(stsp_table_crc32(&t), crc);
    exps[1] = 1;
    assert_int_not_equal(stsp_table_crc32(&t), crc);
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_CRC);
    k.scalar_kind = STSP_SCALAR_FLOAT32;
    assert_int_not_equal(stsp_table_crc32(&k), crc);
}

static void test_saturation_in_command_units(void **state)
{
    const stsp_scalar_t lo[NU] = {(stsp_scalar_t)-3}, hi[NU] = {(stsp_scalar_t)2};
    const stsp_scalar_t bad_lo[NU] = {(stsp_scalar_t)1};
    stsp_table_t t = make_table_limited(lo, hi);
    stsp_ctrl_t c;
    stsp_scalar_t x[NX] = {0, 0}, u[NU];
    (void)state;
    assert_int_equal(stsp_init(&c, &t), STSP_OK);
    x[0] = (stsp_scalar_t)(ONE / 2); /* u = 1: inside */
    assert_int_equal(stsp_step(&c, 0u, x, u), STSP_OK);
    assert_int_equal(u[0], 1);
    assert_int_equal(c.sat_mask, 0u);
    /* tick 1: about (0.05 + 0.11 + 0.2 * 0.05) 2^F units, far above 2: clamped */
    x[0] = QMAX;
    assert_int_equal(stsp_step(&c, 1u, x, u), STSP_WARN_SATURATED);
    assert_int_equal(u[0], hi[0]);
    assert_int_equal(c.sat_mask, 1u);
    /* tick 2: about (-0.06 - 0.12 + 0.25 * 0.05) 2^F units, far below -3 */
    x[0] = QMIN;
    assert_int_equal(stsp_step(&c, 2u, x, u), STSP_WARN_SATURATED);
    assert_int_equal(u[0], lo[0]);
    /* saturation wins over a tick warning, as in float32 */
    assert_int_equal(stsp_step(&c, 2u, x, u), STSP_WARN_SATURATED);
    x[0] = 0;
    assert_int_equal(stsp_step(&c, 2u, x, u), STSP_WARN_SATURATED); /* -0.06 + 0.0125 */
    t = make_table_limited(bad_lo, hi);
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_VALUES);
}

static void test_ticks_as_float(void **state)
{
    stsp_table_t t = make_table();
    stsp_ctrl_t c, before;
    stsp_scalar_t x[NX] = {100, -200}, u[NU] = {7};
    (void)state;
    assert_int_equal(stsp_init(&c, &t), STSP_OK);
    assert_int_equal(stsp_step(&c, 0u, x, u), STSP_OK);
    assert_int_equal(stsp_step(&c, 0u, x, u), STSP_WARN_TICK_REPEATED);
    assert_int_equal(stsp_step(&c, 4u, x, u), STSP_WARN_TICK_SKIPPED); /* stage 1, latches */
    assert_int_equal(c.stage, 1u);
    memcpy(&before, &c, sizeof c);
    u[0] = 7;
    assert_int_equal(stsp_step(&c, 2u, x, u), STSP_ERR_TICK_ORDER);
    assert_int_equal(u[0], 0);
    assert_memory_equal(&before, &c, sizeof c);
    u[0] = 7;
    assert_int_equal(stsp_step(&c, NT, x, u), STSP_ERR_TICK_RANGE);
    assert_int_equal(u[0], 0);
    assert_int_equal(stsp_step(&c, 4u, NULL, u), STSP_ERR_NULL);
    assert_int_equal(stsp_reset(&c), STSP_OK);
    assert_int_equal(stsp_step(&c, 0u, x, u), STSP_OK);
}

static void test_state_conversion(void **state)
{
    stsp_table_t t = make_table();
    stsp_ctrl_t c, idle;
    stsp_scalar_t xq[NX];
    stsp_f32_t x[NX], u[NU];
    const stsp_scalar_t uq[NU] = {(stsp_scalar_t)-3};
    (void)state;
    memset(&idle, 0, sizeof idle);
    assert_int_equal(stsp_init(&c, &t), STSP_OK);
    /* x_exp = {2, -3}: x0 in [-4, 4), x1 in [-1/8, 1/8); LSBs 2^(2-F), 2^(-3-F). */
    x[0] = 1.0f;
    x[1] = -0.0625f;
    assert_int_equal(stsp_state_to_q(&c, x, xq), STSP_OK);
    assert_true((int64_t)xq[0] == ONE / 4);
    assert_true((int64_t)xq[1] == -ONE / 2);
#if F == 15
    /* Ties round up: half an LSB of x0 is 2^(1-F) = 2^-14. */
    x[0] = 0.00006103515625f;         /* 2^-14 = 1/2 LSB of x0 */
    x[1] = -0.00006103515625f / 32.0f; /* -2^-19 = -1/2 LSB of x1 */
    assert_int_equal(stsp_state_to_q(&c, x, xq), STSP_OK);
    assert_int_equal(xq[0], 1);
    assert_int_equal(xq[1], 0);
#endif
    x[0] = 4.0f; /* the range end is not representable: clamped */
    x[1] = -1.0f;
    assert_int_equal(stsp_state_to_q(&c, x, xq), STSP_WARN_STATE_CLAMPED);
    assert_int_equal(xq[0], QMAX);
    assert_int_equal(xq[1], QMIN);
    x[0] = 3.0e38f;
    x[1] = -0.125f; /* exactly -2^F LSBs: in range */
    assert_int_equal(stsp_state_to_q(&c, x, xq), STSP_WARN_STATE_CLAMPED);
    assert_int_equal(xq[0], QMAX);
    assert_int_equal(xq[1], QMIN);
    x[1] = 0.0f;
    assert_int_equal(stsp_state_to_q(&c, x, xq), STSP_WARN_STATE_CLAMPED);
    x[0] = NAN;
    xq[0] = 5; xq[1] = 5;
    assert_int_equal(stsp_state_to_q(&c, x, xq), STSP_ERR_NONFINITE_STATE);
    assert_int_equal(xq[0], 0);
    assert_int_equal(xq[1], 0);
    x[0] = 0.0f;
    x[1] = -INFINITY;
    assert_int_equal(stsp_state_to_q(&c, x, xq), STSP_ERR_NONFINITE_STATE);
    assert_int_equal(stsp_state_to_q(NULL, x, xq), STSP_ERR_NULL);
    assert_int_equal(stsp_state_to_q(&c, NULL, xq), STSP_ERR_NULL);
    assert_int_equal(stsp_state_to_q(&idle, x, xq), STSP_ERR_NOT_INITIALIZED);

    /* u_exp = 4: one unit is 2^(4-F). */
    assert_int_equal(stsp_command_to_f32(&c, uq, u), STSP_OK);
    assert_true(u[0] == -3.0f / (stsp_f32_t)(ONE >> 4));
    assert_int_equal(stsp_command_to_f32(&idle, uq, u), STSP_ERR_NOT_INITIALIZED);
    assert_int_equal(stsp_command_to_f32(&c, NULL, u), STSP_ERR_NULL);
}

static void test_table_changed_after_init(void **state)
{
    const stsp_scalar_t xs[NX] = {QMAX, QMIN};
    const stsp_f32_t xfs[NX] = {1.0f, -0.0625f};
    const stsp_scalar_t uq[NU] = {(stsp_scalar_t)-3};
    uint32_t which, tick;
    (void)state;
    for (which = 0u; which < 6u; ++which) {
        const stsp_table_t orig = heap_table(make_table());
        stsp_table_t t = orig;
        stsp_ctrl_t c, ref;
        stsp_scalar_t *x = heap_copy(xs, sizeof xs), *u = heap_copy(uq, sizeof uq);
        stsp_scalar_t *xq = heap_copy(xs, sizeof xs);
        stsp_f32_t *xf = heap_copy(xfs, sizeof xfs), *uf = heap_copy(xfs, sizeof(stsp_f32_t) * NU);
        stsp_scalar_t u_ref[NU], xq_ref[NX], guard[NU + 1u];
        stsp_f32_t uf_ref[NU];
        assert_int_equal(stsp_init(&c, &t), STSP_OK);
        assert_int_equal(stsp_init(&ref, &orig), STSP_OK);
        assert_int_equal(stsp_step(&c, 0u, x, u), STSP_OK);
        assert_int_equal(stsp_step(&ref, 0u, x, u_ref), STSP_OK);
        switch (which) {
        case 0u: t.nx = NX + 1u; break;
        case 1u: t.nu = NU + 1u; break;
        case 2u: t.n_ticks = NT + 1u; break;
        case 3u: t.K = t.k0; break;             /* an array half as long */
        case 4u: t.x_exp = t.u_exp; break;      /* one exponent where two were */
        default: t.n_latch = N_LATCH + 1u; break;
        }
        for (tick = 1u; tick <= NT; ++tick) {
            assert_int_equal(stsp_step(&c, tick, x, u), stsp_step(&ref, tick, x, u_ref));
            assert_int_equal(u[0], u_ref[0]);
            guard[NU] = 77;                     /* a write past u[nu] fails every build */
            assert_int_equal(stsp_step(&c, tick, x, guard), stsp_step(&ref, tick, x, u_ref));
            assert_int_equal(guard[0], u_ref[0]);
            assert_int_equal(guard[NU], 77);
        }
        assert_int_equal(stsp_state_to_q(&c, xf, xq), stsp_state_to_q(&ref, xf, xq_ref));
        assert_memory_equal(xq, xq_ref, sizeof xq_ref);
        assert_int_equal(stsp_command_to_f32(&c, uq, uf), stsp_command_to_f32(&ref, uq, uf_ref));
        assert_memory_equal(uf, uf_ref, sizeof uf_ref);
        assert_int_equal(stsp_verify(&c), STSP_ERR_TABLE_CHANGED);
        u[0] = 7;
        assert_int_equal(stsp_step(&c, 1u, x, u), STSP_ERR_NOT_INITIALIZED);
        assert_int_equal(u[0], 0);
        assert_int_equal(stsp_state_to_q(&c, xf, xq), STSP_ERR_NOT_INITIALIZED);
        free(x);
        free(u);
        free(xq);
        free(xf);
        free(uf);
        free_heap_table(&orig);
    }
}

static void test_gains_changed_after_init_do_not_overflow(void **state)
{
    const stsp_scalar_t x[NX] = {QMIN, QMIN};
    stsp_table_t t = make_table();
    stsp_ctrl_t c;
    stsp_scalar_t u[NU];
    uint32_t tick, i;
    (void)state;
    assert_int_equal(stsp_init(&c, &t), STSP_OK);
    assert_int_equal(stsp_step(&c, 0u, x, u), STSP_OK);
    for (i = 0u; i < NT * NU * NX; ++i) {
        K[i] = QMIN;                            /* K x alone: 2 * 2^(2F) per row */
    }
    for (i = 0u; i < NT * NU * N_LATCH; ++i) {
        L[i] = QMIN;
    }
    for (i = 0u; i < NS * N_LATCH * NX; ++i) {
        Lambda[i] = QMIN;
    }
    k0[1] = QMAX;
    lambda0[0] = QMAX;
    for (tick = 1u; tick < NT; ++tick) {
        assert_int_equal(stsp_step(&c, tick, x, u), STSP_OK); /* no limits: no error path */
    }
    assert_int_equal(stsp_reset(&c), STSP_OK);
    assert_int_equal(stsp_step(&c, 0u, x, u), STSP_OK);    /* the latch as well */
    assert_int_equal(stsp_verify(&c), STSP_ERR_BAD_CRC);
}

/* x and u may be the same buffer or overlap: the same statuses and commands as separate
 * buffers (every read of x happens before the first write of u), with and without limits. */
static void test_state_and_command_may_share_a_buffer(void **state)
{
    const stsp_scalar_t lo[NU] = {(stsp_scalar_t)-3}, hi[NU] = {(stsp_scalar_t)2};
    const uint32_t ticks[9] = {0u, 1u, 1u, 2u, 3u, 3u, 4u, 2u, 4u};
    uint32_t lim, off, trial, n;
    (void)state;
    for (lim = 0u; lim < 2u; ++lim) {
        const stsp_table_t t = (lim != 0u) ? make_table_limited(lo, hi) : make_table();
        for (off = 0u; off < NX; ++off) {
            for (trial = 0u; trial < 50u; ++trial) {
                stsp_ctrl_t a, b;
                assert_int_equal(stsp_init(&a, &t), STSP_OK);
                assert_int_equal(stsp_init(&b, &t), STSP_OK);
                for (n = 0u; n < 9u; ++n) {
                    stsp_scalar_t x[NX], buf[NX], u[NU];
                    x[0] = random_q();
                    x[1] = random_q();
                    memcpy(buf, x, sizeof buf);
                    assert_int_equal(stsp_step(&b, ticks[n], buf, &buf[off]),
                                     stsp_step(&a, ticks[n], x, u));
                    assert_int_equal(buf[off], u[0]);
                    assert_memory_equal(&a, &b, sizeof a);
                }
            }
        }
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup(test_law_matches_reference, setup),
        cmocka_unit_test_setup(test_safe_command, setup),
        cmocka_unit_test_setup(test_rounding_is_half_up, setup),
        cmocka_unit_test_setup(test_extreme_rows_do_not_overflow, setup),
        cmocka_unit_test_setup(test_row_sum_over_limit_is_refused, setup),
        cmocka_unit_test_setup(test_wrong_variant_and_scales_are_refused, setup),
        cmocka_unit_test_setup(test_band_table_is_refused, setup),
        cmocka_unit_test_setup(test_crc_covers_scales_and_kind, setup),
        cmocka_unit_test_setup(test_saturation_in_command_units, setup),
        cmocka_unit_test_setup(test_ticks_as_float, setup),
        cmocka_unit_test_setup(test_state_conversion, setup),
        cmocka_unit_test_setup(test_table_changed_after_init, setup),
        cmocka_unit_test_setup(test_gains_changed_after_init_do_not_overflow, setup),
        cmocka_unit_test_setup(test_state_and_command_may_share_a_buffer, setup),
        cmocka_unit_test(test_spline_table_is_refused),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
