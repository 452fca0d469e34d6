/* Runtime parameters with spline columns (stsp_params.h, format 2) on the shipped
 * gains/robot_goal_spline* tables (tools/params_tables.py --spline), float32: bit for bit
 * against the float32 specification (params_spline_expected.h, from
 * tests/c/params_spline_reference.py); in Q15/Q31 on gains/robot_goal_<arith>_spline*
 * (tools/params_tables.py --fixed: Q spline gains, fixed-point spline columns) bit for bit
 * against the host's reference (params_qspline_expected.h, from tests/c/params_q_reference.py
 * --spline). For a fixed theta, a change at a stage start and one inside a stage; at the
 * nominal the commands of stsp_step() on the spline table, bit for bit; every bad input's
 * status: a per-tick parameter table with a spline gain table and the reverse, a wrong
 * n_spline_coef, a version beyond 2, NULL columns, a changed coefficient (CRC), a NaN
 * coefficient (float32) or a block's scale outside 1..30 and a row beyond 2^F - 1 (fixed
 * point) (values), a coefficient changed after init (verify; fixed point: a scale changed
 * after init is a defined step), theta out of its range. Built against the generic
 * controller of each arithmetic and under ASan + UBSan. Float32 only: the span cache against
 * none for ticks in any order (the Q spline tick keeps no span cache). */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#if defined(STSP_ARITH_Q15)
#include "robot_goal_q15_params.h"
#include "robot_goal_q15_spline_params.h"
#define G(name) robot_goal_q15_##name
#define GS(name) robot_goal_q15_spline_##name
#define QMAX INT16_MAX
#elif defined(STSP_ARITH_Q31)
#include "robot_goal_q31_params.h"
#include "robot_goal_q31_spline_params.h"
#define G(name) robot_goal_q31_##name
#define GS(name) robot_goal_q31_spline_##name
#define QMAX INT32_MAX
#else
#include "robot_goal_params.h"
#include "robot_goal_spline_params.h"
#define G(name) robot_goal_##name
#define GS(name) robot_goal_spline_##name
#endif
#ifdef STSP_ARITH_FIXED_POINT
#include "params_qspline_expected.h"
#define N_COEF 260u
#else
#include "params_spline_expected.h"
#define N_COEF 224u
#define PAR_THETA_A PSP_THETA_A
#define PAR_THETA_B PSP_THETA_B
#define PAR_MID PSP_MID
#define PAR_HASH_A PSP_HASH_A
#define PAR_HASH_B PSP_HASH_B
#define PAR_HASH_C PSP_HASH_C
#define PAR_N_CHECKED PSP_N_CHECKED
#define par_checked psp_checked
#define par_checked_u psp_checked_u
#endif

#define NX 4u
#define NU 2u
#define N_TICKS 600u
#define N_PARAMS 2u

static const stsp_table_t *const T = &GS(table);
static const stsp_params_table_t *const P = &GS(params);

#define N_CHECKED PAR_N_CHECKED
#define CHECKED_TICKS par_checked
#include "params_run.h"

static void test_runs_match_reference(void **state_)
{
    static const float a[N_PARAMS] = PAR_THETA_A;
    static const float b[N_PARAMS] = PAR_THETA_B;
    uint32_t checked[PAR_N_CHECKED][2];
    uint32_t k;
    (void)state_;
    assert_int_equal(run(a, 0u, NULL, checked), PAR_HASH_A);
    for (k = 0u; k < PAR_N_CHECKED; ++k) {
        assert_int_equal(checked[k][0], (uint32_t)par_checked_u[k][0]);
        assert_int_equal(checked[k][1], (uint32_t)par_checked_u[k][1]);
    }
    assert_int_equal(run(NULL, T->stage_start[1], b, NULL), PAR_HASH_B);
    assert_int_equal(run(a, PAR_MID, b, NULL), PAR_HASH_C);
#ifndef STSP_ARITH_FIXED_POINT
    assert_int_equal(run(NULL, 0u, NULL, NULL), PSP_HASH_NOMINAL);
#endif
}

/* At the nominal the parametric spline law is stsp_step()'s on the spline table, bit for
 * bit (up to a zero's sign), and so is a tick skipped to. */
static void test_nominal_is_stsp_step(void **state_)
{
    stsp_param_t pc;
    stsp_ctrl_t ctrl;
    stsp_scalar_t x[NX], u[NU], w[NU];
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
static stsp_params_table_t copy_of(stsp_scalar_t coef[N_COEF])
{
    stsp_params_table_t p = *P;
    memcpy(coef, P->S_k0, N_COEF * sizeof coef[0]);
    p.S_k0 = coef;
    return p;
}

/* init with the CRC recomputed: `want`, and a refused instance not ready. */
static void expect_with_crc(stsp_params_table_t *p, stsp_status_t want)
{
    stsp_param_t pc;
    p->crc32 = stsp_params_table_crc32(p);
    assert_int_equal(stsp_param_init(&pc, T, p), want);
    if (want != STSP_OK) {
        assert_int_equal(pc.ready, 0u);
    }
}

static void test_bad_tables(void **state_)
{
    static stsp_scalar_t coef[N_COEF];
    stsp_param_t pc;
    stsp_params_table_t p;
    (void)state_;
    assert_int_equal(P->n_spline_coef, N_COEF);
    /* per-tick columns with the spline table, spline columns with the per-tick table */
    assert_int_equal(stsp_param_init(&pc, T, &G(params)), STSP_ERR_BAD_DIMS);
    assert_int_equal(stsp_param_init(&pc, &G(table), P), STSP_ERR_BAD_DIMS);
    p = copy_of(coef);
    p.n_spline_coef = N_COEF - 1u;
    assert_int_equal(stsp_param_init(&pc, T, &p), STSP_ERR_BAD_DIMS);
    p.n_spline_coef = N_COEF + 1u;
    assert_int_equal(stsp_param_init(&pc, T, &p), STSP_ERR_BAD_DIMS);
    p = copy_of(coef);
    p.format_version = 3u;
    assert_int_equal(stsp_param_init(&pc, T, &p), STSP_ERR_BAD_VERSION);
    p = copy_of(coef);
    p.S_k0 = NULL;
    assert_int_equal(stsp_param_init(&pc, T, &p), STSP_ERR_NULL);
    p = copy_of(coef);
    coef[17] = (coef[17] != 0) ? (stsp_scalar_t)0 : (stsp_scalar_t)1;
    assert_int_equal(stsp_param_init(&pc, T, &p), STSP_ERR_BAD_CRC);
    expect_with_crc(&p, STSP_OK);
#ifdef STSP_ARITH_FIXED_POINT
    /* a block's scale (its first word) outside 1..30 */
    p = copy_of(coef);
    coef[0] = 0;
    expect_with_crc(&p, STSP_ERR_BAD_VALUES);
    coef[0] = 31;
    expect_with_crc(&p, STSP_ERR_BAD_VALUES);
    /* a column whose gain takes a row beyond 2^F - 1: its coefficients at the format's top,
     * at the smallest scale */
    p = copy_of(coef);
    coef[0] = 1;
    coef[1] = QMAX;
    coef[2] = QMAX;
    coef[3] = QMAX;
    coef[4] = QMAX;
    expect_with_crc(&p, STSP_ERR_BAD_VALUES);
#else
    coef[17] = NAN;
    expect_with_crc(&p, STSP_ERR_BAD_VALUES);
#endif
}

/* A coefficient changed after init: verify stops the instance, its steps hold. */
static void test_verify(void **state_)
{
    static stsp_scalar_t coef[N_COEF];
    stsp_param_t pc;
    stsp_params_table_t p;
    stsp_scalar_t x[NX], u[NU];
    (void)state_;
    p = copy_of(coef);
    assert_int_equal(stsp_param_init(&pc, T, &p), STSP_OK);
    assert_int_equal(stsp_param_verify(&pc), STSP_OK);
    coef[N_COEF - 1u] = (stsp_scalar_t)(coef[N_COEF - 1u] + 1);
    assert_int_equal(stsp_param_verify(&pc), STSP_ERR_BAD_CRC);
    state(0u, x);
    assert_int_equal(stsp_param_step(&pc, 0u, x, u), STSP_ERR_NOT_INITIALIZED);
    assert_int_equal(word(u[0]), word(T->u_hold[0]));
    p = copy_of(coef);
    assert_int_equal(stsp_param_init(&pc, T, &p), STSP_OK);
    p.n_spline_coef = 1u; /* the header changed */
    assert_int_equal(stsp_param_verify(&pc), STSP_ERR_TABLE_CHANGED);
}

#ifdef STSP_ARITH_FIXED_POINT
/* A block's scale changed after init, before verify notices: the step reads it unchecked,
 * a wrong command but a defined one (no undefined shift: the UBSan build). */
static void test_changed_scale_is_defined(void **state_)
{
    static stsp_scalar_t coef[N_COEF];
    static const float a[N_PARAMS] = PAR_THETA_A;
    stsp_param_t pc;
    stsp_params_table_t p;
    stsp_scalar_t x[NX], u[NU];
    stsp_status_t st;
    (void)state_;
    p = copy_of(coef);
    assert_int_equal(stsp_param_init(&pc, T, &p), STSP_OK);
    assert_int_equal(stsp_set_params(&pc, a), STSP_OK);
    coef[0] = -7;
    state(0u, x);
    st = stsp_param_step(&pc, 0u, x, u);
    assert_true((st == STSP_OK) || (st == STSP_WARN_SATURATED));
}
#endif

/* theta outside its range, NaN: refused, the parameters in use kept. */
static void test_bad_theta(void **state_)
{
    stsp_param_t pc;
    float theta[N_PARAMS];
    (void)state_;
    assert_int_equal(stsp_param_init(&pc, T, P), STSP_OK);
    theta[0] = (float)P->upper[0] + 1.0f;
    theta[1] = (float)P->nominal[1];
    assert_int_equal(stsp_set_params(&pc, theta), STSP_ERR_PARAM_RANGE);
    theta[0] = NAN;
    assert_int_equal(stsp_set_params(&pc, theta), STSP_ERR_PARAM_RANGE);
    assert_true(pc.d[0] == 0);
}

#ifndef STSP_ARITH_FIXED_POINT
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
#endif

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_runs_match_reference),
        cmocka_unit_test(test_nominal_is_stsp_step),
        cmocka_unit_test(test_bad_tables),
        cmocka_unit_test(test_verify),
#ifdef STSP_ARITH_FIXED_POINT
        cmocka_unit_test(test_changed_scale_is_defined),
#endif
        cmocka_unit_test(test_bad_theta),
#ifndef STSP_ARITH_FIXED_POINT
        cmocka_unit_test(test_span_cache_any_order),
#endif
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
