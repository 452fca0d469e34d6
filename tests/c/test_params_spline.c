/* Runtime parameters with spline columns (stsp_params.h, format 2) on the shipped
 * gains/robot_goal_spline* tables (tools/params_tables.py --spline), float32: bit for bit
 * against the float32 specification (params_spline_expected.h, from
 * tests/c/params_spline_reference.py) for a fixed theta, a change at a stage start and one
 * inside a stage; at the nominal the commands of stsp_step() on the spline table, bit for bit;
 * every bad input's status: a per-tick parameter table with a spline gain table and the
 * reverse, a wrong n_spline_coef, a version beyond 2, NULL columns, a changed coefficient
 * (CRC), a NaN coefficient (values), a coefficient changed after init (verify), theta out of
 * its range; the span cache against none for ticks in any order. Built against the generic
 * controller and under ASan + UBSan. */
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

/* The span cache (ctrl.span) for any order of ticks: instance a keeps it, instance b has
 * it cleared before every step (the span searched from the stage's first, as without a
 * cache); the same status and command bits at every step of a fixed pseudo-random sequence of
 * the next tick, a repeated one, skips within a span and across spans and stages, ticks
 * before the last (refused), parameter changes inside a span, resets followed by a jump back
 * to any tick, and a reset to the same span after a parameter change. */
static void test_span_cache_any_order(void **state_)
{
    stsp_param_t a;
    stsp_param_t b;
    float x[NX], ua[NU], ub[NU];
    uint32_t r = 12345u;
    uint32_t next = 0u;
    uint32_t k;
    uint32_t hits = 0u;
    (void)state_;
    assert_int_equal(stsp_param_init(&a, T, P), STSP_OK);
    assert_int_equal(stsp_param_init(&b, T, P), STSP_OK);
    for (k = 0u; k < 3000u; ++k) {
        uint32_t op;
        uint32_t j = next;
        stsp_status_t sa;
        stsp_status_t sb;
        r = (r * 1103515245u) + 12345u;
        op = (r >> 16) % 100u;
        if ((op < 6u) && (next > 0u)) {
            j = next - 1u;                                   /* repeated */
        } else if (op < 14u) {
            j = next + 1u + ((r >> 8) % 40u);                /* skipped */
        } else if ((op < 18u) && (next > 2u)) {
            j = (r >> 4) % (next - 1u);                      /* before the last: refused */
        } else if (op < 23u) {
            float theta[N_PARAMS];
            uint32_t q;
            for (q = 0u; q < N_PARAMS; ++q) {
                const float w = (float)((r >> (4u + 5u * q)) % 17u) / 16.0f;
                theta[q] = P->lower[q] + (w * (P->upper[q] - P->lower[q]));
                if (theta[q] > P->upper[q]) {
                    theta[q] = P->upper[q];
                }
            }
            assert_int_equal(stsp_set_params(&a, theta), STSP_OK);
            assert_int_equal(stsp_set_params(&b, theta), STSP_OK);
        } else if (op < 27u) {
            assert_int_equal(stsp_param_reset(&a), STSP_OK);
            assert_int_equal(stsp_param_reset(&b), STSP_OK);
            j = (r >> 4) % N_TICKS;                          /* back (or on) to any tick */
        } else {
            /* the next tick */
        }
        if (j >= N_TICKS) {
            assert_int_equal(stsp_param_reset(&a), STSP_OK);
            assert_int_equal(stsp_param_reset(&b), STSP_OK);
            j = 0u;
        }
        state(j, x);
        b.ctrl.span.next = 0u;
        sa = stsp_param_step(&a, j, x, ua);
        sb = stsp_param_step(&b, j, x, ub);
        assert_int_equal(sa, sb);
        assert_int_equal(word(ua[0]), word(ub[0]));
        assert_int_equal(word(ua[1]), word(ub[1]));
        if (sa >= STSP_OK) {
            ++hits;
            next = a.ctrl.next_tick;
        }
    }
    assert_true(hits > 2000u);
    /* A record of a later span than the tick (as after a reset that kept it, or a table
     * whose instance was copied): searched again from the stage's first span. */
    assert_int_equal(stsp_param_reset(&a), STSP_OK);
    assert_int_equal(stsp_param_reset(&b), STSP_OK);
    for (k = 0u; k < 200u; ++k) {
        state(k, x);
        assert_true(stsp_param_step(&a, k, x, ua) >= STSP_OK);
    }
    {
        const stsp_span_t later = a.ctrl.span;
        assert_int_equal(stsp_param_reset(&a), STSP_OK);
        for (k = 0u; k < 30u; ++k) {
            state(k, x);
            assert_true(stsp_param_step(&a, k, x, ua) >= STSP_OK);
            assert_true(stsp_param_step(&b, k, x, ub) >= STSP_OK);
            if (k == 20u) {
                a.ctrl.span = later;
            }
        }
        for (; k < 60u; ++k) {
            state(k, x);
            assert_true(stsp_param_step(&a, k, x, ua) >= STSP_OK);
            b.ctrl.span.next = 0u;
            assert_true(stsp_param_step(&b, k, x, ub) >= STSP_OK);
            assert_int_equal(word(ua[0]), word(ub[0]));
            assert_int_equal(word(ua[1]), word(ub[1]));
        }
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_runs_match_reference),
        cmocka_unit_test(test_nominal_is_stsp_step),
        cmocka_unit_test(test_bad_tables),
        cmocka_unit_test(test_verify),
        cmocka_unit_test(test_bad_theta),
        cmocka_unit_test(test_span_cache_any_order),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
