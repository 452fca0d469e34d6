/* The estimator controller (stsp_estimator.h) on the shipped robot_position_sensor tables:
 * bit for bit against the float32 specification (estimator_expected.h, from
 * tests/c/estimator_reference.py), and every bad input's status: readings NaN/Inf or missing,
 * ticks repeated, skipped, backwards or past the plan, NULL pointers, corrupt or mismatched
 * estimator tables (magic, version, sizes, CRC, values, problem hash), tables changed after
 * init (verify). Built against the generic controller and under ASan + UBSan.
 * Built with STSP_ARITH_Q15 (estimator_q15*): the same on robot_position_sensor_q15.*, bit for
 * bit against the integer reference (estimator_q_expected.h, from
 * tests/c/estimator_q_reference.py; every prediction hashed too), a saturating reading
 * (STSP_WARN_STATE_CLAMPED) and corrupt exponents, shifts and row sums.
 * Built with STSP_ARITH_Q31 (estimator_q31*): the same on robot_position_sensor_q31.*, against
 * estimator_q31_expected.h (tests/c/estimator_q_reference.py --arith q31). */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "estimator_tables.h"
#if defined(STSP_ARITH_Q31)
#include "estimator_q31_expected.h"
#elif defined(STSP_ARITH_FIXED_POINT)
#include "estimator_q_expected.h"
#else
#include "estimator_expected.h"
#endif

#define NX SENSOR(NX)
#define NY SENSOR(NY)
#define EVERY SENSOR(EVERY)
#define N_TICKS SENSOR(N_TICKS)
#define N_SAMPLES ((N_TICKS + EVERY - 1u) / EVERY)

static const stsp_table_t *const T = &TABLE;
static const stsp_est_table_t *const E = &ESTIMATOR;

#ifdef STSP_ARITH_FIXED_POINT
/* A value as the expected values hold it: the integer's 32-bit two's complement. */
static uint32_t bits_of(stsp_scalar_t v)
{
    return (uint32_t)(int32_t)v;
}

static void reading(uint32_t tick, stsp_scalar_t y[2])
{
    y[0] = est_y[tick / EVERY][0];
    y[1] = est_y[tick / EVERY][1];
}

/* A changed table entry (one bit). */
static stsp_scalar_t flipped(stsp_scalar_t v)
{
    return (stsp_scalar_t)(v ^ 1);
}
#else
static uint32_t bits_of(float v)
{
    uint32_t b;
    v = v + 0.0f; /* a zero as +0, as the specification's hash */
    memcpy(&b, &v, sizeof b);
    return b;
}

static void reading(uint32_t tick, float y[2])
{
    memcpy(&y[0], &est_y[tick / EVERY][0], sizeof y[0]);
    memcpy(&y[1], &est_y[tick / EVERY][1], sizeof y[1]);
}

static float flipped(float v)
{
    return -v;
}
#endif

/* One in-order tick with the recorded reading (none at EST_MISSING). */
static stsp_status_t step_recorded(stsp_est_t *e, uint32_t j, stsp_scalar_t u[2])
{
    stsp_scalar_t y[2];
    if ((j % EVERY) != 0u) {
        return stsp_est_step(e, j, NULL, u);
    }
    reading(j, y);
    return stsp_est_step(e, j, (j == EST_MISSING) ? NULL : y, u);
}

static void test_crc_and_header(void **state)
{
    (void)state;
    assert_int_equal(stsp_est_table_crc32(E), E->crc32);
    assert_int_equal(E->scalar_kind, STSP_SCALAR_KIND);
    assert_int_equal(E->ny, NY);
    assert_int_equal(E->every, EVERY);
    assert_int_equal(E->nx, NX);
    assert_memory_equal(E->problem_sha256, T->problem_sha256, 32u);
}

/* The whole plan with the recorded readings: FNV-1a over every command (fixed point: and
 * every prediction), the commands at the checked ticks, each tick's status (*clamped counts
 * STSP_WARN_STATE_CLAMPED, fixed point only). */
static uint32_t run_plan(stsp_est_t *e, uint32_t *clamped)
{
    stsp_scalar_t u[2];
    uint32_t j;
    uint32_t c = 0u;
    uint32_t h = 0x811C9DC5u;
    *clamped = 0u;
    for (j = 0u; j < N_TICKS; ++j) {
        const stsp_status_t st = step_recorded(e, j, u);
        if (j == EST_MISSING) {
            assert_int_equal(st, STSP_WARN_NO_MEASUREMENT);
        } else if (st == STSP_WARN_STATE_CLAMPED) {
            ++*clamped;
        } else {
            assert_int_equal(st, STSP_OK);
        }
        h = est_fnv1a(est_fnv1a(h, bits_of(u[0])), bits_of(u[1]));
#ifdef STSP_ARITH_FIXED_POINT
        {
            uint32_t r;
            for (r = 0u; r < NX; ++r) {
                h = est_fnv1a(h, bits_of(e->xhat[r]));
            }
        }
#endif
        if ((c < EST_N_CHECKED) && (est_checked[c] == j)) {
            assert_int_equal(bits_of(u[0]), est_checked_u[c][0]);
            assert_int_equal(bits_of(u[1]), est_checked_u[c][1]);
            ++c;
        }
    }
    assert_int_equal(c, EST_N_CHECKED);
    return h;
}

static void test_bit_for_bit_against_the_specification(void **state)
{
    stsp_est_t e;
    stsp_scalar_t u[2];
    uint32_t clamped;
    (void)state;
    assert_int_equal(stsp_est_init(&e, T, E), STSP_OK);
    assert_int_equal(run_plan(&e, &clamped), EST_HASH);
#ifdef STSP_ARITH_FIXED_POINT
    assert_int_equal(clamped, EST_N_CLAMPED); /* the saturating reading's tick among them */
    assert_true(EST_N_CLAMPED >= 1u);
#else
    assert_int_equal(clamped, 0u);
#endif
    assert_int_equal(stsp_est_step(&e, N_TICKS, NULL, u), STSP_ERR_TICK_RANGE);
    assert_true((u[0] == T->u_hold[0]) && (u[1] == T->u_hold[1]));
    /* reset: the same plan again, the same commands */
    assert_int_equal(stsp_est_reset(&e), STSP_OK);
    assert_int_equal(run_plan(&e, &clamped), EST_HASH);
}

#ifndef STSP_ARITH_FIXED_POINT
/* A NaN or infinite reading is refused with the safe command and changes nothing: the same
 * tick stepped again with the good reading gives the specification's command. */
static void test_nonfinite_reading(void **state)
{
    const float bad[3] = {NAN, INFINITY, -INFINITY};
    stsp_est_t e;
    float y[2];
    float u[2];
    uint32_t i;
    (void)state;
    assert_int_equal(stsp_est_init(&e, T, E), STSP_OK);
    for (i = 0u; i < 3u; ++i) {
        reading(0u, y);
        y[i % 2u] = bad[i];
        u[0] = u[1] = 7.0f;
        assert_int_equal(stsp_est_step(&e, 0u, y, u), STSP_ERR_NONFINITE_MEASUREMENT);
        assert_true((u[0] == T->u_hold[0]) && (u[1] == T->u_hold[1]));
    }
    assert_int_equal(step_recorded(&e, 0u, u), STSP_OK);
    assert_int_equal(bits_of(u[0]), est_checked_u[0][0]);
    assert_int_equal(bits_of(u[1]), est_checked_u[0][1]);
    /* off a sampling tick y is not read: a NaN there is no error */
    reading(0u, y);
    y[0] = NAN;
    assert_int_equal(stsp_est_step(&e, 1u, y, u), STSP_OK);
    assert_int_equal(bits_of(u[0]), est_checked_u[1][0]);
}
#endif

static void test_ticks_repeated_skipped_backwards(void **state)
{
    stsp_est_t e;
    stsp_est_t f;
    stsp_scalar_t u[2];
    stsp_scalar_t again[2];
    uint32_t j;
    (void)state;
    assert_int_equal(stsp_est_init(&e, T, E), STSP_OK);
    for (j = 0u; j < 20u; ++j) {
        assert_int_equal(step_recorded(&e, j, u), STSP_OK);
    }
    assert_int_equal(stsp_est_step(&e, 19u, NULL, again), STSP_WARN_TICK_REPEATED);
    assert_memory_equal(again, u, sizeof u);
    assert_int_equal(stsp_est_step(&e, 18u, NULL, again), STSP_ERR_TICK_ORDER);
    assert_true((again[0] == T->u_hold[0]) && (again[1] == T->u_hold[1]));
    /* a skip predicts over the missed ticks with the last command held: the specification's
     * commands at the tick skipped to and the one after it */
    f = e;
    assert_int_equal(stsp_est_reset(&e), STSP_OK);
    for (j = 0u; j < EST_SKIP_FROM; ++j) {
        assert_int_equal(step_recorded(&e, j, u), STSP_OK);
    }
    assert_int_equal(stsp_est_step(&e, EST_SKIP_TO, NULL, u), STSP_WARN_TICK_SKIPPED);
    assert_int_equal(bits_of(u[0]), est_skipped_u[0][0]);
    assert_int_equal(bits_of(u[1]), est_skipped_u[0][1]);
    assert_int_equal(stsp_est_step(&e, EST_SKIP_TO + 1u, NULL, u), STSP_OK);
    assert_int_equal(bits_of(u[0]), est_skipped_u[1][0]);
    assert_int_equal(bits_of(u[1]), est_skipped_u[1][1]);
    /* a skip into stage 1 predicts over 3980 ticks and latches there */
    assert_int_equal(stsp_est_step(&f, 4000u, NULL, u), STSP_WARN_TICK_SKIPPED);
#ifndef STSP_ARITH_FIXED_POINT
    assert_true(isfinite(u[0]) && isfinite(u[1]));
#endif
    assert_int_equal(f.ctrl.stage, 1u);
}

static void test_null_and_uninitialized(void **state)
{
    stsp_est_t e;
    stsp_scalar_t y[2] = {(stsp_scalar_t)0, (stsp_scalar_t)0};
    stsp_scalar_t u[2] = {(stsp_scalar_t)3, (stsp_scalar_t)3};
    (void)state;
    memset(&e, 0, sizeof e);
    assert_int_equal(stsp_est_step(&e, 0u, y, u), STSP_ERR_NOT_INITIALIZED);
    assert_true(u[0] == (stsp_scalar_t)3); /* nu unknown: not written */
    assert_int_equal(stsp_est_reset(&e), STSP_ERR_NOT_INITIALIZED);
    assert_int_equal(stsp_est_verify(&e), STSP_ERR_NOT_INITIALIZED);
    assert_int_equal(stsp_est_init(NULL, T, E), STSP_ERR_NULL);
    assert_int_equal(stsp_est_init(&e, NULL, E), STSP_ERR_NULL);
    assert_int_equal(stsp_est_init(&e, T, NULL), STSP_ERR_NULL);
    assert_int_equal(stsp_est_init(&e, T, E), STSP_OK);
    assert_int_equal(stsp_est_step(&e, 0u, y, NULL), STSP_ERR_NULL);
    assert_int_equal(stsp_est_step(NULL, 0u, y, u), STSP_ERR_NULL);
    assert_int_equal(stsp_est_reset(NULL), STSP_ERR_NULL);
    assert_int_equal(stsp_est_verify(NULL), STSP_ERR_NULL);
}

static stsp_status_t init_copy(stsp_est_table_t *c)
{
    stsp_est_t e;
    const stsp_status_t st = stsp_est_init(&e, T, c);
    if (st != STSP_OK) { /* refused: the instance is not ready */
        stsp_scalar_t u[2];
        assert_int_equal(stsp_est_step(&e, 0u, NULL, u), STSP_ERR_NOT_INITIALIZED);
    }
    return st;
}

static stsp_scalar_t gain_copy[N_SAMPLES * NX * NY];
#ifdef STSP_ARITH_FIXED_POINT
static int8_t exp_copy[NY];
static uint8_t shift_copy[NY + 2u * NX];

/* A copy of E with one changed array and its CRC recomputed: the values check's status. */
static stsp_status_t refit(stsp_est_table_t *c)
{
    c->crc32 = stsp_est_table_crc32(c);
    return init_copy(c);
}

/* Exponents, shifts and row sums: the fixed-point values check (CRC right). */
static void corrupt_fixed_point(void)
{
    /* the row limit 2^(61 - F): a shift's largest value */
    const uint8_t k_max = (uint8_t)(61 - STSP_Q_FRAC_BITS);
    stsp_est_table_t c;
    /* tables of the other fixed-point format */
#ifdef STSP_ARITH_Q31
    c = *E; c.scalar_kind = STSP_SCALAR_Q15;
#else
    c = *E; c.scalar_kind = STSP_SCALAR_Q31;
#endif
    assert_int_equal(init_copy(&c), STSP_ERR_BAD_VERSION);
    c = *E; c.shift = NULL;
    assert_int_equal(init_copy(&c), STSP_ERR_NULL);
    c = *E; c.y_exp = NULL;
    assert_int_equal(init_copy(&c), STSP_ERR_NULL);
    c = *E; c.e_exp = NULL;
    assert_int_equal(init_copy(&c), STSP_ERR_NULL);
    /* a shift outside 1 .. 61 - F */
    memcpy(shift_copy, E->shift, sizeof shift_copy);
    shift_copy[NY + 1u] = 0u;
    c = *E; c.shift = shift_copy;
    assert_int_equal(refit(&c), STSP_ERR_BAD_VALUES);
    shift_copy[NY + 1u] = (uint8_t)(k_max + 1u);
    assert_int_equal(refit(&c), STSP_ERR_BAD_VALUES);
    /* a prediction row whose sum could overflow: its pass-through 2^k alone at the limit */
    memcpy(shift_copy, E->shift, sizeof shift_copy);
    shift_copy[NY + NX] = k_max;
    assert_int_equal(refit(&c), STSP_ERR_BAD_VALUES);
    /* an innovation finer than the reading's by too much (the reading's coefficient 2^up with
     * up beyond 61 - F), an exponent beyond STSP_Q_EXP_MAX, e_exp above y_exp */
    memcpy(exp_copy, E->e_exp, sizeof exp_copy);
    exp_copy[0] = -40;
    c = *E; c.e_exp = exp_copy;
    assert_int_equal(refit(&c), STSP_ERR_BAD_VALUES);
    exp_copy[0] = -61;
    assert_int_equal(refit(&c), STSP_ERR_BAD_VALUES);
    exp_copy[0] = (int8_t)(E->y_exp[0] + 1);
    assert_int_equal(refit(&c), STSP_ERR_BAD_VALUES);
}
#endif

static void test_corrupt_tables_are_refused(void **state)
{
    static const uint32_t bad_starts[3] = {0u, 2u, 3u}; /* stage 0 with 2 maps of 3000 ticks */
    stsp_est_table_t c;
    (void)state;
    c = *E; c.magic ^= 1u;
    assert_int_equal(init_copy(&c), STSP_ERR_BAD_MAGIC);
    c = *E; c.format_version = 2u;
    assert_int_equal(init_copy(&c), STSP_ERR_BAD_VERSION);
#ifdef STSP_ARITH_FIXED_POINT
    c = *E; c.scalar_kind = STSP_SCALAR_FLOAT32;
#else
    c = *E; c.scalar_kind = STSP_SCALAR_Q15;
#endif
    assert_int_equal(init_copy(&c), STSP_ERR_BAD_VERSION);
    c = *E; c.ny = 0u;
    assert_int_equal(init_copy(&c), STSP_ERR_BAD_DIMS);
    c = *E; c.ny = (uint16_t)(STSP_MAX_NY + 1u);
    assert_int_equal(init_copy(&c), STSP_ERR_BAD_DIMS);
    c = *E; c.every = 0u;
    assert_int_equal(init_copy(&c), STSP_ERR_BAD_DIMS);
    c = *E; c.nx = 3u;
    assert_int_equal(init_copy(&c), STSP_ERR_BAD_DIMS);
    c = *E; c.nu = 1u;
    assert_int_equal(init_copy(&c), STSP_ERR_BAD_DIMS);
    c = *E; c.n_ticks = 5999u;
    assert_int_equal(init_copy(&c), STSP_ERR_BAD_DIMS);
    c = *E; c.model_start = bad_starts;
    assert_int_equal(init_copy(&c), STSP_ERR_BAD_DIMS);
    c = *E; c.gain = NULL;
    assert_int_equal(init_copy(&c), STSP_ERR_NULL);
    /* one flipped bit of a gain: the CRC */
    memcpy(gain_copy, E->gain, sizeof gain_copy);
    gain_copy[17] = flipped(gain_copy[17]);
    c = *E; c.gain = gain_copy;
    assert_int_equal(init_copy(&c), STSP_ERR_BAD_CRC);
#ifdef STSP_ARITH_FIXED_POINT
    corrupt_fixed_point();
#else
    /* a NaN gain with a matching CRC: the values */
    gain_copy[17] = NAN;
    c.crc32 = stsp_est_table_crc32(&c);
    assert_int_equal(init_copy(&c), STSP_ERR_BAD_VALUES);
#endif
    /* tables of another problem file (CRC right for the changed hash) */
    c = *E; c.problem_sha256[0] ^= 1u;
    c.crc32 = stsp_est_table_crc32(&c);
    assert_int_equal(init_copy(&c), STSP_ERR_BAD_PROBLEM);
    c.crc32 ^= 1u; /* a hash changed without its CRC */
    assert_int_equal(init_copy(&c), STSP_ERR_BAD_CRC);
}

static void test_verify_stops_on_a_changed_table(void **state)
{
    stsp_est_table_t c = *E;
    stsp_est_t e;
    stsp_scalar_t u[2];
    (void)state;
    memcpy(gain_copy, E->gain, sizeof gain_copy);
    c.gain = gain_copy;
    assert_int_equal(stsp_est_init(&e, T, &c), STSP_OK);
    assert_int_equal(stsp_est_verify(&e), STSP_OK);
    assert_int_equal(step_recorded(&e, 0u, u), STSP_OK);
    gain_copy[3] = flipped(gain_copy[3]); /* the data: the CRC */
    assert_int_equal(stsp_est_verify(&e), STSP_ERR_BAD_CRC);
    assert_int_equal(stsp_est_step(&e, 1u, NULL, u), STSP_ERR_NOT_INITIALIZED);
    assert_true((u[0] == T->u_hold[0]) && (u[1] == T->u_hold[1]));
    memcpy(gain_copy, E->gain, sizeof gain_copy);
    assert_int_equal(stsp_est_init(&e, T, &c), STSP_OK);
    c.every = 10u; /* the header: changed, no array read through it */
    assert_int_equal(stsp_est_verify(&e), STSP_ERR_TABLE_CHANGED);
    assert_int_equal(stsp_est_reset(&e), STSP_ERR_NOT_INITIALIZED);
#ifdef STSP_ARITH_FIXED_POINT
    c.every = E->every; /* an exponent array moved: the header too */
    assert_int_equal(stsp_est_init(&e, T, &c), STSP_OK);
    memcpy(exp_copy, E->e_exp, sizeof exp_copy);
    c.e_exp = exp_copy;
    assert_int_equal(stsp_est_verify(&e), STSP_ERR_TABLE_CHANGED);
#endif
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_crc_and_header),
        cmocka_unit_test(test_bit_for_bit_against_the_specification),
#ifndef STSP_ARITH_FIXED_POINT
        cmocka_unit_test(test_nonfinite_reading),
#endif
        cmocka_unit_test(test_ticks_repeated_skipped_backwards),
        cmocka_unit_test(test_null_and_uninitialized),
        cmocka_unit_test(test_corrupt_tables_are_refused),
        cmocka_unit_test(test_verify_stops_on_a_changed_table),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
