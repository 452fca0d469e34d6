/* The Q15 estimator controller (stsp_estimator.h, fixed point) on the shipped
 * robot_position_sensor_q15 tables: bit for bit against the integer reference
 * (estimator_q_expected.h, from tests/c/estimator_q_reference.py), a saturating reading
 * (STSP_WARN_STATE_CLAMPED), and every bad input's status: readings missing, ticks repeated,
 * skipped, backwards or past the plan, NULL pointers, corrupt or mismatched estimator tables
 * (magic, version, scalar kind, sizes, CRC, exponents, shifts, row sums, problem hash), tables
 * changed after init (verify). Built against the Q15 controller and under ASan + UBSan. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "estimator_tables.h"
#include "estimator_q_expected.h"

#define NX SENSOR(NX)
#define NY SENSOR(NY)
#define EVERY SENSOR(EVERY)
#define N_TICKS SENSOR(N_TICKS)
#define N_SAMPLES ((N_TICKS + EVERY - 1u) / EVERY)

static const stsp_table_t *const T = &TABLE;
static const stsp_est_table_t *const E = &ESTIMATOR;

/* One in-order tick with the recorded reading (none at EST_Q_MISSING). */
static stsp_status_t step_recorded(stsp_est_t *e, uint32_t j, stsp_q15_t u[2])
{
    stsp_q15_t y[2];
    if ((j % EVERY) != 0u) {
        return stsp_est_step(e, j, NULL, u);
    }
    y[0] = est_q_y[j / EVERY][0];
    y[1] = est_q_y[j / EVERY][1];
    return stsp_est_step(e, j, (j == EST_Q_MISSING) ? NULL : y, u);
}

static void test_crc_and_header(void **state)
{
    (void)state;
    assert_int_equal(stsp_est_table_crc32(E), E->crc32);
    assert_int_equal(E->scalar_kind, STSP_SCALAR_Q15);
    assert_int_equal(E->ny, NY);
    assert_int_equal(E->nx, NX);
    assert_memory_equal(E->problem_sha256, T->problem_sha256, 32u);
}

static void test_bit_for_bit_against_the_reference(void **state)
{
    stsp_est_t e;
    stsp_q15_t u[2];
    uint32_t j;
    uint32_t c = 0u;
    uint32_t clamped = 0u;
    uint32_t h = 0x811C9DC5u;
    uint32_t r;
    (void)state;
    assert_int_equal(stsp_est_init(&e, T, E), STSP_OK);
    for (j = 0u; j < N_TICKS; ++j) {
        const stsp_status_t st = step_recorded(&e, j, u);
        if (j == EST_Q_MISSING) {
            assert_int_equal(st, STSP_WARN_NO_MEASUREMENT);
        } else if (st == STSP_WARN_STATE_CLAMPED) {
            ++clamped;
        } else {
            assert_int_equal(st, STSP_OK);
        }
        if (j == EST_Q_SATURATING) {
            assert_int_equal(st, STSP_WARN_STATE_CLAMPED);
        }
        h = est_fnv1a(est_fnv1a(h, (uint32_t)u[0]), (uint32_t)u[1]);
        for (r = 0u; r < NX; ++r) {
            h = est_fnv1a(h, (uint32_t)e.xhat[r]);
        }
        if ((c < EST_Q_N_CHECKED) && (est_q_checked[c] == j)) {
            assert_int_equal(u[0], est_q_checked_u[c][0]);
            assert_int_equal(u[1], est_q_checked_u[c][1]);
            ++c;
        }
    }
    assert_int_equal(c, EST_Q_N_CHECKED);
    assert_int_equal(clamped, EST_Q_N_CLAMPED);
    assert_int_equal(h, EST_Q_HASH);
    assert_int_equal(stsp_est_step(&e, N_TICKS, NULL, u), STSP_ERR_TICK_RANGE);
    assert_true((u[0] == T->u_hold[0]) && (u[1] == T->u_hold[1]));
    /* reset: the same plan again, the same commands */
    assert_int_equal(stsp_est_reset(&e), STSP_OK);
    for (j = 0u; j <= est_q_checked[2]; ++j) {
        (void)step_recorded(&e, j, u);
    }
    assert_int_equal(u[0], est_q_checked_u[2][0]);
    assert_int_equal(u[1], est_q_checked_u[2][1]);
}

static void test_ticks_repeated_skipped_backwards(void **state)
{
    stsp_est_t e;
    stsp_est_t f;
    stsp_q15_t u[2];
    stsp_q15_t again[2];
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
    f = e;
    assert_int_equal(stsp_est_reset(&e), STSP_OK);
    for (j = 0u; j < EST_Q_SKIP_FROM; ++j) {
        assert_int_equal(step_recorded(&e, j, u), STSP_OK);
    }
    assert_int_equal(stsp_est_step(&e, EST_Q_SKIP_TO, NULL, u), STSP_WARN_TICK_SKIPPED);
    assert_int_equal(u[0], est_q_skipped_u[0][0]);
    assert_int_equal(u[1], est_q_skipped_u[0][1]);
    assert_int_equal(stsp_est_step(&e, EST_Q_SKIP_TO + 1u, NULL, u), STSP_OK);
    assert_int_equal(u[0], est_q_skipped_u[1][0]);
    assert_int_equal(u[1], est_q_skipped_u[1][1]);
    /* a skip into stage 1 predicts over 3980 ticks (saturating or not) and latches there */
    assert_true(stsp_est_step(&f, 4000u, NULL, u) > STSP_OK);
    assert_int_equal(f.ctrl.stage, 1u);
}

static void test_null_and_uninitialized(void **state)
{
    stsp_est_t e;
    stsp_q15_t y[2] = {0, 0};
    stsp_q15_t u[2] = {3, 3};
    (void)state;
    memset(&e, 0, sizeof e);
    assert_int_equal(stsp_est_step(&e, 0u, y, u), STSP_ERR_NOT_INITIALIZED);
    assert_true(u[0] == 3);
    assert_int_equal(stsp_est_init(NULL, T, E), STSP_ERR_NULL);
    assert_int_equal(stsp_est_init(&e, NULL, E), STSP_ERR_NULL);
    assert_int_equal(stsp_est_init(&e, T, NULL), STSP_ERR_NULL);
    assert_int_equal(stsp_est_init(&e, T, E), STSP_OK);
    assert_int_equal(stsp_est_step(&e, 0u, y, NULL), STSP_ERR_NULL);
    assert_int_equal(stsp_est_step(NULL, 0u, y, u), STSP_ERR_NULL);
}

static stsp_status_t init_copy(stsp_est_table_t *c)
{
    stsp_est_t e;
    const stsp_status_t st = stsp_est_init(&e, T, c);
    if (st != STSP_OK) {
        stsp_q15_t u[2];
        assert_int_equal(stsp_est_step(&e, 0u, NULL, u), STSP_ERR_NOT_INITIALIZED);
    }
    return st;
}

static stsp_q15_t gain_copy[N_SAMPLES * NX * NY];
static int8_t exp_copy[NY];
static uint8_t shift_copy[NY + 2u * NX];

/* A copy of E with one changed array and its CRC recomputed: the values check's status. */
static stsp_status_t refit(stsp_est_table_t *c)
{
    c->crc32 = stsp_est_table_crc32(c);
    return init_copy(c);
}

static void test_corrupt_tables_are_refused(void **state)
{
    stsp_est_table_t c;
    (void)state;
    c = *E; c.magic ^= 1u;
    assert_int_equal(init_copy(&c), STSP_ERR_BAD_MAGIC);
    c = *E; c.scalar_kind = STSP_SCALAR_FLOAT32;
    assert_int_equal(init_copy(&c), STSP_ERR_BAD_VERSION);
    c = *E; c.scalar_kind = STSP_SCALAR_Q31;
    assert_int_equal(init_copy(&c), STSP_ERR_BAD_VERSION);
    c = *E; c.ny = 0u;
    assert_int_equal(init_copy(&c), STSP_ERR_BAD_DIMS);
    c = *E; c.nx = 3u;
    assert_int_equal(init_copy(&c), STSP_ERR_BAD_DIMS);
    c = *E; c.shift = NULL;
    assert_int_equal(init_copy(&c), STSP_ERR_NULL);
    c = *E; c.y_exp = NULL;
    assert_int_equal(init_copy(&c), STSP_ERR_NULL);
    c = *E; c.e_exp = NULL;
    assert_int_equal(init_copy(&c), STSP_ERR_NULL);
    /* a changed gain: the CRC */
    memcpy(gain_copy, E->gain, sizeof gain_copy);
    gain_copy[17] = (stsp_q15_t)(gain_copy[17] ^ 1);
    c = *E; c.gain = gain_copy;
    assert_int_equal(init_copy(&c), STSP_ERR_BAD_CRC);
    /* a shift outside 1 .. 61 - F (CRC right): the values */
    memcpy(shift_copy, E->shift, sizeof shift_copy);
    shift_copy[NY + 1u] = 0u;
    c = *E; c.shift = shift_copy;
    assert_int_equal(refit(&c), STSP_ERR_BAD_VALUES);
    shift_copy[NY + 1u] = 47u;
    assert_int_equal(refit(&c), STSP_ERR_BAD_VALUES);
    /* a prediction row whose sum could overflow: its pass-through 2^k alone at the limit */
    memcpy(shift_copy, E->shift, sizeof shift_copy);
    shift_copy[NY + NX] = 46u;
    assert_int_equal(refit(&c), STSP_ERR_BAD_VALUES);
    /* an innovation finer than the reading's by too much: the reading's coefficient 2^up with
     * up beyond 61 - F, and an exponent beyond STSP_Q_EXP_MAX */
    memcpy(exp_copy, E->e_exp, sizeof exp_copy);
    exp_copy[0] = -40;
    c = *E; c.e_exp = exp_copy;
    assert_int_equal(refit(&c), STSP_ERR_BAD_VALUES);
    exp_copy[0] = -61;
    assert_int_equal(refit(&c), STSP_ERR_BAD_VALUES);
    /* e_exp above y_exp */
    exp_copy[0] = (int8_t)(E->y_exp[0] + 1);
    assert_int_equal(refit(&c), STSP_ERR_BAD_VALUES);
    /* tables of another problem file (CRC right for the changed hash) */
    c = *E; c.problem_sha256[0] ^= 1u;
    assert_int_equal(refit(&c), STSP_ERR_BAD_PROBLEM);
}

static void test_verify_stops_on_a_changed_table(void **state)
{
    stsp_est_table_t c = *E;
    stsp_est_t e;
    stsp_q15_t u[2];
    (void)state;
    memcpy(shift_copy, E->shift, sizeof shift_copy);
    c.shift = shift_copy;
    assert_int_equal(stsp_est_init(&e, T, &c), STSP_OK);
    assert_int_equal(stsp_est_verify(&e), STSP_OK);
    assert_int_equal(step_recorded(&e, 0u, u), STSP_OK);
    shift_copy[0] = (uint8_t)(shift_copy[0] + 1u); /* the data: the CRC */
    assert_int_equal(stsp_est_verify(&e), STSP_ERR_BAD_CRC);
    assert_int_equal(stsp_est_step(&e, 1u, NULL, u), STSP_ERR_NOT_INITIALIZED);
    assert_true((u[0] == T->u_hold[0]) && (u[1] == T->u_hold[1]));
    memcpy(shift_copy, E->shift, sizeof shift_copy);
    assert_int_equal(stsp_est_init(&e, T, &c), STSP_OK);
    c.e_exp = exp_copy; /* the header: changed */
    assert_int_equal(stsp_est_verify(&e), STSP_ERR_TABLE_CHANGED);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_crc_and_header),
        cmocka_unit_test(test_bit_for_bit_against_the_reference),
        cmocka_unit_test(test_ticks_repeated_skipped_backwards),
        cmocka_unit_test(test_null_and_uninitialized),
        cmocka_unit_test(test_corrupt_tables_are_refused),
        cmocka_unit_test(test_verify_stops_on_a_changed_table),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
