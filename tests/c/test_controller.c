/* Unit tests of the controller on small hand-made tables whose law is checked against a
 * double-precision reference evaluation written out here. Built several times (CMakeLists.txt):
 * generic dimensions, STSP_FIXED_NX/NU/N_LATCH = 2/1/2 (the main table's shape), and each under
 * ASan + UBSan. Every documented response of docs/guide/firmware.md has a test here. */
#include <float.h>
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
#include "stsp_crc32.h"
#include "table_a.h"

/* Table A's gains (its shape: table_a.h). */
static const float K[NT * NU * NX] = {0.5f, -1.0f, 0.6f, -1.1f, 0.7f, -1.2f,
                                      0.8f, -1.3f, 0.9f, -1.4f};
static const float k0[NT * NU] = {0.1f, 0.2f, 0.3f, 0.4f, 0.5f};
static const float L[NT * NU * N_LATCH] = {2.0f, 0.0f, 2.5f, 0.0f, 3.0f, 0.0f,
                                           1.0f, -1.0f, 1.5f, -1.5f};
static const float Lambda[NS * N_LATCH * NX] = {1.0f, 2.0f, 0.0f, 0.0f,
                                                -1.0f, 0.5f, 0.25f, 3.0f};
static const float lambda0[NS * N_LATCH] = {-0.5f, 0.0f, 1.0f, -2.0f};
static const float no_min[NU] = {-FLT_MAX}, no_max[NU] = {FLT_MAX};
static const float tight_min[NU] = {-0.25f}, tight_max[NU] = {0.5f};
static const float wide_min[NU] = {-1000.0f}, wide_max[NU] = {1000.0f};
static const float zero_hold[NU] = {0.0f};

/* CRC-32 of table A (unlimited) as host/stospline/table/format.py table_crc32 computes it
 * (tests/python/firmware/test_table_limits.py builds the same table): the serialization order of
 * both implementations, limits included, is pinned here. */
#define TABLE_A_CRC32 0x6C34DDB7u

static stsp_table_t make_table_hold(const float *lo, const float *hi, const float *hold)
{
    stsp_table_t t = table_header(NX, NU, N_LATCH, NS, NT, 10u);
    t.stage_start = stage_start; t.stage_n_latch = stage_n_latch;
    t.K = K; t.k0 = k0; t.L = L; t.Lambda = Lambda; t.lambda0 = lambda0;
    t.u_min = lo; t.u_max = hi; t.u_hold = hold;
    t.crc32 = stsp_table_crc32(&t);
    return t;
}

static stsp_table_t make_table_limited(const float *lo, const float *hi)
{
    return make_table_hold(lo, hi, zero_hold);
}

static stsp_table_t make_table(void)
{
    return make_table_limited(no_min, no_max);
}

/* Table B: nx = 1, nu = 2, no multipliers (n_latch = 0, L/Lambda/lambda0 NULL), one stage of
 * 3 ticks, u = -(x, x). A different shape: a fixed 2/1/2 build must refuse it. */
static const uint32_t b_start[2] = {0u, 3u};
static const uint16_t b_stage_n_latch[1] = {0u};
static const float b_K[3 * 2] = {1.0f, 1.0f, 1.0f, 1.0f, 1.0f, 1.0f};
static const float b_k0[3 * 2] = {0.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f};
static const float b_min[2] = {-FLT_MAX, -FLT_MAX}, b_max[2] = {FLT_MAX, FLT_MAX};
static const float b_hold[2] = {0.0f, 0.0f};

static stsp_table_t make_table_b(void)
{
    stsp_table_t t = table_header(1u, 2u, 0u, 1u, 3u, 1u);
    t.stage_start = b_start; t.stage_n_latch = b_stage_n_latch; t.K = b_K; t.k0 = b_k0;
    t.u_min = b_min; t.u_max = b_max; t.u_hold = b_hold;
    t.crc32 = stsp_table_crc32(&t);
    return t;
}

#ifdef STSP_FIXED_NX
#define EXPECT_TABLE_B STSP_ERR_BAD_DIMS /* another shape than the build's */
#else
#define EXPECT_TABLE_B STSP_OK
#endif

/* Reference law in double: u = -K x - k0 - L v with v latched at `latch_x` in `latch_stage`. */
static double reference_u_latched(uint32_t tick, const float *x, const float *latch_x,
                                  uint32_t latch_stage)
{
    uint32_t i, j;
    double v[N_LATCH] = {0.0, 0.0}, acc = k0[tick];
    for (i = 0u; i < stage_n_latch[latch_stage]; ++i) {
        v[i] = lambda0[latch_stage * N_LATCH + i];
        for (j = 0u; j < NX; ++j) {
            v[i] += (double)Lambda[(latch_stage * N_LATCH + i) * NX + j] * latch_x[j];
        }
    }
    for (j = 0u; j < NX; ++j) {
        acc += (double)K[tick * NX + j] * x[j];
    }
    for (i = 0u; i < N_LATCH; ++i) {
        acc += (double)L[tick * N_LATCH + i] * v[i];
    }
    return -acc;
}

static double reference_u(uint32_t tick, const float *x, const float *latch_x)
{
    return reference_u_latched(tick, x, latch_x, (tick >= stage_start[1]) ? 1u : 0u);
}

static double clamp(double u, float lo, float hi)
{
    return (u < lo) ? lo : ((u > hi) ? hi : u);
}

static stsp_table_t table, table_tight, table_wide;
static stsp_ctrl_t ctrl;

static int setup(void **state)
{
    (void)state;
    table = make_table();
    table_tight = make_table_limited(tight_min, tight_max);
    table_wide = make_table_limited(wide_min, wide_max);
    return stsp_init(&ctrl, &table) == STSP_OK ? 0 : -1;
}

static void test_crc_known_answer(void **state)
{
    /* "12345678" as two little-endian words; zlib.crc32(b"12345678") = 0x9AE0DAAF. */
    uint32_t crc = stsp_crc32_begin();
    (void)state;
    crc = stsp_crc32_u32(crc, 0x34333231u);
    crc = stsp_crc32_u32(crc, 0x38373635u);
    assert_int_equal(stsp_crc32_end(crc), 0x9AE0DAAFu);
}

static void test_crc_matches_python_and_covers_limits(void **state)
{
    (void)state;
    assert_int_equal(table.crc32, TABLE_A_CRC32);
    assert_int_not_equal(table_tight.crc32, table.crc32);
    assert_int_not_equal(table_wide.crc32, table_tight.crc32);
}

static void test_law_and_latching(void **state)
{
    const float xs[NT][NX] = {{1.0f, -2.0f}, {0.5f, 0.25f}, {-1.0f, 3.0f},
                              {2.0f, 1.0f}, {-0.5f, -0.75f}};
    float u[NU];
    uint32_t tick;
    (void)state;
    for (tick = 0u; tick < NT; ++tick) {
        const float *latch = (tick < 3u) ? xs[0] : xs[3];
        assert_int_equal(stsp_step(&ctrl, tick, xs[tick], u), STSP_OK);
        assert_float_equal(u[0], reference_u(tick, xs[tick], latch), 1e-5);
        assert_int_equal(ctrl.next_tick, tick + 1u);
        assert_int_equal(ctrl.stage, (tick < 3u) ? 0u : 1u);
    }
}

/* Inactive limits take the compare path, no limits the sum check: the same commands. */
static void test_inactive_limits_change_nothing(void **state)
{
    const float xs[NT][NX] = {{1.0f, -2.0f}, {0.5f, 0.25f}, {-1.0f, 3.0f},
                              {2.0f, 1.0f}, {-0.5f, -0.75f}};
    stsp_ctrl_t wide;
    float u[NU], uw[NU];
    uint32_t tick;
    (void)state;
    assert_int_equal(stsp_init(&wide, &table_wide), STSP_OK);
    for (tick = 0u; tick < NT; ++tick) {
        assert_int_equal(stsp_step(&ctrl, tick, xs[tick], u), STSP_OK);
        assert_int_equal(stsp_step(&wide, tick, xs[tick], uw), STSP_OK);
        assert_int_equal(f32_bits(u[0]), f32_bits(uw[0]));
    }
}

/* NaN and +-Inf in any state entry, on every kind of tick, with and without limits: status
 * STSP_ERR_NONFINITE_STATE, u all zeros, the instance unchanged. */
static void test_nonfinite_state(void **state)
{
    const float specials[4] = {NAN, -NAN, INFINITY, -INFINITY};
    const float good[NX] = {1.0f, 2.0f};
    const stsp_table_t *tables[3] = {&table, &table_tight, &table_wide};
    /* Ticks reached from a controller stepped through `prefix` ticks 0..prefix-1:
     * 0 = first step (latch), 1 = ordinary, 2 = ordinary, 3 = stage switch (latch). */
    const uint32_t prefixes[4] = {0u, 1u, 2u, 3u};
    uint32_t tb, s, j, p, t;
    (void)state;
    for (tb = 0u; tb < 3u; ++tb) {
        for (p = 0u; p < 4u; ++p) {
            for (s = 0u; s < 4u; ++s) {
                for (j = 0u; j < NX; ++j) {
                    stsp_ctrl_t c, fresh;
                    float bad[NX] = {1.0f, 2.0f}, u[NU] = {42.0f}, u_ref[NU];
                    assert_int_equal(stsp_init(&c, tables[tb]), STSP_OK);
                    for (t = 0u; t < prefixes[p]; ++t) {
                        assert_true(stsp_step(&c, t, good, u) >= STSP_OK);
                    }
                    memcpy(&fresh, &c, sizeof c);
                    bad[j] = specials[s];
                    u[0] = 42.0f;
                    assert_int_equal(stsp_step(&c, prefixes[p], bad, u),
                                     STSP_ERR_NONFINITE_STATE);
                    assert_true(f32_bits(u[0]) == 0u);
                    assert_memory_equal(&c, &fresh, sizeof c);
                    /* A skip onto the same tick (cold path without latch) too. */
                    if (prefixes[p] > 0u && prefixes[p] < 3u) {
                        assert_int_equal(stsp_step(&c, prefixes[p] + 1u, bad, u),
                                         STSP_ERR_NONFINITE_STATE);
                        assert_true(f32_bits(u[0]) == 0u);
                    }
                    assert_true(stsp_step(&c, prefixes[p], good, u) >= STSP_OK);
                    assert_true(stsp_step(&fresh, prefixes[p], good, u_ref) >= STSP_OK);
                    assert_int_equal(f32_bits(u[0]), f32_bits(u_ref[0]));
                }
            }
        }
    }
}

static void test_subnormal_state_is_finite(void **state)
{
    const float x[NX] = {FLT_MIN / 4.0f, -FLT_MIN / 8.0f};
    const float z[NX] = {-0.0f, 0.0f};
    float u[NU];
    (void)state;
    assert_int_equal(stsp_step(&ctrl, 0u, x, u), STSP_OK);
    assert_float_equal(u[0], reference_u(0u, x, x), 1e-6);
    assert_int_equal(stsp_step(&ctrl, 1u, z, u), STSP_OK);
    assert_float_equal(u[0], reference_u(1u, z, x), 1e-6);
}

static void test_overflow_gives_zero_and_error(void **state)
{
    const float huge[NX] = {FLT_MAX, -FLT_MAX};
    const float big_ok[NX] = {1e30f, -1e30f};
    const float good[NX] = {1.0f, 1.0f};
    float u[NU] = {7.0f};
    stsp_ctrl_t c;
    (void)state;
    /* The latch itself overflows (Lambda x at tick 0). */
    assert_int_equal(stsp_step(&ctrl, 0u, huge, u), STSP_ERR_NONFINITE_OUTPUT);
    assert_true(u[0] == 0.0f);
    assert_int_equal(ctrl.next_tick, 0u);
    /* Large but representable: a finite command. */
    assert_int_equal(stsp_step(&ctrl, 0u, big_ok, u), STSP_OK);
    assert_true(isfinite(u[0]));
    /* An ordinary (fast-path) tick overflows, with and without limits. */
    assert_int_equal(stsp_init(&c, &table), STSP_OK);
    assert_int_equal(stsp_step(&c, 0u, good, u), STSP_OK);
    u[0] = 7.0f;
    assert_int_equal(stsp_step(&c, 1u, huge, u), STSP_ERR_NONFINITE_OUTPUT);
    assert_true(u[0] == 0.0f);
    assert_int_equal(stsp_init(&c, &table_tight), STSP_OK);
    assert_int_equal(stsp_step(&c, 0u, good, u), STSP_WARN_SATURATED);
    assert_int_equal(stsp_step(&c, 1u, huge, u), STSP_ERR_NONFINITE_OUTPUT);
    assert_true(u[0] == 0.0f);
}

static void test_saturation(void **state)
{
    /* Table A: u0 = 0.9 - 2.5 x0 - 3 x1 at tick 0 (latching there); with v latched at
     * x_mid, u1 = 0.15 - 0.6 x0 + 1.1 x1 and u2 = 0.12 - 0.7 x0 + 1.2 x1. */
    const float x_mid[NX] = {0.36f, 0.0f}, x_low[NX] = {1.0f, 0.0f};
    const float x_high[NX] = {-1.0f, 0.0f}, x3[NX] = {0.0f, 0.9f};
    float u[NU];
    stsp_ctrl_t c;
    (void)state;
    assert_int_equal(stsp_init(&c, &table_tight), STSP_OK);
    assert_int_equal(stsp_step(&c, 0u, x_mid, u), STSP_OK);         /* latch, inside */
    assert_float_equal(u[0], reference_u(0u, x_mid, x_mid), 1e-6);
    assert_int_equal(stsp_step(&c, 1u, x_low, u), STSP_WARN_SATURATED); /* -0.45 < u_min */
    assert_true(u[0] == tight_min[0]);
    assert_int_equal(c.sat_mask, 1u);
    assert_int_equal(c.next_tick, 2u);                               /* the tick counted */
    assert_int_equal(stsp_step(&c, 2u, x_high, u), STSP_WARN_SATURATED); /* 0.82 > u_max */
    assert_true(u[0] == tight_max[0]);
    assert_int_equal(c.sat_mask, 1u);
    /* Saturation wins over a tick warning; a latch tick (cold path) saturates too. */
    assert_int_equal(stsp_reset(&c), STSP_OK);
    assert_int_equal(stsp_step(&c, 0u, x_low, u), STSP_WARN_SATURATED);  /* -1.6 */
    assert_true(u[0] == tight_min[0]);
    assert_int_equal(stsp_step(&c, 2u, x_low, u), STSP_WARN_SATURATED);  /* skipped tick 1 */
    assert_true(u[0] == tight_min[0]);
    assert_int_equal(c.next_tick, 3u);
    assert_int_equal(stsp_step(&c, 2u, x_low, u), STSP_WARN_SATURATED);  /* repeated */
    assert_int_equal(stsp_step(&c, 3u, x3, u), STSP_OK);                 /* stage 1 latch */
    assert_float_equal(u[0], reference_u(3u, x3, x3), 1e-5);
    assert_true(u[0] > tight_min[0] && u[0] < tight_max[0]);
}

/* No limits, nu = 2: each command finite but their sum overflows. The fast check raises a
 * false alarm; the cold path finds nothing to clamp and returns the commands untouched. */
static void test_sum_overflow_is_not_an_error(void **state)
{
    const stsp_table_t tb = make_table_b();
    const float x[1] = {-2.0e38f};
    float u[2] = {0.0f, 0.0f};
    stsp_ctrl_t c;
    (void)state;
    assert_int_equal(stsp_init(&c, &tb), EXPECT_TABLE_B);
    if (EXPECT_TABLE_B != STSP_OK) {
        return;
    }
    assert_int_equal(stsp_step(&c, 0u, x, u), STSP_OK);
    assert_true(u[0] == 2.0e38f && u[1] == 2.0e38f);
    assert_int_equal(stsp_step(&c, 1u, x, u), STSP_OK);
    assert_true(u[0] == 2.0e38f && u[1] == 2.0e38f);
    assert_int_equal(c.next_tick, 2u);
}

/* A table without multipliers may leave L, Lambda and lambda0 NULL. */
static void test_table_without_multipliers(void **state)
{
    const stsp_table_t tb = make_table_b();
    const float x[1] = {1.5f};
    float u[2];
    stsp_ctrl_t c;
    uint32_t tick;
    (void)state;
    assert_int_equal(stsp_init(&c, &tb), EXPECT_TABLE_B);
    if (EXPECT_TABLE_B != STSP_OK) {
        assert_int_equal(stsp_step(&c, 0u, x, u), STSP_ERR_NOT_INITIALIZED);
        return;
    }
    for (tick = 0u; tick < 3u; ++tick) {
        assert_int_equal(stsp_step(&c, tick, x, u), STSP_OK);
        assert_true(u[0] == -1.5f && u[1] == -1.5f);
    }
    assert_int_equal(stsp_step(&c, 3u, x, u), STSP_ERR_TICK_RANGE);
    assert_true(u[0] == 0.0f && u[1] == 0.0f);
}

static void test_tick_range_and_order(void **state)
{
    const float x[NX] = {0.1f, 0.2f};
    float u[NU] = {3.0f};
    uint32_t tick;
    (void)state;
    assert_int_equal(stsp_step(&ctrl, NT, x, u), STSP_ERR_TICK_RANGE);
    assert_true(u[0] == 0.0f);
    assert_int_equal(stsp_step(&ctrl, UINT32_MAX, x, u), STSP_ERR_TICK_RANGE);
    assert_int_equal(stsp_step(&ctrl, 0u, x, u), STSP_OK);
    assert_int_equal(stsp_step(&ctrl, 1u, x, u), STSP_OK);
    assert_int_equal(stsp_step(&ctrl, 2u, x, u), STSP_OK);
    u[0] = 5.0f;
    assert_int_equal(stsp_step(&ctrl, 0u, x, u), STSP_ERR_TICK_ORDER);
    assert_true(u[0] == 0.0f);
    assert_int_equal(ctrl.next_tick, 3u);
    /* Run to the end: a step after the last tick is an error, the last one may repeat. */
    for (tick = 3u; tick < NT; ++tick) {
        assert_int_equal(stsp_step(&ctrl, tick, x, u), STSP_OK);
    }
    u[0] = 5.0f;
    assert_int_equal(stsp_step(&ctrl, NT, x, u), STSP_ERR_TICK_RANGE);
    assert_true(u[0] == 0.0f);
    assert_int_equal(stsp_step(&ctrl, NT + 1u, x, u), STSP_ERR_TICK_RANGE);
    assert_int_equal(stsp_step(&ctrl, NT - 1u, x, u), STSP_WARN_TICK_REPEATED);
    assert_float_equal(u[0], reference_u(NT - 1u, x, x), 1e-5);
}

static void test_repeated_tick_keeps_latch(void **state)
{
    const float x0[NX] = {1.0f, 1.0f}, x1[NX] = {-3.0f, 2.0f}, x3[NX] = {0.5f, 0.5f};
    float u1[NU], u2[NU];
    (void)state;
    assert_int_equal(stsp_step(&ctrl, 0u, x0, u1), STSP_OK);
    assert_int_equal(stsp_step(&ctrl, 0u, x1, u2), STSP_WARN_TICK_REPEATED);
    assert_float_equal(u2[0], reference_u(0u, x1, x0), 1e-5); /* latch from the first call */
    assert_int_equal(stsp_step(&ctrl, 1u, x1, u2), STSP_OK);
    assert_int_equal(stsp_step(&ctrl, 1u, x1, u2), STSP_WARN_TICK_REPEATED);
    assert_int_equal(stsp_step(&ctrl, 2u, x1, u2), STSP_OK);
    assert_int_equal(stsp_step(&ctrl, 3u, x3, u2), STSP_OK);    /* stage 1 latches at x3 */
    assert_int_equal(stsp_step(&ctrl, 3u, x1, u2), STSP_WARN_TICK_REPEATED);
    assert_float_equal(u2[0], reference_u(3u, x1, x3), 1e-5);
    assert_int_equal(stsp_step(&ctrl, 4u, x1, u2), STSP_OK);
    assert_float_equal(u2[0], reference_u(4u, x1, x3), 1e-5);
}

static void test_skipped_stage_start_latches_late(void **state)
{
    const float x0[NX] = {1.0f, 1.0f}, x4[NX] = {0.5f, -2.0f};
    float u[NU];
    stsp_ctrl_t c;
    (void)state;
    assert_int_equal(stsp_step(&ctrl, 0u, x0, u), STSP_OK);
    assert_int_equal(stsp_step(&ctrl, 4u, x4, u), STSP_WARN_TICK_SKIPPED);
    assert_float_equal(u[0], reference_u(4u, x4, x4), 1e-5); /* stage 1 latched at tick 4 */
    /* Skipped within a stage: no latch, the stage's v stays. */
    assert_int_equal(stsp_init(&c, &table), STSP_OK);
    assert_int_equal(stsp_step(&c, 0u, x0, u), STSP_OK);
    assert_int_equal(stsp_step(&c, 2u, x4, u), STSP_WARN_TICK_SKIPPED);
    assert_float_equal(u[0], reference_u(2u, x4, x0), 1e-5);
    assert_int_equal(stsp_step(&c, 3u, x4, u), STSP_OK);
    /* The first step of a plan at a later tick latches that tick's stage. */
    assert_int_equal(stsp_init(&c, &table), STSP_OK);
    assert_int_equal(stsp_step(&c, 1u, x4, u), STSP_WARN_TICK_SKIPPED);
    assert_float_equal(u[0], reference_u(1u, x4, x4), 1e-5);
}

static void test_reset_restarts(void **state)
{
    const float xa[NX] = {1.0f, 1.0f}, xb[NX] = {2.0f, -1.0f};
    float u[NU];
    (void)state;
    assert_int_equal(stsp_step(&ctrl, 0u, xa, u), STSP_OK);
    assert_int_equal(stsp_step(&ctrl, 1u, xa, u), STSP_OK);
    assert_int_equal(stsp_reset(&ctrl), STSP_OK);
    assert_int_equal(stsp_step(&ctrl, 0u, xb, u), STSP_OK);
    assert_float_equal(u[0], reference_u(0u, xb, xb), 1e-5);
}

static void test_instances_are_independent(void **state)
{
    stsp_ctrl_t other;
    const float xa[NX] = {1.0f, 1.0f}, xb[NX] = {-2.0f, 0.5f};
    float ua[NU], ub[NU];
    (void)state;
    assert_int_equal(stsp_init(&other, &table), STSP_OK);
    assert_int_equal(stsp_step(&ctrl, 0u, xa, ua), STSP_OK);
    assert_int_equal(stsp_step(&other, 0u, xb, ub), STSP_OK);
    assert_int_equal(stsp_step(&ctrl, 1u, xa, ua), STSP_OK);
    assert_int_equal(stsp_step(&other, 1u, xa, ub), STSP_OK);
    assert_float_equal(ua[0], reference_u(1u, xa, xa), 1e-5);
    assert_float_equal(ub[0], reference_u(1u, xa, xb), 1e-5);
}

static void test_not_initialized_and_null(void **state)
{
    static const unsigned char fills[5] = {0x00u, 0xFFu, 0xA5u, 0xCCu, 0x53u};
    stsp_ctrl_t fresh;
    stsp_table_t bad;
    const float x[NX] = {0.0f, 0.0f};
    float u[NU] = {9.0f};
    unsigned i;
    (void)state;
    /* Stepping before init, whatever the uninitialised memory holds: u is not written. */
    for (i = 0u; i < 5u; ++i) {
        memset(&fresh, fills[i], sizeof fresh);
        u[0] = 9.0f;
        assert_int_equal(stsp_step(&fresh, 0u, x, u), STSP_ERR_NOT_INITIALIZED);
        assert_int_equal(stsp_reset(&fresh), STSP_ERR_NOT_INITIALIZED);
        assert_int_equal(stsp_verify(&fresh), STSP_ERR_NOT_INITIALIZED);
        assert_true(u[0] == 9.0f);
    }
    /* A failed init leaves a previously good instance not ready. */
    assert_int_equal(stsp_init(&fresh, &table), STSP_OK);
    bad = make_table();
    bad.magic = 0u;
    assert_int_equal(stsp_init(&fresh, &bad), STSP_ERR_BAD_MAGIC);
    assert_int_equal(stsp_step(&fresh, 0u, x, u), STSP_ERR_NOT_INITIALIZED);
    assert_int_equal(stsp_step(NULL, 0u, x, u), STSP_ERR_NULL);
    assert_int_equal(stsp_step(&ctrl, 0u, NULL, u), STSP_ERR_NULL);
    assert_true(u[0] == 0.0f);
    assert_int_equal(stsp_step(&ctrl, 0u, x, NULL), STSP_ERR_NULL);
    assert_int_equal(stsp_init(NULL, &table), STSP_ERR_NULL);
    assert_int_equal(stsp_init(&fresh, NULL), STSP_ERR_NULL);
    assert_int_equal(stsp_init_expect(NULL, &table, NX, NU), STSP_ERR_NULL);
    assert_int_equal(stsp_reset(NULL), STSP_ERR_NULL);
    assert_int_equal(stsp_verify(NULL), STSP_ERR_NULL);
    /* The NULL errors changed nothing: tick 0 still latches. */
    assert_int_equal(stsp_step(&ctrl, 0u, x, u), STSP_OK);
    assert_int_equal(ctrl.next_tick, 1u);
}

static void test_corrupt_tables_are_refused(void **state)
{
    stsp_table_t t;
    stsp_ctrl_t c;
    float Kbad[NT * NU * NX], Lnan[NT * NU * N_LATCH], lam0inf[NS * N_LATCH];
    const uint32_t bad_start[NS + 1u] = {0u, 3u, 3u};
    const uint32_t bad_first[NS + 1u] = {1u, 3u, 5u};
    const uint16_t bad_stage_n_latch[NS] = {1u, 3u};
    const float pos_min[NU] = {0.5f}, neg_max[NU] = {-0.5f}, nan_lim[NU] = {NAN};
    const float inf_max[NU] = {INFINITY}, swapped_min[NU] = {1.0f}, swapped_max[NU] = {-1.0f};
    const float x[NX] = {0.0f, 0.0f};
    float u[NU];
    (void)state;

    memcpy(Kbad, K, sizeof K);
    Kbad[7] = 1.3000001f;               /* one flipped mantissa bit in the middle */
    t = make_table(); t.K = Kbad;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_CRC);
    assert_int_equal(stsp_step(&c, 0u, x, u), STSP_ERR_NOT_INITIALIZED);

    t = make_table(); t.crc32 ^= 1u;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_CRC);
    t = make_table(); t.u_max = wide_max; /* limits are covered by the CRC */
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_CRC);
    t = make_table(); t.magic = 0u;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_MAGIC);
    t = make_table(); t.format_version = 1u;  /* format 1 had no limits */
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_VERSION);
    t = make_table(); t.format_version = 99u;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_VERSION);
    t = make_table(); t.scalar_kind = 7u;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_VERSION);
    t = make_table(); t.nx = 0u;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_DIMS);
    t = make_table(); t.nu = 0u;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_DIMS);
    t = make_table(); t.nu = STSP_MAX_NU + 1u;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_DIMS);
    t = make_table(); t.nx = STSP_MAX_NX + 1u;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_DIMS);
    t = make_table(); t.n_latch = STSP_MAX_LATCH + 1u;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_DIMS);
    t = make_table(); t.n_stages = 0u;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_DIMS);
    t = make_table(); t.n_stages = STSP_MAX_STAGES + 1u;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_DIMS);
    t = make_table(); t.tick_hz = 0u;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_DIMS);
    t = make_table(); t.n_ticks = 0u;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_DIMS);
    t = make_table(); t.n_ticks = UINT32_MAX; /* offsets would overflow 32 bits */
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_DIMS);
    t = make_table(); t.stage_start = bad_start;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_DIMS);
    t = make_table(); t.stage_start = bad_first;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_DIMS);
    t = make_table(); t.stage_n_latch = bad_stage_n_latch;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_DIMS);
    t = make_table(); t.n_ticks = 6u;    /* disagrees with stage_start[n_stages] */
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_DIMS);
    t = make_table(); t.K = NULL;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_NULL);
    t = make_table(); t.L = NULL;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_NULL);
    t = make_table(); t.u_min = NULL;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_NULL);
    t = make_table(); t.u_max = NULL;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_NULL);
    t = make_table(); t.u_hold = NULL;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_NULL);
    t = make_table(); t.stage_start = NULL;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_NULL);

    /* Bad values behind a valid CRC (a broken generator rather than a broken flash). */
    memcpy(Lnan, L, sizeof L);
    Lnan[3] = NAN;
    t = make_table(); t.L = Lnan; t.crc32 = stsp_table_crc32(&t);
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_VALUES);
    memcpy(lam0inf, lambda0, sizeof lambda0);
    lam0inf[2] = -INFINITY;
    t = make_table(); t.lambda0 = lam0inf; t.crc32 = stsp_table_crc32(&t);
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_VALUES);
    t = make_table_limited(pos_min, no_max);       /* u_hold = 0 below u_min */
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_VALUES);
    t = make_table_limited(no_min, neg_max);       /* u_hold = 0 above u_max */
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_VALUES);
    t = make_table_hold(pos_min, no_max, pos_min); /* u_min > 0 with u_hold at it: valid */
    assert_int_equal(stsp_init(&c, &t), STSP_OK);
    t = make_table_hold(tight_min, tight_max, wide_max);   /* u_hold above u_max */
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_VALUES);
    t = make_table_hold(no_min, no_max, nan_lim);          /* u_hold NaN */
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_VALUES);
    t = make_table_limited(swapped_min, swapped_max);
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_VALUES);
    t = make_table_limited(nan_lim, no_max);
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_VALUES);
    t = make_table_limited(no_min, inf_max);
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_VALUES);
    assert_int_equal(stsp_step(&c, 0u, x, u), STSP_ERR_NOT_INITIALIZED);
}

/* Every refused step writes the table's safe command u_hold, as init copied it: a minimum
 * thrust (u_min > 0) is a valid table; NaN state, NULL x, a tick past the plan and a stopped
 * instance all command it, even after the table's u_hold changed; the CRC covers it. */
static void test_safe_command(void **state)
{
    static const float lo[NU] = {0.125f}, hi[NU] = {0.875f};
    static float hold[NU] = {0.375f};
    const float x_nan[NX] = {NAN, 0.0f}, x[NX] = {0.0f, 0.0f};
    float u[NU];
    stsp_ctrl_t c;
    stsp_table_t t = make_table_hold(lo, hi, hold);
    (void)state;
    hold[0] = 0.375f;
    assert_int_equal(stsp_init(&c, &t), STSP_OK);
    u[0] = -1.0f;
    assert_int_equal(stsp_step(&c, 0u, x_nan, u), STSP_ERR_NONFINITE_STATE);
    assert_true(u[0] == 0.375f);
    u[0] = -1.0f;
    assert_int_equal(stsp_step(&c, 0u, NULL, u), STSP_ERR_NULL);
    assert_true(u[0] == 0.375f);
    u[0] = -1.0f;
    assert_int_equal(stsp_step(&c, NT, x, u), STSP_ERR_TICK_RANGE);
    assert_true(u[0] == 0.375f);
    assert_true(stsp_step(&c, 0u, x, u) >= STSP_OK);          /* a valid step: the law */
    assert_true(u[0] >= 0.125f && u[0] <= 0.875f);
    hold[0] = 0.5f;                                    /* the table changes after init */
    assert_int_equal(stsp_verify(&c), STSP_ERR_BAD_CRC);   /* the CRC covers u_hold */
    u[0] = -1.0f;
    assert_int_equal(stsp_step(&c, 1u, x, u), STSP_ERR_NOT_INITIALIZED);
    assert_true(u[0] == 0.375f);                       /* the copy, not the changed table */
    hold[0] = 0.375f;
}

static void test_wrong_dimensions(void **state)
{
    const stsp_table_t tb = make_table_b();
    const float x[NX] = {0.0f, 0.0f};
    float u[NU];
    stsp_ctrl_t c;
    (void)state;
    assert_int_equal(stsp_init_expect(&c, &table, NX, NU), STSP_OK);
    assert_int_equal(stsp_step(&c, 0u, x, u), STSP_OK);
    assert_int_equal(stsp_init_expect(&c, &table, NX + 1u, NU), STSP_ERR_BAD_DIMS);
    assert_int_equal(stsp_step(&c, 0u, x, u), STSP_ERR_NOT_INITIALIZED);
    assert_int_equal(stsp_init_expect(&c, &table, NX, NU + 1u), STSP_ERR_BAD_DIMS);
    assert_int_equal(stsp_init_expect(&c, &tb, NX, NU),
                     (EXPECT_TABLE_B == STSP_OK) ? STSP_ERR_BAD_DIMS : EXPECT_TABLE_B);
    assert_int_equal(stsp_init(&c, &tb), EXPECT_TABLE_B);
}

static void test_verify_detects_a_changed_table(void **state)
{
    float Kram[NT * NU * NX];
    stsp_table_t t;
    stsp_ctrl_t c;
    const float x[NX] = {1.0f, 0.0f};
    float u[NU] = {1.0f};
    (void)state;
    memcpy(Kram, K, sizeof K);
    t = make_table();
    t.K = Kram;
    assert_int_equal(stsp_init(&c, &t), STSP_OK);
    assert_int_equal(stsp_verify(&c), STSP_OK);
    assert_int_equal(stsp_step(&c, 0u, x, u), STSP_OK);
    Kram[2] = -Kram[2];                 /* a bit flipped after init */
    assert_int_equal(stsp_verify(&c), STSP_ERR_BAD_CRC);
    u[0] = 1.0f;                        /* stopped: zeros in the validated u[nu] */
    assert_int_equal(stsp_step(&c, 1u, x, u), STSP_ERR_NOT_INITIALIZED);
    assert_true(f32_bits(u[0]) == 0u);
}

/* The table header changes after init (a table in RAM overwritten, flash rewritten): the case
 * stsp_verify() exists for. Until verify runs, stsp_step() keeps to what init validated (the
 * same commands as the unchanged table; nothing read or written outside the arrays, x[nx] and
 * u[nu]); verify then returns STSP_ERR_TABLE_CHANGED without following the changed header,
 * and every later step holds zeros. Arrays, x and u are exact heap blocks (ASan in the _san
 * builds); each tick is also stepped again (a repeat) into a guarded u, so that a write past
 * u[nu] fails every build. */
enum { HDR_NX, HDR_NU, HDR_NL, HDR_NS, HDR_NT, HDR_K, HDR_START, HDR_L_NULL, HDR_MAGIC,
       HDR_VERSION, HDR_KIND, HDR_BAND, HDR_CHANGES };

static void change_header(stsp_table_t *t, int which, const stsp_bandqp_t *band,
                          const uint32_t *short_start)
{
    switch (which) {
    case HDR_NX: t->nx = NX + 1u; break;
    case HDR_NU: t->nu = NU + 1u; break;          /* nu 1 -> 2 */
    case HDR_NL: t->n_latch = N_LATCH + 1u; break;
    case HDR_NS: t->n_stages = NS + 1u; break;
    case HDR_NT: t->n_ticks = NT + 1u; break;
    case HDR_K: t->K = t->k0; break;              /* an array half as long */
    case HDR_START: t->stage_start = short_start; break;
    case HDR_L_NULL: t->L = NULL; break;
    case HDR_MAGIC: t->magic = 0u; break;
    case HDR_VERSION: t->format_version = STSP_FORMAT_VERSION + 1u; break;
    case HDR_KIND: t->scalar_kind = STSP_SCALAR_Q15; break;
    default: t->band_qp = band; break;            /* a band dual appears */
    }
}

static void test_step_and_verify_after_a_header_change(void **state)
{
    static const double nt[2 * 3] = {1.0, 0.0, 0.0, 0.0, 1.0, 0.0}, m3[3] = {0.0, 0.0, 0.0};
    static const double w3[3 * 3] = {1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0};
    static const uint32_t two_starts[2] = {0u, 5u};
    const stsp_bandqp_t band = {3u, 3u, nt, m3, w3, m3, m3, stsp_bandqp_solve_f32};
    const float xs[NT][NX] = {{1.0f, -2.0f}, {0.5f, 0.25f}, {-1.0f, 3.0f},
                              {2.0f, 1.0f}, {-0.5f, -0.75f}};
    int which;
    (void)state;
    for (which = 0; which < HDR_CHANGES; ++which) {
        const stsp_table_t orig = heap_table(make_table());
        stsp_table_t t = orig;
        uint32_t *short_start = heap_copy(two_starts, sizeof two_starts);
        float *x = malloc(sizeof(float) * NX), *u = malloc(sizeof(float) * NU);
        float guard[NU + 1u], u_ref[NU];
        stsp_ctrl_t c, ref;
        uint32_t tick;
        assert_non_null(x);
        assert_non_null(u);
        assert_int_equal(stsp_init(&c, &t), STSP_OK);
        assert_int_equal(stsp_init(&ref, &table), STSP_OK);
        memcpy(x, xs[0], sizeof xs[0]);
        assert_int_equal(stsp_step(&c, 0u, x, u), STSP_OK);
        assert_int_equal(stsp_step(&ref, 0u, xs[0], u_ref), STSP_OK);
        change_header(&t, which, &band, short_start);
        /* Ordinary ticks, the stage-1 latch and the end of the plan, as validated. */
        for (tick = 1u; tick <= NT; ++tick) {
            memcpy(x, xs[tick % NT], sizeof xs[0]);
            assert_int_equal(stsp_step(&c, tick, x, u), stsp_step(&ref, tick, x, u_ref));
            assert_int_equal(f32_bits(u[0]), f32_bits(u_ref[0]));
            guard[NU] = 77.0f;
            assert_int_equal(stsp_step(&c, tick, x, guard), stsp_step(&ref, tick, x, u_ref));
            assert_int_equal(f32_bits(guard[0]), f32_bits(u_ref[0]));
            assert_true(guard[NU] == 77.0f);
        }
        assert_int_equal(stsp_reset(&c), STSP_OK);
        assert_int_equal(stsp_step(&c, 0u, x, u), STSP_OK);
        assert_int_equal(stsp_verify(&c), STSP_ERR_TABLE_CHANGED);
        /* Stopped: every later call refuses, and step holds zeros in the validated u[nu]. */
        u[0] = 5.0f;
        guard[NU] = 77.0f;
        assert_int_equal(stsp_step(&c, 1u, x, u), STSP_ERR_NOT_INITIALIZED);
        assert_true(f32_bits(u[0]) == 0u);
        assert_int_equal(stsp_step(&c, 1u, x, guard), STSP_ERR_NOT_INITIALIZED);
        assert_true(guard[NU] == 77.0f);
        assert_int_equal(stsp_reset(&c), STSP_ERR_NOT_INITIALIZED);
        assert_int_equal(stsp_verify(&c), STSP_ERR_NOT_INITIALIZED);
        free(x);
        free(u);
        free(short_start);
        free_heap_table(&orig);
    }
}

/* Table B (nu = 2) changed to nu = 3 after init; u exactly 2 long (a heap
 * block: ASan), then a guarded u (every build). */
static void test_step_writes_only_the_validated_inputs(void **state)
{
    stsp_table_t tb = make_table_b();
    const float x[1] = {1.5f};
    float *u = malloc(2u * sizeof(float));
    float guard[3];
    stsp_ctrl_t c;
    (void)state;
    assert_non_null(u);
    if (stsp_init(&c, &tb) != STSP_OK) {
        assert_int_equal(EXPECT_TABLE_B, STSP_ERR_BAD_DIMS); /* fixed 2/1/2 build */
        free(u);
        return;
    }
    assert_int_equal(stsp_step(&c, 0u, x, u), STSP_OK);
    tb.nu = 3u;
    assert_int_equal(stsp_step(&c, 1u, x, u), STSP_OK);
    assert_true(u[0] == -1.5f && u[1] == -1.5f);
    guard[2] = 77.0f;
    assert_int_equal(stsp_step(&c, 2u, x, guard), STSP_OK);
    assert_true(guard[0] == -1.5f && guard[1] == -1.5f && guard[2] == 77.0f);
    assert_int_equal(stsp_step(&c, 5u, x, guard), STSP_ERR_TICK_RANGE);
    assert_true(guard[0] == 0.0f && guard[1] == 0.0f && guard[2] == 77.0f);
    assert_int_equal(stsp_verify(&c), STSP_ERR_TABLE_CHANGED);
    u[0] = u[1] = 5.0f;
    assert_int_equal(stsp_step(&c, 2u, x, u), STSP_ERR_NOT_INITIALIZED);
    assert_true(u[0] == 0.0f && u[1] == 0.0f);
    free(u);
}

/* stage_start changed in RAM after init (a data change: the CRC covers it). The stage end the
 * hot path compares with stays within the validated n_ticks, so a stage "longer" than the
 * table never reads K beyond its last tick (a heap block: ASan); verify then reports the CRC. */
static void test_changed_stage_starts_stay_in_bounds(void **state)
{
    const float x[NX] = {0.5f, -0.25f};
    float u[NU];
    uint32_t tick, which;
    (void)state;
    for (which = 1u; which <= NS; ++which) {
        const stsp_table_t t = heap_table(make_table());
        uint32_t *starts = (uint32_t *)t.stage_start;
        stsp_ctrl_t c;
        assert_int_equal(stsp_init(&c, &t), STSP_OK);
        starts[which] = 100u;
        for (tick = 0u; tick < NT; ++tick) {
            assert_true(stsp_step(&c, tick, x, u) >= STSP_OK);
        }
        assert_int_equal(stsp_step(&c, NT, x, u), STSP_ERR_TICK_RANGE);
        assert_int_equal(stsp_verify(&c), STSP_ERR_BAD_CRC);
        u[0] = 5.0f;
        assert_int_equal(stsp_step(&c, 0u, x, u), STSP_ERR_NOT_INITIALIZED);
        assert_true(f32_bits(u[0]) == 0u);
        free_heap_table(&t);
    }
}

/* x and u may be the same buffer or overlap: every read of x happens before the first write
 * of u, so the statuses and commands are those of separate buffers. In particular a finite
 * state whose command overflows is STSP_ERR_NONFINITE_OUTPUT (it was reported as
 * STSP_ERR_NONFINITE_STATE when u overwrote x before the cold path looked at x). */
static void test_state_and_command_may_share_a_buffer(void **state)
{
    const stsp_table_t *tables[3] = {&table, &table_tight, &table_wide};
    const float xs[8][NX] = {{0.36f, 0.0f}, {1.0f, 0.0f}, {-1.0f, 0.0f}, {FLT_MAX, -FLT_MAX},
                             {0.0f, 0.9f}, {NAN, 1.0f}, {0.5f, -INFINITY}, {2.0f, 1.0f}};
    const uint32_t ticks[10] = {0u, 1u, 1u, 2u, 3u, 3u, 4u, 4u, 2u, 4u};
    uint32_t tb, off, n, k;
    (void)state;
    for (tb = 0u; tb < 3u; ++tb) {
        for (off = 0u; off < NX; ++off) {        /* u = &buf[0] (same buffer), &buf[1] */
            for (k = 0u; k < 8u; ++k) {          /* the state of the checked call */
                stsp_ctrl_t a, b;
                assert_int_equal(stsp_init(&a, tables[tb]), STSP_OK);
                assert_int_equal(stsp_init(&b, tables[tb]), STSP_OK);
                for (n = 0u; n < 10u; ++n) {
                    const float *x = xs[(n == k % 10u) ? k : n % 3u];
                    float buf[NX], u[NU];
                    stsp_status_t st_a, st_b;
                    memcpy(buf, x, sizeof buf);
                    st_a = stsp_step(&a, ticks[n], x, u);
                    st_b = stsp_step(&b, ticks[n], buf, &buf[off]);
                    assert_int_equal(st_b, st_a);
                    assert_int_equal(f32_bits(buf[off]), f32_bits(u[0]));
                    assert_memory_equal(&a, &b, sizeof a);
                }
            }
        }
    }
}

/* The overflow itself, on an ordinary tick and on a latch, with one shared buffer. */
static void test_shared_buffer_overflow_is_an_output_error(void **state)
{
    float buf[NX] = {1.0f, 1.0f};
    stsp_ctrl_t c;
    (void)state;
    assert_int_equal(stsp_init(&c, &table), STSP_OK);
    buf[0] = FLT_MAX; buf[1] = -FLT_MAX;          /* the latch overflows (cold path) */
    assert_int_equal(stsp_step(&c, 0u, buf, buf), STSP_ERR_NONFINITE_OUTPUT);
    assert_true(f32_bits(buf[0]) == 0u && buf[1] == -FLT_MAX);
    buf[0] = 1.0f; buf[1] = 1.0f;
    assert_int_equal(stsp_step(&c, 0u, buf, buf), STSP_OK);
    buf[0] = FLT_MAX; buf[1] = -FLT_MAX;          /* the law overflows (ordinary tick) */
    assert_int_equal(stsp_step(&c, 1u, buf, buf), STSP_ERR_NONFINITE_OUTPUT);
    assert_true(f32_bits(buf[0]) == 0u);
    buf[0] = INFINITY; buf[1] = 1.0f;             /* a non-finite state stays a state error */
    assert_int_equal(stsp_step(&c, 1u, buf, buf), STSP_ERR_NONFINITE_STATE);
    assert_true(f32_bits(buf[0]) == 0u);
}

/* Seeded random walk over ticks, states (with NaN, Inf, huge and subnormal entries), resets
 * and both limit settings, against a model of the documented contract: the status, the
 * command (double-precision reference, clamped), zeros on errors, the instance untouched by
 * errors. */
/* The generic float32 build keeps the rows of K, k0 and L of tick next_tick in the instance
 * (stsp_ctrl_t.rows). Between calls they are always those of next_tick in the arrays `t` (the
 * table as init validated it) holds: one past the end of each after the last tick, L NULL
 * without multipliers. A fixed-shape build has no such state. */
#ifndef STSP_FIXED_NX
static void assert_rows_of_next_tick(const stsp_ctrl_t *c, const stsp_table_t *t)
{
    const uint32_t n = c->next_tick;
    assert_true(n <= t->n_ticks);
    assert_ptr_equal(c->rows.K, &t->K[n * t->nu * t->nx]);
    assert_ptr_equal(c->rows.k0, &t->k0[n * t->nu]);
    if (t->n_latch > 0u) {
        assert_ptr_equal(c->rows.L, &t->L[n * t->nu * t->n_latch]);
    } else {
        assert_null(c->rows.L);
    }
}
#else
static void assert_rows_of_next_tick(const stsp_ctrl_t *c, const stsp_table_t *t)
{
    (void)c;
    (void)t;
}
#endif

static uint32_t lcg(uint32_t *s)
{
    *s = *s * 1664525u + 1013904223u;
    return *s >> 8;
}

static float random_x(uint32_t *s)
{
    const uint32_t r = lcg(s) % 100u;
    if (r == 0u) {
        return NAN;
    }
    if (r == 1u) {
        return (lcg(s) & 1u) ? INFINITY : -INFINITY;
    }
    if (r == 2u) {
        return (lcg(s) & 1u) ? FLT_MAX : -FLT_MAX;
    }
    if (r == 3u) {
        return FLT_MIN / 16.0f;
    }
    return ((float)(lcg(s) % 20001u) - 10000.0f) / 2500.0f;
}

static void test_random_walk_against_model(void **state)
{
    const stsp_table_t *tables[2] = {&table, &table_tight};
    uint32_t seed = 12345u, tb, n;
    (void)state;
    for (tb = 0u; tb < 2u; ++tb) {
        const stsp_table_t *t = tables[tb];
        const double lo = t->u_min[0], hi = t->u_max[0];
        stsp_ctrl_t c;
        /* the model: next tick, stage, latch */
        uint32_t m_next = 0u, m_stage = 0u, m_latched = 0u, m_latch_stage = 0u;
        int m_latch_huge = 0;
        float m_latch_x[NX] = {0.0f, 0.0f};
        assert_int_equal(stsp_init(&c, t), STSP_OK);
        for (n = 0u; n < 20000u; ++n) {
            const uint32_t r = lcg(&seed) % 100u;
            uint32_t tick, j, stage;
            float x[NX], u[NU] = {123.0f};
            stsp_ctrl_t before;
            stsp_status_t st, tick_status = STSP_OK;
            int finite = 1, huge = 0, huge_now, relatch;
            double ref, tol;
            if (r < 3u) {
                assert_int_equal(stsp_reset(&c), STSP_OK);
                assert_rows_of_next_tick(&c, t);
                m_next = 0u; m_stage = 0u; m_latched = 0u;
                continue;
            }
            tick = (r < 70u) ? m_next : (r < 80u) ? m_next + 1u + lcg(&seed) % 3u
                 : (r < 88u) ? m_next - 1u : (r < 94u) ? lcg(&seed) % (NT + 2u)
                 : NT + lcg(&seed) % 3u;
            for (j = 0u; j < NX; ++j) {
                x[j] = random_x(&seed);
                finite = finite && isfinite(x[j]);
                huge = huge || !(fabsf(x[j]) < 1e30f);
            }
            memcpy(&before, &c, sizeof c);
            st = stsp_step(&c, tick, x, u);
            assert_rows_of_next_tick(&c, t);
            if (st < STSP_OK) {
                /* every error: zeros, and the instance as it was */
                assert_true(f32_bits(u[0]) == 0u);
                assert_memory_equal(&c, &before, sizeof c);
            }
            if (tick >= NT) {
                assert_int_equal(st, STSP_ERR_TICK_RANGE);
                continue;
            }
            if (m_next > 0u && tick + 1u < m_next) {
                assert_int_equal(st, STSP_ERR_TICK_ORDER);
                continue;
            }
            if (!finite) {
                assert_int_equal(st, STSP_ERR_NONFINITE_STATE);
                continue;
            }
            stage = (tick >= stage_start[1]) ? 1u : 0u;
            relatch = !m_latched || (stage != m_stage && stage_n_latch[stage] > 0u);
            /* a v latched from a huge state stays huge until the next latch */
            huge_now = huge || (!relatch && m_latch_huge);
            if (huge_now && st == STSP_ERR_NONFINITE_OUTPUT) {
                continue;                 /* float32 overflow: the documented error */
            }
            assert_true(st >= STSP_OK);   /* a command: finite, within the limits */
            assert_true(isfinite(u[0]));
            assert_true(u[0] >= t->u_min[0] && u[0] <= t->u_max[0]);
            if (m_next > 0u && tick + 1u == m_next) {
                tick_status = STSP_WARN_TICK_REPEATED;
            } else if (tick > m_next) {
                tick_status = STSP_WARN_TICK_SKIPPED;
            }
            if (!huge_now) {
                ref = relatch ? reference_u_latched(tick, x, x, stage)
                              : reference_u_latched(tick, x, m_latch_x, m_latch_stage);
                tol = 1e-5 + 1e-5 * fabs(ref);
                if (st == STSP_WARN_SATURATED) {
                    assert_true(ref <= lo + tol || ref >= hi - tol);
                } else {
                    assert_int_equal(st, tick_status);
                    assert_true(ref >= lo - tol && ref <= hi + tol);
                }
                assert_float_equal(u[0], clamp(ref, t->u_min[0], t->u_max[0]), tol);
            } else if (st != STSP_WARN_SATURATED) {
                assert_int_equal(st, tick_status);
            }
            if (relatch) {
                m_latch_huge = huge;
                memcpy(m_latch_x, x, sizeof x);
                m_latch_stage = stage;
                m_latched = 1u;
            }
            m_stage = stage;
            if (tick + 1u > m_next) {
                m_next = tick + 1u;
            }
            assert_int_equal(c.next_tick, m_next);
            assert_int_equal(c.stage, m_stage);
        }
    }
}

/* The rows the generic float32 build keeps (stsp_ctrl_t.rows) through every kind of step:
 * init, ordinary ticks, a stage change (latch), a repeat, a skip, refused steps (order, range,
 * a non-finite state on an ordinary tick), the end of the plan, reset, a re-init of the same
 * instance with another table (no multipliers: L NULL), and a header changed after init (the
 * rows come from the validated copy: those of the original arrays). */
static void test_kept_rows_follow_next_tick(void **state)
{
    const float x[NX] = {0.5f, -0.25f}, bad[NX] = {NAN, 1.0f}, xb[1] = {2.0f};
    const stsp_table_t orig = heap_table(make_table());
    stsp_table_t t = orig, tb = make_table_b();
    float u[NU], ub[2];
    stsp_ctrl_t c, before;
    uint32_t tick;
    (void)state;
    assert_int_equal(stsp_init(&c, &table), STSP_OK);
    assert_rows_of_next_tick(&c, &table);
    assert_int_equal(stsp_step(&c, 0u, x, u), STSP_OK);      /* stage 0 latch */
    assert_rows_of_next_tick(&c, &table);
    assert_int_equal(stsp_step(&c, 1u, x, u), STSP_OK);      /* ordinary */
    assert_int_equal(stsp_step(&c, 2u, x, u), STSP_OK);
    assert_rows_of_next_tick(&c, &table);
    memcpy(&before, &c, sizeof c);
    assert_int_equal(stsp_step(&c, 1u, x, u), STSP_ERR_TICK_ORDER);
    assert_int_equal(stsp_step(&c, NT, x, u), STSP_ERR_TICK_RANGE);
    assert_memory_equal(&c, &before, sizeof c);
    assert_int_equal(stsp_step(&c, 3u, x, u), STSP_OK);      /* stage 1 latch */
    assert_rows_of_next_tick(&c, &table);
    assert_int_equal(stsp_step(&c, 3u, x, u), STSP_WARN_TICK_REPEATED);
    assert_rows_of_next_tick(&c, &table);
    memcpy(&before, &c, sizeof c);
    assert_int_equal(stsp_step(&c, 4u, bad, u), STSP_ERR_NONFINITE_STATE); /* ordinary tick */
    assert_memory_equal(&c, &before, sizeof c);
    assert_int_equal(stsp_step(&c, 4u, x, u), STSP_OK);      /* the table's last tick */
    assert_int_equal(c.next_tick, NT);
    assert_rows_of_next_tick(&c, &table);                     /* one past the end */
    assert_int_equal(stsp_step(&c, NT, x, u), STSP_ERR_TICK_RANGE);
    assert_rows_of_next_tick(&c, &table);
    assert_int_equal(stsp_reset(&c), STSP_OK);
    assert_rows_of_next_tick(&c, &table);
    assert_int_equal(stsp_step(&c, 2u, x, u), STSP_WARN_TICK_SKIPPED);
    assert_rows_of_next_tick(&c, &table);
    /* Re-init with table B (two inputs, no multipliers) in the same instance. */
    if (stsp_init(&c, &tb) == STSP_OK) {
        assert_rows_of_next_tick(&c, &tb);
        for (tick = 0u; tick < 3u; ++tick) {
            assert_int_equal(stsp_step(&c, tick, xb, ub), STSP_OK);
            assert_rows_of_next_tick(&c, &tb);
            assert_true(ub[0] == -2.0f && ub[1] == -2.0f);
        }
    } else {
        assert_int_equal(EXPECT_TABLE_B, STSP_ERR_BAD_DIMS);
    }
    /* A header changed after init: K moved to another array, more inputs, more ticks. */
    assert_int_equal(stsp_init(&c, &t), STSP_OK);
    assert_int_equal(stsp_step(&c, 0u, x, u), STSP_OK);
    t.K = t.k0;
    t.nu = NU + 1u;
    t.n_ticks = NT + 1u;
    for (tick = 1u; tick < NT; ++tick) {
        assert_true(stsp_step(&c, tick, x, u) >= STSP_OK);
        assert_rows_of_next_tick(&c, &orig);
        assert_float_equal(u[0], reference_u(tick, x, x), 1e-5);
    }
    assert_int_equal(stsp_reset(&c), STSP_OK);
    assert_rows_of_next_tick(&c, &orig);
    free_heap_table(&orig);
}

/* Table C: nx 3, nu 3 (a pair of rows and an odd last row), n_latch 2, two stages of 3 ticks
 * (stage 1 keeps stage 0's multipliers: stage_n_latch 0), random gains. An ordinary tick (on
 * the rows the instance moved on to) gives the bits of the same tick stepped again (a repeat:
 * the cold path, the rows from the tick index), and the rows kept stay those of next_tick. */
#define C_NX 3u
#define C_NU 3u
#define C_NL 2u
#define C_NT 6u
static void test_ordinary_rows_equal_cold_rows(void **state)
{
    static const uint32_t c_start[3] = {0u, 3u, C_NT};
    static const uint16_t c_n_latch[2] = {2u, 0u};
    static float cK[C_NT * C_NU * C_NX], ck0[C_NT * C_NU], cL[C_NT * C_NU * C_NL];
    static float cLambda[2u * C_NL * C_NX], clambda0[2u * C_NL];
    static const float c_min[C_NU] = {-FLT_MAX, -FLT_MAX, -FLT_MAX};
    static const float c_max[C_NU] = {FLT_MAX, FLT_MAX, FLT_MAX};
    static const float c_hold[C_NU] = {0.0f, 0.0f, 0.0f};
    uint32_t seed = 777u, i, tick;
    stsp_table_t t = table_header(C_NX, C_NU, C_NL, 2u, C_NT, 10u);
    stsp_ctrl_t c, ref;
    (void)state;
    for (i = 0u; i < C_NT * C_NU * C_NX; ++i) {
        cK[i] = (float)((int32_t)(lcg(&seed) % 2001u) - 1000) / 337.0f;
    }
    for (i = 0u; i < C_NT * C_NU; ++i) {
        ck0[i] = (float)((int32_t)(lcg(&seed) % 2001u) - 1000) / 411.0f;
    }
    for (i = 0u; i < C_NT * C_NU * C_NL; ++i) {
        cL[i] = (float)((int32_t)(lcg(&seed) % 2001u) - 1000) / 293.0f;
    }
    for (i = 0u; i < 2u * C_NL * C_NX; ++i) {
        cLambda[i] = (float)((int32_t)(lcg(&seed) % 2001u) - 1000) / 513.0f;
    }
    for (i = 0u; i < 2u * C_NL; ++i) {
        clambda0[i] = (float)((int32_t)(lcg(&seed) % 2001u) - 1000) / 129.0f;
    }
    t.stage_start = c_start; t.stage_n_latch = c_n_latch;
    t.K = cK; t.k0 = ck0; t.L = cL; t.Lambda = cLambda; t.lambda0 = clambda0;
    t.u_min = c_min; t.u_max = c_max; t.u_hold = c_hold;
    t.crc32 = stsp_table_crc32(&t);
    if (stsp_init(&c, &t) != STSP_OK) {
        assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_DIMS); /* a fixed-shape build */
        return;
    }
    assert_int_equal(stsp_init(&ref, &t), STSP_OK);
    for (tick = 0u; tick < C_NT; ++tick) {
        float x[C_NX], u[C_NU], u_ref[C_NU];
        for (i = 0u; i < C_NX; ++i) {
            x[i] = (float)((int32_t)(lcg(&seed) % 2001u) - 1000) / 97.0f;
        }
        assert_int_equal(stsp_step(&c, tick, x, u), STSP_OK);
        assert_rows_of_next_tick(&c, &t);
        assert_int_equal(stsp_step(&ref, tick, x, u_ref), STSP_OK);
        if (tick > 0u) {
            assert_int_equal(stsp_step(&ref, tick, x, u_ref), STSP_WARN_TICK_REPEATED);
        }
        for (i = 0u; i < C_NU; ++i) {
            assert_int_equal(f32_bits(u[i]), f32_bits(u_ref[i]));
        }
    }
}

static void test_status_strings(void **state)
{
    (void)state;
    assert_string_equal(stsp_status_str(STSP_OK), "ok");
    assert_string_equal(stsp_status_str(STSP_ERR_BAD_CRC), "table CRC mismatch");
    assert_string_equal(stsp_status_str(STSP_WARN_SATURATED),
                        "command clamped to the actuator limits");
    assert_string_equal(stsp_status_str(STSP_ERR_BAD_VALUES),
                        "table values not finite or limits invalid");
    assert_string_equal(stsp_status_str(STSP_WARN_BAND_FALLBACK),
                        "band QP failed: latched the design's affine map");
    assert_string_equal(stsp_status_str((stsp_status_t)123), "unknown status");
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_crc_known_answer),
        cmocka_unit_test_setup(test_crc_matches_python_and_covers_limits, setup),
        cmocka_unit_test_setup(test_law_and_latching, setup),
        cmocka_unit_test_setup(test_inactive_limits_change_nothing, setup),
        cmocka_unit_test_setup(test_nonfinite_state, setup),
        cmocka_unit_test_setup(test_safe_command, setup),
        cmocka_unit_test_setup(test_subnormal_state_is_finite, setup),
        cmocka_unit_test_setup(test_overflow_gives_zero_and_error, setup),
        cmocka_unit_test_setup(test_saturation, setup),
        cmocka_unit_test_setup(test_sum_overflow_is_not_an_error, setup),
        cmocka_unit_test_setup(test_table_without_multipliers, setup),
        cmocka_unit_test_setup(test_tick_range_and_order, setup),
        cmocka_unit_test_setup(test_repeated_tick_keeps_latch, setup),
        cmocka_unit_test_setup(test_skipped_stage_start_latches_late, setup),
        cmocka_unit_test_setup(test_reset_restarts, setup),
        cmocka_unit_test_setup(test_instances_are_independent, setup),
        cmocka_unit_test_setup(test_not_initialized_and_null, setup),
        cmocka_unit_test_setup(test_corrupt_tables_are_refused, setup),
        cmocka_unit_test_setup(test_wrong_dimensions, setup),
        cmocka_unit_test_setup(test_verify_detects_a_changed_table, setup),
        cmocka_unit_test_setup(test_step_and_verify_after_a_header_change, setup),
        cmocka_unit_test_setup(test_step_writes_only_the_validated_inputs, setup),
        cmocka_unit_test_setup(test_changed_stage_starts_stay_in_bounds, setup),
        cmocka_unit_test_setup(test_state_and_command_may_share_a_buffer, setup),
        cmocka_unit_test_setup(test_shared_buffer_overflow_is_an_output_error, setup),
        cmocka_unit_test_setup(test_random_walk_against_model, setup),
        cmocka_unit_test_setup(test_kept_rows_follow_next_tick, setup),
        cmocka_unit_test_setup(test_ordinary_rows_equal_cold_rows, setup),
        cmocka_unit_test_setup(test_status_strings, setup),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
