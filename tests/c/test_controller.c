/* Unit tests of the controller on a small hand-made table whose law is checked against a
 * double-precision reference evaluation written out here. */
#include <float.h>
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "stospline/stsp_controller.h"
#include "stsp_crc32.h"

/* nx = 2, nu = 1, n_latch = 2; stage 0 = ticks 0..2 (one multiplier), stage 1 = ticks 3..4. */
#define NX 2u
#define NU 1u
#define NL 2u
#define NT 5u
#define NS 2u

static const uint32_t stage_start[NS + 1u] = {0u, 3u, 5u};
static const uint16_t stage_np[NS] = {1u, 2u};
static const float K[NT * NU * NX] = {0.5f, -1.0f, 0.6f, -1.1f, 0.7f, -1.2f,
                                      0.8f, -1.3f, 0.9f, -1.4f};
static const float k0[NT * NU] = {0.1f, 0.2f, 0.3f, 0.4f, 0.5f};
static const float L[NT * NU * NL] = {2.0f, 0.0f, 2.5f, 0.0f, 3.0f, 0.0f,
                                      1.0f, -1.0f, 1.5f, -1.5f};
static const float Lambda[NS * NL * NX] = {1.0f, 2.0f, 0.0f, 0.0f,
                                           -1.0f, 0.5f, 0.25f, 3.0f};
static const float lambda0[NS * NL] = {-0.5f, 0.0f, 1.0f, -2.0f};

static stsp_table_t make_table(void)
{
    stsp_table_t t;
    memset(&t, 0, sizeof t);
    t.magic = STSP_TABLE_MAGIC;
    t.format_version = STSP_FORMAT_VERSION;
    t.scalar_kind = STSP_SCALAR_FLOAT32;
    t.nx = NX; t.nu = NU; t.n_latch = NL; t.n_stages = NS; t.n_ticks = NT; t.tick_hz = 10u;
    t.stage_start = stage_start; t.stage_np = stage_np;
    t.K = K; t.k0 = k0; t.L = L; t.Lambda = Lambda; t.lambda0 = lambda0;
    t.crc32 = stsp_table_crc32(&t);
    return t;
}

/* Reference law in double: u = -K x - k0 - L v with v latched at `latch_x`. */
static double reference_u(uint32_t tick, const float *x, const float *latch_x)
{
    uint32_t s = (tick >= stage_start[1]) ? 1u : 0u, i, j;
    double v[NL] = {0.0, 0.0}, acc = k0[tick];
    for (i = 0u; i < stage_np[s]; ++i) {
        v[i] = lambda0[s * NL + i];
        for (j = 0u; j < NX; ++j) {
            v[i] += (double)Lambda[(s * NL + i) * NX + j] * latch_x[j];
        }
    }
    for (j = 0u; j < NX; ++j) {
        acc += (double)K[tick * NX + j] * x[j];
    }
    for (i = 0u; i < NL; ++i) {
        acc += (double)L[tick * NL + i] * v[i];
    }
    return -acc;
}

static stsp_table_t table;
static stsp_ctrl_t ctrl;

static int setup(void **state)
{
    (void)state;
    table = make_table();
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
    }
}

static void test_nonfinite_state(void **state)
{
    const float good[NX] = {1.0f, 2.0f};
    float bad[NX] = {1.0f, 0.0f};
    float u[NU] = {42.0f};
    const float specials[3] = {NAN, INFINITY, -INFINITY};
    int i;
    (void)state;
    for (i = 0; i < 3; ++i) {
        bad[1] = specials[i];
        u[0] = 42.0f;
        assert_int_equal(stsp_step(&ctrl, 0u, bad, u), STSP_ERR_NONFINITE_STATE);
        assert_true(u[0] == 0.0f);
    }
    /* The failed steps changed nothing: tick 0 is still the next one and still latches. */
    assert_int_equal(stsp_step(&ctrl, 0u, good, u), STSP_OK);
    assert_float_equal(u[0], reference_u(0u, good, good), 1e-5);
}

static void test_subnormal_state_is_finite(void **state)
{
    const float x[NX] = {FLT_MIN / 4.0f, -FLT_MIN / 8.0f};
    float u[NU];
    (void)state;
    assert_int_equal(stsp_step(&ctrl, 0u, x, u), STSP_OK);
    assert_float_equal(u[0], reference_u(0u, x, x), 1e-6);
}

static void test_overflow_gives_zero_and_error(void **state)
{
    const float huge[NX] = {FLT_MAX, -FLT_MAX};
    float u[NU] = {7.0f};
    (void)state;
    assert_int_equal(stsp_step(&ctrl, 0u, huge, u), STSP_ERR_NONFINITE_OUTPUT);
    assert_true(u[0] == 0.0f);
}

static void test_tick_range_and_order(void **state)
{
    const float x[NX] = {0.1f, 0.2f};
    float u[NU] = {3.0f};
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
}

static void test_repeated_tick_keeps_latch(void **state)
{
    const float x0[NX] = {1.0f, 1.0f}, x1[NX] = {-3.0f, 2.0f};
    float u1[NU], u2[NU];
    (void)state;
    assert_int_equal(stsp_step(&ctrl, 0u, x0, u1), STSP_OK);
    assert_int_equal(stsp_step(&ctrl, 0u, x1, u2), STSP_WARN_TICK_REPEATED);
    assert_float_equal(u2[0], reference_u(0u, x1, x0), 1e-5); /* latch from the first call */
}

static void test_skipped_stage_start_latches_late(void **state)
{
    const float x0[NX] = {1.0f, 1.0f}, x4[NX] = {0.5f, -2.0f};
    float u[NU];
    (void)state;
    assert_int_equal(stsp_step(&ctrl, 0u, x0, u), STSP_OK);
    assert_int_equal(stsp_step(&ctrl, 4u, x4, u), STSP_WARN_TICK_SKIPPED);
    assert_float_equal(u[0], reference_u(4u, x4, x4), 1e-5); /* stage 1 latched at tick 4 */
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
    stsp_ctrl_t fresh;
    const float x[NX] = {0.0f, 0.0f};
    float u[NU] = {9.0f};
    (void)state;
    memset(&fresh, 0, sizeof fresh);
    assert_int_equal(stsp_step(&fresh, 0u, x, u), STSP_ERR_NOT_INITIALIZED);
    assert_int_equal(stsp_reset(&fresh), STSP_ERR_NOT_INITIALIZED);
    assert_int_equal(stsp_step(NULL, 0u, x, u), STSP_ERR_NULL);
    assert_int_equal(stsp_step(&ctrl, 0u, NULL, u), STSP_ERR_NULL);
    assert_true(u[0] == 0.0f);
    assert_int_equal(stsp_step(&ctrl, 0u, x, NULL), STSP_ERR_NULL);
    assert_int_equal(stsp_init(NULL, &table), STSP_ERR_NULL);
    assert_int_equal(stsp_init(&fresh, NULL), STSP_ERR_NULL);
    assert_int_equal(stsp_reset(NULL), STSP_ERR_NULL);
}

static void test_corrupt_tables_are_refused(void **state)
{
    stsp_table_t t;
    stsp_ctrl_t c;
    float Kbad[NT * NU * NX];
    const uint32_t bad_start[NS + 1u] = {0u, 3u, 3u};
    const uint16_t bad_np[NS] = {1u, 3u};
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
    t = make_table(); t.magic = 0u;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_MAGIC);
    t = make_table(); t.format_version = 99u;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_VERSION);
    t = make_table(); t.scalar_kind = 7u;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_VERSION);
    t = make_table(); t.nx = 0u;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_DIMS);
    t = make_table(); t.n_latch = STSP_MAX_LATCH + 1u;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_DIMS);
    t = make_table(); t.stage_start = bad_start;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_DIMS);
    t = make_table(); t.stage_np = bad_np;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_DIMS);
    t = make_table(); t.n_ticks = 6u;    /* disagrees with stage_start[n_stages] */
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_DIMS);
    t = make_table(); t.K = NULL;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_NULL);
}

static void test_status_strings(void **state)
{
    (void)state;
    assert_string_equal(stsp_status_str(STSP_OK), "ok");
    assert_string_equal(stsp_status_str(STSP_ERR_BAD_CRC), "table CRC mismatch");
    assert_string_equal(stsp_status_str((stsp_status_t)123), "unknown status");
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_crc_known_answer),
        cmocka_unit_test_setup(test_law_and_latching, setup),
        cmocka_unit_test_setup(test_nonfinite_state, setup),
        cmocka_unit_test_setup(test_subnormal_state_is_finite, setup),
        cmocka_unit_test_setup(test_overflow_gives_zero_and_error, setup),
        cmocka_unit_test_setup(test_tick_range_and_order, setup),
        cmocka_unit_test_setup(test_repeated_tick_keeps_latch, setup),
        cmocka_unit_test_setup(test_skipped_stage_start_latches_late, setup),
        cmocka_unit_test_setup(test_reset_restarts, setup),
        cmocka_unit_test_setup(test_instances_are_independent, setup),
        cmocka_unit_test_setup(test_not_initialized_and_null, setup),
        cmocka_unit_test_setup(test_corrupt_tables_are_refused, setup),
        cmocka_unit_test_setup(test_status_strings, setup),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
