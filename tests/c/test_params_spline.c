/* Runtime parameters with spline columns (stsp_params.h, format 2) on the shipped
 * gains/robot_goal_spline* tables (tools/params_tables.py --spline), float32: bit for bit
 * against the float32 specification (params_spline_expected.h, from
 * tests/c/params_spline_reference.py) for a fixed theta, a change at a stage start and one
 * inside a stage; at the nominal the commands of stsp_step() on the spline table, bit for bit;
 * every bad input's status: a per-tick parameter table with a spline gain table and the
 * reverse, a wrong n_spline_coef, a version beyond 2, NULL columns, a changed coefficient
 * (CRC), a NaN coefficient (values), a coefficient changed after init (verify), theta out of
 * its range. Built against the generic controller and under ASan + UBSan. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "robot_goal_params.h"
#include "robot_goal_spline_params.h"
#include "params_spline_expected.h"

#define NX 4u
#define NU 2u
#define N_TICKS 600u
#define N_PARAMS 2u
#define N_COEF 224u

static const stsp_table_t *const T = &robot_goal_spline_table;
static const stsp_params_table_t *const P = &robot_goal_spline_params;

#define N_CHECKED PSP_N_CHECKED
#define CHECKED_TICKS psp_checked
#include "params_run.h"

static void test_runs_match_reference(void **state_)
{
    static const float a[N_PARAMS] = PSP_THETA_A;
    static const float b[N_PARAMS] = PSP_THETA_B;
    uint32_t checked[PSP_N_CHECKED][2];
    uint32_t k;
    (void)state_;
    assert_int_equal(run(a, 0u, NULL, checked), PSP_HASH_A);
    for (k = 0u; k < PSP_N_CHECKED; ++k) {
        assert_int_equal(checked[k][0], psp_checked_u[k][0]);
        assert_int_equal(checked[k][1], psp_checked_u[k][1]);
    }
    assert_int_equal(run(NULL, T->stage_start[1], b, NULL), PSP_HASH_B);
    assert_int_equal(run(a, PSP_MID, b, NULL), PSP_HASH_C);
    assert_int_equal(run(NULL, 0u, NULL, NULL), PSP_HASH_NOMINAL);
}

/* At the nominal the parametric spline law is stsp_step()'s on the spline table, bit for
 * bit (up to a zero's sign), and so is a tick skipped to. */
static void test_nominal_is_stsp_step(void **state_)
{
    stsp_param_t pc;
    stsp_ctrl_t ctrl;
    float x[NX], u[NU], w[NU];
    uint32_t j;
    (void)state_;
    assert_int_equal(stsp_param_init(&pc, T, P), STSP_OK);
    assert_int_equal(stsp_init(&ctrl, T), STSP_OK);
    for (j = 0u; j < N_TICKS; j += (j < 290u) ? 1u : 7u) {
        state(j, x);
        assert_int_equal(stsp_param_step(&pc, j, x, u), stsp_step(&ctrl, j, x, w));
        assert_int_equal(word(u[0]), word(w[0]));
        assert_int_equal(word(u[1]), word(w[1]));
    }
}

/* A parameter table in RAM: the shipped one with its columns copied into coef. */
static stsp_params_table_t copy_of(float coef[N_COEF])
{
    stsp_params_table_t p = *P;
    memcpy(coef, P->S_k0, N_COEF * sizeof coef[0]);
    p.S_k0 = coef;
    return p;
}

static void test_bad_tables(void **state_)
{
    static float coef[N_COEF];
    stsp_param_t pc;
    stsp_params_table_t p;
    (void)state_;
    assert_int_equal(P->n_spline_coef, N_COEF);
    /* per-tick columns with the spline table, spline columns with the per-tick table */
    assert_int_equal(stsp_param_init(&pc, T, &robot_goal_params), STSP_ERR_BAD_DIMS);
    assert_int_equal(stsp_param_init(&pc, &robot_goal_table, P), STSP_ERR_BAD_DIMS);
    p = copy_of(coef);
    p.n_spline_coef = N_COEF - 1u;
    assert_int_equal(stsp_param_init(&pc, T, &p), STSP_ERR_BAD_DIMS);
    p = copy_of(coef);
    p.format_version = 3u;
    assert_int_equal(stsp_param_init(&pc, T, &p), STSP_ERR_BAD_VERSION);
    p = copy_of(coef);
    p.S_k0 = NULL;
    assert_int_equal(stsp_param_init(&pc, T, &p), STSP_ERR_NULL);
    p = copy_of(coef);
    coef[17] = coef[17] * 1.5f + 1.0f;
    assert_int_equal(stsp_param_init(&pc, T, &p), STSP_ERR_BAD_CRC);
    p.crc32 = stsp_params_table_crc32(&p);
    assert_int_equal(stsp_param_init(&pc, T, &p), STSP_OK);
    coef[17] = NAN;
    p.crc32 = stsp_params_table_crc32(&p);
    assert_int_equal(stsp_param_init(&pc, T, &p), STSP_ERR_BAD_VALUES);
    assert_int_equal(pc.ready, 0u);
}

/* A coefficient changed after init: verify stops the instance, its steps hold. */
static void test_verify(void **state_)
{
    static float coef[N_COEF];
    stsp_param_t pc;
    stsp_params_table_t p;
    float x[NX], u[NU];
    (void)state_;
    p = copy_of(coef);
    assert_int_equal(stsp_param_init(&pc, T, &p), STSP_OK);
    assert_int_equal(stsp_param_verify(&pc), STSP_OK);
    coef[N_COEF - 1u] += 1.0f;
    assert_int_equal(stsp_param_verify(&pc), STSP_ERR_BAD_CRC);
    state(0u, x);
    assert_int_equal(stsp_param_step(&pc, 0u, x, u), STSP_ERR_NOT_INITIALIZED);
    assert_int_equal(word(u[0]), word(T->u_hold[0]));
    p = copy_of(coef);
    assert_int_equal(stsp_param_init(&pc, T, &p), STSP_OK);
    p.n_spline_coef = 1u; /* the header changed */
    assert_int_equal(stsp_param_verify(&pc), STSP_ERR_TABLE_CHANGED);
}

/* theta outside its range, NaN: refused, the parameters in use kept. */
static void test_bad_theta(void **state_)
{
    stsp_param_t pc;
    float theta[N_PARAMS];
    (void)state_;
    assert_int_equal(stsp_param_init(&pc, T, P), STSP_OK);
    theta[0] = P->upper[0] + 1.0f;
    theta[1] = P->nominal[1];
    assert_int_equal(stsp_set_params(&pc, theta), STSP_ERR_PARAM_RANGE);
    theta[0] = NAN;
    assert_int_equal(stsp_set_params(&pc, theta), STSP_ERR_PARAM_RANGE);
    assert_true(pc.d[0] == 0.0f);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_runs_match_reference),
        cmocka_unit_test(test_nominal_is_stsp_step),
        cmocka_unit_test(test_bad_tables),
        cmocka_unit_test(test_verify),
        cmocka_unit_test(test_bad_theta),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
