/* Runtime parameters (stsp_params.h) on the shipped robot_goal tables, in every arithmetic:
 * float32 on gains/robot_goal* bit for bit against the float32 specification
 * (params_expected.h, from tests/c/params_reference.py), Q15/Q31 on gains/robot_goal_<arith>*
 * bit for bit against the host's reference (params_q_expected.h, from
 * tests/c/params_q_reference.py): a fixed theta, a change at a stage start and a change inside
 * a stage; at the nominal the commands of stsp_step(); the clamp to narrowed limits; every bad
 * input's status: theta NaN/Inf/outside the range (the old parameters kept), NULL pointers,
 * mismatched or corrupt parameter tables (magic, version, scalar kind, sizes, CRC, values,
 * problem hash; fixed point also exponents, row sums beyond 2^F - 1 and a d_exp too small for
 * the range), tables changed after init (verify). Built against the generic controller of
 * each arithmetic and under ASan + UBSan. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#if defined(STSP_ARITH_Q15)
#include "robot_goal_q15_params.h"
#define G(name) robot_goal_q15_##name
#define QMAX INT16_MAX
#define LIMIT 100 /* a narrowed u_max[0], command units */
#elif defined(STSP_ARITH_Q31)
#include "robot_goal_q31_params.h"
#define G(name) robot_goal_q31_##name
#define QMAX INT32_MAX
#define LIMIT (100 << 16)
#else
#include "robot_goal_params.h"
#define G(name) robot_goal_##name
#define LIMIT 0.2f
#endif
#ifdef STSP_ARITH_FIXED_POINT
#include "params_q_expected.h"
#else
#include "params_expected.h"
#endif

#define NX 4u
#define NU 2u
#define N_TICKS 600u
#define N_PARAMS 2u

static const stsp_table_t *const T = &G(table);
static const stsp_params_table_t *const P = &G(params);

#define N_CHECKED PAR_N_CHECKED
#define CHECKED_TICKS par_checked
#include "params_run.h"

/* theta[p] = values[p] as binary32 (the table's nominal, lower or upper). */
static void as_theta(const stsp_param_value_t *values, float theta[N_PARAMS])
{
    theta[0] = (float)values[0];
    theta[1] = (float)values[1];
}

static void test_fixed_theta_matches_reference(void **state_)
{
    static const float theta[N_PARAMS] = PAR_THETA_A;
    uint32_t checked[PAR_N_CHECKED][2];
    uint32_t k;
    (void)state_;
    assert_int_equal(run(theta, 0u, NULL, checked), PAR_HASH_A);
    for (k = 0u; k < PAR_N_CHECKED; ++k) {
        assert_int_equal(checked[k][0], (uint32_t)par_checked_u[k][0]);
        assert_int_equal(checked[k][1], (uint32_t)par_checked_u[k][1]);
    }
}

static void test_change_at_stage_start_matches_reference(void **state_)
{
    static const float theta[N_PARAMS] = PAR_THETA_B;
    (void)state_;
    assert_int_equal(run(NULL, T->stage_start[1], theta, NULL), PAR_HASH_B);
}

static void test_change_mid_stage_matches_reference(void **state_)
{
    static const float a[N_PARAMS] = PAR_THETA_A;
    static const float b[N_PARAMS] = PAR_THETA_B;
    (void)state_;
    assert_int_equal(run(a, PAR_MID, b, NULL), PAR_HASH_C);
}

/* At the nominal the parametric law is stsp_step()'s, bit for bit (up to a zero's sign). */
static void test_nominal_is_stsp_step(void **state_)
{
    float nominal[N_PARAMS];
    stsp_param_t pc;
    stsp_ctrl_t ctrl;
    stsp_scalar_t x[NX], u[NU], w[NU];
    uint32_t j;
    (void)state_;
    as_theta(G(param_nominal), nominal);
    assert_int_equal(stsp_param_init(&pc, T, P), STSP_OK);
    assert_int_equal(stsp_set_params(&pc, nominal), STSP_OK);
    assert_int_equal(stsp_init(&ctrl, T), STSP_OK);
    for (j = 0u; j < N_TICKS; ++j) {
        state(j, x);
        assert_int_equal(stsp_param_step(&pc, j, x, u), stsp_step(&ctrl, j, x, w));
        assert_int_equal(word(u[0]), word(w[0]));
        assert_int_equal(word(u[1]), word(w[1]));
    }
}

/* Limits narrower than the commands: clamped, STSP_WARN_SATURATED, sat_mask. */
static void test_limits_clamp(void **state_)
{
    static stsp_scalar_t u_max[NU];
    static const float theta[N_PARAMS] = PAR_THETA_A;
    stsp_table_t narrow = *T;
    stsp_param_t pc, wide;
    stsp_scalar_t x[NX], u[NU], w[NU];
    uint32_t j;
    uint32_t saturated = 0u;
    (void)state_;
    u_max[0] = LIMIT;
    u_max[1] = T->u_max[1];
    narrow.u_max = u_max;
    narrow.crc32 = stsp_table_crc32(&narrow);
    assert_int_equal(stsp_param_init(&pc, &narrow, P), STSP_OK);
    assert_int_equal(stsp_param_init(&wide, T, P), STSP_OK);
    assert_int_equal(stsp_set_params(&pc, theta), STSP_OK);
    assert_int_equal(stsp_set_params(&wide, theta), STSP_OK);
    for (j = 0u; j < N_TICKS; ++j) {
        stsp_status_t st;
        state(j, x);
        st = stsp_param_step(&pc, j, x, u);
        assert_int_equal(stsp_param_step(&wide, j, x, w), STSP_OK);
        assert_int_equal(word(u[1]), word(w[1]));
        if (w[0] > LIMIT) {
            assert_int_equal(st, STSP_WARN_SATURATED);
            assert_true(u[0] == LIMIT);
            assert_int_equal(pc.ctrl.sat_mask, 1u);
            ++saturated;
        } else {
            assert_int_equal(st, STSP_OK);
            assert_int_equal(word(u[0]), word(w[0]));
        }
    }
    assert_true(saturated > 0u);
}

/* Bad theta: the status, and the parameters in use unchanged (the same commands after). */
static void test_bad_theta_keeps_the_old(void **state_)
{
    static const float good[N_PARAMS] = PAR_THETA_A;
    float lower[N_PARAMS], upper[N_PARAMS];
    stsp_param_t pc;
    stsp_param_t ref;
    float bad[5][N_PARAMS] = {{NAN, 5.0f}, {-1.0f, INFINITY}, {-INFINITY, 5.0f},
                              {-0.49f, 5.0f}, {-1.0f, 5.51f}};
    stsp_scalar_t x[NX], u[NU], w[NU];
    uint32_t k;
    (void)state_;
    as_theta(G(param_lower), lower);
    as_theta(G(param_upper), upper);
    assert_int_equal(stsp_param_init(&pc, T, P), STSP_OK);
    assert_int_equal(stsp_param_init(&ref, T, P), STSP_OK);
    assert_int_equal(stsp_set_params(&pc, good), STSP_OK);
    assert_int_equal(stsp_set_params(&ref, good), STSP_OK);
    for (k = 0u; k < 5u; ++k) {
        assert_int_equal(stsp_set_params(&pc, bad[k]), STSP_ERR_PARAM_RANGE);
    }
    /* the range's ends are inside (fixed point: their d_q within the Q range) */
    assert_int_equal(stsp_set_params(&ref, lower), STSP_OK);
    assert_true(ref.d[0] < 0);
    assert_int_equal(stsp_set_params(&ref, upper), STSP_OK);
    assert_true(ref.d[0] > 0);
    assert_int_equal(stsp_set_params(&ref, good), STSP_OK);
    assert_memory_equal(pc.d, ref.d, sizeof pc.d);
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
    stsp_scalar_t x[NX] = {0}, u[NU] = {7, 7};
    static const float good[N_PARAMS] = PAR_THETA_A;
    (void)state_;
    assert_int_equal(stsp_param_init(NULL, T, P), STSP_ERR_NULL);
    assert_int_equal(stsp_param_init(&pc, T, NULL), STSP_ERR_NULL);
    assert_int_equal(stsp_param_init(&pc, NULL, P), STSP_ERR_NULL);
    assert_int_equal(stsp_param_step(&pc, 0u, x, u), STSP_ERR_NOT_INITIALIZED);
    assert_true(u[0] == 7); /* not written: nu unknown */
    assert_int_equal(stsp_set_params(&pc, good), STSP_ERR_NOT_INITIALIZED);
    assert_int_equal(stsp_param_reset(&pc), STSP_ERR_NOT_INITIALIZED);
    assert_int_equal(stsp_param_verify(&pc), STSP_ERR_NOT_INITIALIZED);
    assert_int_equal(stsp_param_init(&pc, T, P), STSP_OK);
    assert_int_equal(stsp_param_step(&pc, 0u, NULL, u), STSP_ERR_NULL);
    assert_memory_equal(u, T->u_hold, sizeof u);
    assert_int_equal(stsp_param_step(&pc, 0u, x, NULL), STSP_ERR_NULL);
#ifndef STSP_ARITH_FIXED_POINT
    x[2] = NAN;
    assert_int_equal(stsp_param_step(&pc, 0u, x, u), STSP_ERR_NONFINITE_STATE);
    assert_memory_equal(u, T->u_hold, sizeof u);
    x[2] = 0.0f;
#endif
    assert_true(stsp_param_step(&pc, 0u, x, u) >= 0);
    assert_int_equal(stsp_param_step(&pc, N_TICKS, x, u), STSP_ERR_TICK_RANGE);
    assert_int_equal(stsp_param_reset(&pc), STSP_OK);
    assert_true(stsp_param_step(&pc, 0u, x, u) >= 0);
}

/* A copy of the parameter table with one thing wrong: init's status, instance not ready. */
static void expect_refused(const stsp_params_table_t *bad, stsp_status_t want)
{
    stsp_param_t pc;
    stsp_scalar_t x[NX] = {0}, u[NU];
    assert_int_equal(stsp_param_init(&pc, T, bad), want);
    assert_int_equal(stsp_param_step(&pc, 0u, x, u), STSP_ERR_NOT_INITIALIZED);
}

/* `bad` with its CRC recomputed (as a generator would): refused with `want`. */
static void expect_refused_with_crc(stsp_params_table_t bad, stsp_status_t want)
{
    bad.crc32 = stsp_params_table_crc32(&bad);
    expect_refused(&bad, want);
}

/* Every scalar kind but the build's: STSP_ERR_BAD_VERSION. */
static void expect_other_kinds_refused(void)
{
    static const uint16_t kinds[3] = {STSP_SCALAR_FLOAT32, STSP_SCALAR_Q15, STSP_SCALAR_Q31};
    stsp_params_table_t bad;
    uint32_t k;
    for (k = 0u; k < 3u; ++k) {
        if (kinds[k] != STSP_SCALAR_KIND) {
            bad = *P;
            bad.scalar_kind = kinds[k];
            expect_refused(&bad, STSP_ERR_BAD_VERSION);
        }
    }
}

static void test_bad_tables(void **state_)
{
    static stsp_scalar_t s_k0[N_PARAMS * N_TICKS * NU];
    static stsp_param_value_t values[N_PARAMS];
    stsp_params_table_t bad;
    (void)state_;
    bad = *P; bad.magic ^= 1u; expect_refused(&bad, STSP_ERR_BAD_MAGIC);
    bad = *P; bad.format_version = 9u; expect_refused(&bad, STSP_ERR_BAD_VERSION);
    /* spline columns (format 2): for a spline gain table only */
    bad = *P; bad.format_version = 2u; expect_refused(&bad, STSP_ERR_BAD_DIMS);
    expect_other_kinds_refused();
    bad = *P; bad.n_params = 0u; expect_refused(&bad, STSP_ERR_BAD_DIMS);
    bad = *P; bad.n_params = STSP_MAX_PARAMS + 1u; expect_refused(&bad, STSP_ERR_BAD_DIMS);
    bad = *P; bad.nu = 3u; expect_refused(&bad, STSP_ERR_BAD_DIMS);
    bad = *P; bad.n_latch = 2u; expect_refused(&bad, STSP_ERR_BAD_DIMS);
    bad = *P; bad.n_stages = 1u; expect_refused(&bad, STSP_ERR_BAD_DIMS);
    bad = *P; bad.n_ticks = N_TICKS - 1u; expect_refused(&bad, STSP_ERR_BAD_DIMS);
    bad = *P; bad.S_k0 = NULL; expect_refused(&bad, STSP_ERR_NULL);
    bad = *P; bad.S_lambda0 = NULL; expect_refused(&bad, STSP_ERR_NULL);
    bad = *P; bad.upper = NULL; expect_refused(&bad, STSP_ERR_NULL);
    bad = *P; bad.crc32 ^= 1u; expect_refused(&bad, STSP_ERR_BAD_CRC);
    /* a corrupted column: the CRC */
    memcpy(s_k0, G(S_k0), sizeof s_k0);
    s_k0[123] = (stsp_scalar_t)(s_k0[123] + 1);
    bad = *P; bad.S_k0 = s_k0; expect_refused(&bad, STSP_ERR_BAD_CRC);
    /* another problem's table: the hash */
    bad = *P; bad.problem_sha256[0] ^= 1u;
    expect_refused_with_crc(bad, STSP_ERR_BAD_PROBLEM);
    /* values: a nominal outside its range, a NaN bound, an infinite nominal */
    memcpy(values, G(param_nominal), sizeof values);
    values[1] = 6.0f;
    bad = *P; bad.nominal = values; expect_refused_with_crc(bad, STSP_ERR_BAD_VALUES);
    values[1] = (stsp_param_value_t)NAN;
    bad = *P; bad.lower = values; expect_refused_with_crc(bad, STSP_ERR_BAD_VALUES);
    values[1] = (stsp_param_value_t)INFINITY;
    bad = *P; bad.nominal = values; expect_refused_with_crc(bad, STSP_ERR_BAD_VALUES);
#ifdef STSP_ARITH_FIXED_POINT
    {
        static stsp_scalar_t s_lam[N_PARAMS * 2u * 4u];
        static int8_t d_exp[N_PARAMS];
        bad = *P; bad.d_exp = NULL; expect_refused(&bad, STSP_ERR_NULL);
        /* a law row beyond 2^F - 1 with the columns: one column entry at the Q range's end */
        s_k0[123] = (stsp_scalar_t)QMAX;
        bad = *P; bad.S_k0 = s_k0; expect_refused_with_crc(bad, STSP_ERR_BAD_VALUES);
        /* a latch row likewise */
        memcpy(s_lam, G(S_lambda0), sizeof s_lam);
        s_lam[0] = (stsp_scalar_t)(-QMAX);
        bad = *P; bad.S_lambda0 = s_lam; expect_refused_with_crc(bad, STSP_ERR_BAD_VALUES);
        /* exponents: beyond +-STSP_Q_EXP_MAX; too small for the range (d_q beyond the Q
         * range at its ends) */
        memcpy(d_exp, G(param_d_exp), sizeof d_exp);
        d_exp[0] = (int8_t)(STSP_Q_EXP_MAX + 1);
        bad = *P; bad.d_exp = d_exp; expect_refused_with_crc(bad, STSP_ERR_BAD_VALUES);
        d_exp[0] = (int8_t)(G(param_d_exp)[0] - 1);
        bad = *P; bad.d_exp = d_exp; expect_refused_with_crc(bad, STSP_ERR_BAD_VALUES);
    }
#else
    /* a NaN column entry */
    s_k0[123] = NAN;
    bad = *P; bad.S_k0 = s_k0; expect_refused_with_crc(bad, STSP_ERR_BAD_VALUES);
#endif
    assert_int_equal(stsp_params_table_crc32(P), P->crc32);
}

static void test_verify(void **state_)
{
    static stsp_param_value_t nominal[N_PARAMS];
    stsp_param_t pc;
    stsp_params_table_t changing = *P;
    stsp_scalar_t x[NX] = {0}, u[NU];
    (void)state_;
    memcpy(nominal, G(param_nominal), sizeof nominal);
    changing.nominal = nominal;
    assert_int_equal(stsp_param_init(&pc, T, &changing), STSP_OK);
    assert_int_equal(stsp_param_verify(&pc), STSP_OK);
    nominal[0] = -1.25f; /* RAM changed after init */
    assert_int_equal(stsp_param_verify(&pc), STSP_ERR_BAD_CRC);
    assert_int_equal(stsp_param_step(&pc, 0u, x, u), STSP_ERR_NOT_INITIALIZED);
    assert_memory_equal(u, T->u_hold, sizeof u);
    nominal[0] = G(param_nominal)[0];
    assert_int_equal(stsp_param_init(&pc, T, &changing), STSP_OK);
    changing.n_ticks = 10u;
    assert_int_equal(stsp_param_verify(&pc), STSP_ERR_TABLE_CHANGED);
    assert_int_equal(stsp_param_step(&pc, 0u, x, u), STSP_ERR_NOT_INITIALIZED);
#ifdef STSP_ARITH_FIXED_POINT
    changing = *P;
    assert_int_equal(stsp_param_init(&pc, T, &changing), STSP_OK);
    changing.d_exp = NULL;
    assert_int_equal(stsp_param_verify(&pc), STSP_ERR_TABLE_CHANGED);
#endif
}

/* A change inside a stage: the feed-forward moves at once, the multipliers at the next latch;
 * a change before a stage start is the run at the new theta from there on. */
static void test_when_it_takes_effect(void **state_)
{
    static const float b[N_PARAMS] = PAR_THETA_B;
    stsp_param_t late, early;
    stsp_scalar_t x[NX], u[NU], w[NU];
    uint32_t j;
    const uint32_t s1 = T->stage_start[1];
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
        cmocka_unit_test(test_fixed_theta_matches_reference),
        cmocka_unit_test(test_change_at_stage_start_matches_reference),
        cmocka_unit_test(test_change_mid_stage_matches_reference),
        cmocka_unit_test(test_nominal_is_stsp_step),
        cmocka_unit_test(test_limits_clamp),
        cmocka_unit_test(test_bad_theta_keeps_the_old),
        cmocka_unit_test(test_null_and_not_ready),
        cmocka_unit_test(test_bad_tables),
        cmocka_unit_test(test_verify),
        cmocka_unit_test(test_when_it_takes_effect),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
