/* Runtime parameters (stsp_params.h) on the shipped robot_goal tables: bit for bit against the
 * float32 specification (params_expected.h, from tests/c/params_reference.py) for a fixed
 * theta, a change at a stage start and a change inside a stage; at the nominal the commands of
 * stsp_step(); every bad input's status: theta NaN/Inf/outside the range (the old parameters
 * kept), NULL pointers, mismatched or corrupt parameter tables (magic, version, Q kind, sizes,
 * CRC, values, problem hash), tables changed after init (verify). Built against the generic
 * controller and under ASan + UBSan. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "robot_goal_params.h"
#include "params_expected.h"

#define NX ROBOT_GOAL_NX
#define NU ROBOT_GOAL_NU
#define N_TICKS ROBOT_GOAL_N_TICKS

static const stsp_table_t *const T = &robot_goal_table;
static const stsp_params_table_t *const P = &robot_goal_params;

static uint32_t bits_of(float v)
{
    uint32_t b;
    v = v + 0.0f; /* a zero as +0, as the specification's hash */
    memcpy(&b, &v, sizeof b);
    return b;
}

static uint32_t fnv1a(uint32_t h, uint32_t w)
{
    uint32_t i;
    for (i = 0u; i < 4u; ++i) {
        h = (h ^ ((w >> (8u * i)) & 0xFFu)) * 0x01000193u;
    }
    return h;
}

/* The state of tick j, as params_reference.params_state(). */
static void state(uint32_t j, float x[NX])
{
    uint32_t c;
    for (c = 0u; c < NX; ++c) {
        x[c] = (float)((7u * j + 13u * c) % 41u) * 0.05f - 1.0f;
    }
}

/* A run over every tick: theta0 set before tick 0 (NULL: the nominal), theta1 before tick
 * `at` (NULL: none); returns the hash of the commands, run A's checked ticks into checked. */
static uint32_t run(const float *theta0, uint32_t at, const float *theta1,
                    uint32_t checked[PAR_N_CHECKED][2])
{
    stsp_param_t pc;
    float x[NX];
    float u[NU];
    uint32_t h = 0x811C9DC5u;
    uint32_t j;
    uint32_t k = 0u;
    assert_int_equal(stsp_param_init(&pc, T, P), STSP_OK);
    if (theta0 != NULL) {
        assert_int_equal(stsp_set_params(&pc, theta0), STSP_OK);
    }
    for (j = 0u; j < N_TICKS; ++j) {
        stsp_status_t st;
        if ((theta1 != NULL) && (j == at)) {
            assert_int_equal(stsp_set_params(&pc, theta1), STSP_OK);
        }
        state(j, x);
        st = stsp_param_step(&pc, j, x, u);
        assert_true((st == STSP_OK) || (st == STSP_WARN_SATURATED));
        h = fnv1a(fnv1a(h, bits_of(u[0])), bits_of(u[1]));
        if ((checked != NULL) && (k < PAR_N_CHECKED) && (par_checked[k] == j)) {
            checked[k][0] = bits_of(u[0]);
            checked[k][1] = bits_of(u[1]);
            ++k;
        }
    }
    return h;
}

static void test_fixed_theta_matches_spec(void **state_)
{
    static const float theta[2] = PAR_THETA_A;
    uint32_t checked[PAR_N_CHECKED][2];
    uint32_t k;
    (void)state_;
    assert_int_equal(run(theta, 0u, NULL, checked), PAR_HASH_A);
    for (k = 0u; k < PAR_N_CHECKED; ++k) {
        assert_int_equal(checked[k][0], par_checked_u[k][0]);
        assert_int_equal(checked[k][1], par_checked_u[k][1]);
    }
}

static void test_change_at_stage_start_matches_spec(void **state_)
{
    static const float theta[2] = PAR_THETA_B;
    (void)state_;
    assert_int_equal(run(NULL, robot_goal_table.stage_start[1], theta, NULL), PAR_HASH_B);
}

static void test_change_mid_stage_matches_spec(void **state_)
{
    static const float a[2] = PAR_THETA_A;
    static const float b[2] = PAR_THETA_B;
    (void)state_;
    assert_int_equal(run(a, PAR_MID, b, NULL), PAR_HASH_C);
}

/* At the nominal the parametric law is stsp_step()'s, bit for bit (up to a zero's sign). */
static void test_nominal_is_stsp_step(void **state_)
{
    stsp_param_t pc;
    stsp_ctrl_t ctrl;
    float x[NX], u[NU], w[NU];
    uint32_t j;
    (void)state_;
    assert_int_equal(stsp_param_init(&pc, T, P), STSP_OK);
    assert_int_equal(stsp_set_params(&pc, robot_goal_param_nominal), STSP_OK);
    assert_int_equal(stsp_init(&ctrl, T), STSP_OK);
    for (j = 0u; j < N_TICKS; ++j) {
        state(j, x);
        assert_int_equal(stsp_param_step(&pc, j, x, u), stsp_step(&ctrl, j, x, w));
        assert_int_equal(bits_of(u[0]), bits_of(w[0]));
        assert_int_equal(bits_of(u[1]), bits_of(w[1]));
    }
}

/* Bad theta: the status, and the parameters in use unchanged (the same commands after). */
static void test_bad_theta_keeps_the_old(void **state_)
{
    static const float good[2] = PAR_THETA_A;
    stsp_param_t pc;
    stsp_param_t ref;
    float bad[5][2] = {{NAN, 5.0f}, {-1.0f, INFINITY}, {-INFINITY, 5.0f}, {-0.49f, 5.0f},
                       {-1.0f, 5.51f}};
    float x[NX], u[NU], w[NU];
    uint32_t k;
    (void)state_;
    assert_int_equal(stsp_param_init(&pc, T, P), STSP_OK);
    assert_int_equal(stsp_param_init(&ref, T, P), STSP_OK);
    assert_int_equal(stsp_set_params(&pc, good), STSP_OK);
    assert_int_equal(stsp_set_params(&ref, good), STSP_OK);
    for (k = 0u; k < 5u; ++k) {
        assert_int_equal(stsp_set_params(&pc, bad[k]), STSP_ERR_PARAM_RANGE);
    }
    /* the range's ends are inside */
    assert_int_equal(stsp_set_params(&ref, robot_goal_param_lower), STSP_OK);
    assert_int_equal(stsp_set_params(&ref, robot_goal_param_upper), STSP_OK);
    assert_int_equal(stsp_set_params(&ref, good), STSP_OK);
    for (k = 0u; k < N_TICKS; k += 37u) {
        state(k, x);
        assert_true(stsp_param_step(&pc, k, x, u) >= 0);
        assert_true(stsp_param_step(&ref, k, x, w) >= 0);
        assert_memory_equal(u, w, sizeof u);
    }
    assert_int_equal(stsp_set_params(NULL, good), STSP_ERR_NULL);
    assert_int_equal(stsp_set_params(&pc, NULL), STSP_ERR_NULL);
}

static void test_null_and_not_ready(void **state_)
{
    stsp_param_t pc;
    float x[NX] = {0}, u[NU] = {7.0f, 7.0f};
    static const float good[2] = PAR_THETA_A;
    (void)state_;
    assert_int_equal(stsp_param_init(NULL, T, P), STSP_ERR_NULL);
    assert_int_equal(stsp_param_init(&pc, T, NULL), STSP_ERR_NULL);
    assert_int_equal(stsp_param_init(&pc, NULL, P), STSP_ERR_NULL);
    assert_int_equal(stsp_param_step(&pc, 0u, x, u), STSP_ERR_NOT_INITIALIZED);
    assert_true(u[0] == 7.0f); /* not written: nu unknown */
    assert_int_equal(stsp_set_params(&pc, good), STSP_ERR_NOT_INITIALIZED);
    assert_int_equal(stsp_param_reset(&pc), STSP_ERR_NOT_INITIALIZED);
    assert_int_equal(stsp_param_verify(&pc), STSP_ERR_NOT_INITIALIZED);
    assert_int_equal(stsp_param_init(&pc, T, P), STSP_OK);
    assert_int_equal(stsp_param_step(&pc, 0u, NULL, u), STSP_ERR_NULL);
    assert_memory_equal(u, robot_goal_table.u_hold, sizeof u);
    assert_int_equal(stsp_param_step(&pc, 0u, x, NULL), STSP_ERR_NULL);
    x[2] = NAN;
    assert_int_equal(stsp_param_step(&pc, 0u, x, u), STSP_ERR_NONFINITE_STATE);
    assert_memory_equal(u, robot_goal_table.u_hold, sizeof u);
    x[2] = 0.0f;
    assert_true(stsp_param_step(&pc, 0u, x, u) >= 0);
    assert_int_equal(stsp_param_step(&pc, N_TICKS, x, u), STSP_ERR_TICK_RANGE);
    assert_int_equal(stsp_param_reset(&pc), STSP_OK);
    assert_true(stsp_param_step(&pc, 0u, x, u) >= 0);
}

/* A copy of the parameter table with one thing wrong: init's status, instance not ready. */
static void expect_refused(const stsp_params_table_t *bad, stsp_status_t want)
{
    stsp_param_t pc;
    float x[NX] = {0}, u[NU];
    assert_int_equal(stsp_param_init(&pc, T, bad), want);
    assert_int_equal(stsp_param_step(&pc, 0u, x, u), STSP_ERR_NOT_INITIALIZED);
}

static void test_bad_tables(void **state_)
{
    static float s_k0[2 * N_TICKS * NU];
    static float nominal[2];
    stsp_params_table_t bad;
    (void)state_;
    bad = *P; bad.magic ^= 1u; expect_refused(&bad, STSP_ERR_BAD_MAGIC);
    bad = *P; bad.format_version = 9u; expect_refused(&bad, STSP_ERR_BAD_VERSION);
    bad = *P; bad.scalar_kind = STSP_SCALAR_Q15; expect_refused(&bad, STSP_ERR_BAD_VERSION);
    bad = *P; bad.scalar_kind = STSP_SCALAR_Q31; expect_refused(&bad, STSP_ERR_BAD_VERSION);
    bad = *P; bad.n_params = 0u; expect_refused(&bad, STSP_ERR_BAD_DIMS);
    bad = *P; bad.n_params = STSP_MAX_PARAMS + 1u; expect_refused(&bad, STSP_ERR_BAD_DIMS);
    bad = *P; bad.nu = 3u; expect_refused(&bad, STSP_ERR_BAD_DIMS);
    bad = *P; bad.n_latch = 2u; expect_refused(&bad, STSP_ERR_BAD_DIMS);
    bad = *P; bad.n_stages = 1u; expect_refused(&bad, STSP_ERR_BAD_DIMS);
    bad = *P; bad.n_ticks = 599u; expect_refused(&bad, STSP_ERR_BAD_DIMS);
    bad = *P; bad.S_k0 = NULL; expect_refused(&bad, STSP_ERR_NULL);
    bad = *P; bad.S_lambda0 = NULL; expect_refused(&bad, STSP_ERR_NULL);
    bad = *P; bad.crc32 ^= 1u; expect_refused(&bad, STSP_ERR_BAD_CRC);
    /* a corrupted column: the CRC */
    memcpy(s_k0, robot_goal_S_k0, sizeof s_k0);
    s_k0[123] = s_k0[123] * 2.0f + 1.0f;
    bad = *P; bad.S_k0 = s_k0; expect_refused(&bad, STSP_ERR_BAD_CRC);
    /* another problem's table: the hash (CRC recomputed, as a generator would) */
    bad = *P; bad.problem_sha256[0] ^= 1u; bad.crc32 = stsp_params_table_crc32(&bad);
    expect_refused(&bad, STSP_ERR_BAD_PROBLEM);
    /* values: a NaN column entry, a nominal outside its range */
    s_k0[123] = NAN;
    bad = *P; bad.S_k0 = s_k0; bad.crc32 = stsp_params_table_crc32(&bad);
    expect_refused(&bad, STSP_ERR_BAD_VALUES);
    memcpy(nominal, robot_goal_param_nominal, sizeof nominal);
    nominal[1] = 6.0f;
    bad = *P; bad.nominal = nominal; bad.crc32 = stsp_params_table_crc32(&bad);
    expect_refused(&bad, STSP_ERR_BAD_VALUES);
    assert_int_equal(stsp_params_table_crc32(P), P->crc32);
}

static void test_verify(void **state_)
{
    static float nominal[2];
    stsp_param_t pc;
    stsp_params_table_t changing = *P;
    float x[NX] = {0}, u[NU];
    (void)state_;
    memcpy(nominal, robot_goal_param_nominal, sizeof nominal);
    changing.nominal = nominal;
    assert_int_equal(stsp_param_init(&pc, T, &changing), STSP_OK);
    assert_int_equal(stsp_param_verify(&pc), STSP_OK);
    nominal[0] = -1.25f; /* RAM changed after init */
    assert_int_equal(stsp_param_verify(&pc), STSP_ERR_BAD_CRC);
    assert_int_equal(stsp_param_step(&pc, 0u, x, u), STSP_ERR_NOT_INITIALIZED);
    assert_memory_equal(u, robot_goal_table.u_hold, sizeof u);
    nominal[0] = robot_goal_param_nominal[0];
    assert_int_equal(stsp_param_init(&pc, T, &changing), STSP_OK);
    changing.n_ticks = 10u;
    assert_int_equal(stsp_param_verify(&pc), STSP_ERR_TABLE_CHANGED);
    assert_int_equal(stsp_param_step(&pc, 0u, x, u), STSP_ERR_NOT_INITIALIZED);
}

/* A change inside a stage: the feed-forward moves at once, the multipliers at the next latch;
 * a change before a stage start is the run at the new theta from there on. */
static void test_when_it_takes_effect(void **state_)
{
    static const float b[2] = PAR_THETA_B;
    stsp_param_t late, early;
    float x[NX], u[NU], w[NU];
    uint32_t j;
    const uint32_t s1 = robot_goal_table.stage_start[1];
    (void)state_;
    assert_int_equal(stsp_param_init(&late, T, P), STSP_OK);
    assert_int_equal(stsp_param_init(&early, T, P), STSP_OK);
    assert_int_equal(stsp_set_params(&early, b), STSP_OK);
    for (j = 0u; j < N_TICKS; ++j) {
        if (j == s1) {
            assert_int_equal(stsp_set_params(&late, b), STSP_OK);
        }
        state(j, x);
        assert_true(stsp_param_step(&late, j, x, u) >= 0);
        assert_true(stsp_param_step(&early, j, x, w) >= 0);
        if (j >= s1) { /* stage 1 relatches all its multipliers: the same plan from here */
            assert_memory_equal(u, w, sizeof u);
        }
    }
    assert_memory_equal(late.ctrl.v, early.ctrl.v, sizeof late.ctrl.v);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_fixed_theta_matches_spec),
        cmocka_unit_test(test_change_at_stage_start_matches_spec),
        cmocka_unit_test(test_change_mid_stage_matches_spec),
        cmocka_unit_test(test_nominal_is_stsp_step),
        cmocka_unit_test(test_bad_theta_keeps_the_old),
        cmocka_unit_test(test_null_and_not_ready),
        cmocka_unit_test(test_bad_tables),
        cmocka_unit_test(test_verify),
        cmocka_unit_test(test_when_it_takes_effect),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
