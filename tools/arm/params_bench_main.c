/* Instruction-count bench of runtime parameters (tools/arm/count_params.py, QEMU mps2-an386,
 * Cortex-M4F) on gains/robot_goal* (built with -DBENCH_DRONE: gains/drone_gates*, its six
 * gate coordinates, float32 only): BENCH_REPS times, the same ticks through stsp_step()
 * (bench_plain) and through stsp_param_step() with theta set inside the range (bench_param):
 * ticks 0 .. 20 in order (tick 0 latches stage 0), then a skip to the tick before stage 1,
 * the switch tick (the latch of stage 1) and the one after it. Prints one line per call:
 *     call <index> kind <0 plain|1 param> tick <tick> status <status>
 * Built with -DBENCH_HASH instead: runs A, B and C of tests/c/params_reference.py (the states,
 * thetas and changes of tests/c/test_params.c; the drone's: tests/c/params_drone_expected.h)
 * and prints the hash of each run's commands,
 *     hash <A|B|C> 0x<FNV-1a>
 * for the bit-exact comparison with the float32 specification on the target. Built with
 * STSP_ARITH_Q15 or STSP_ARITH_Q31: the same on gains/robot_goal_<arith>* (the fixed-point
 * parametric controller), states as Q integers, and with -DBENCH_HASH the runs of
 * tests/c/params_q_reference.py against the host's bit-exact reference. Built with
 * PARAMS_SPLINE (float32): the same on gains/robot_goal_spline* (spline columns, format 2),
 * with -DBENCH_HASH the runs of tests/c/params_spline_reference.py; with PARAMS_SPLINE and
 * STSP_ARITH_Q15 or _Q31: gains/robot_goal_<arith>_spline* (fixed-point spline columns), the
 * runs of tests/c/params_q_reference.py --spline. */
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#if defined(BENCH_DRONE)
#include "drone_gates_params.h"
#define G(name) drone_gates_##name
#define NX 6u
#define NU 3u
#define NP 6u
#define N_TICKS 400u
/* the bench's theta: each gate moved inside its +-0.5 m; the start: rest at (0, 0, 1) */
#define BENCH_THETA {0.3f, 2.2f, 1.2f, 2.9f, -0.2f, 1.4f}
#define BENCH_X {0.0f, 0.0f, 0.0f, 0.0f, 1.0f, 0.0f}
#elif defined(STSP_ARITH_Q15) && defined(PARAMS_SPLINE)
#include "robot_goal_q15_spline_params.h"
#define G(name) robot_goal_q15_spline_##name
#elif defined(STSP_ARITH_Q31) && defined(PARAMS_SPLINE)
#include "robot_goal_q31_spline_params.h"
#define G(name) robot_goal_q31_spline_##name
#elif defined(STSP_ARITH_Q15)
#include "robot_goal_q15_params.h"
#define G(name) robot_goal_q15_##name
#elif defined(STSP_ARITH_Q31)
#include "robot_goal_q31_params.h"
#define G(name) robot_goal_q31_##name
#elif defined(PARAMS_SPLINE)
#include "robot_goal_spline_params.h"
#define G(name) robot_goal_spline_##name
#else
#include "robot_goal_params.h"
#define G(name) robot_goal_##name
#endif
#ifndef BENCH_DRONE
#define NX 4u
#define NU 2u
#define NP 2u
#define N_TICKS 600u
#define BENCH_THETA {-0.7f, 5.3f}
#define BENCH_X {-1.0f, 5.0f, 0.0f, 0.0f}
#endif
#ifdef BENCH_HASH
#if defined(BENCH_DRONE)
#include "params_drone_expected.h"
#elif defined(STSP_ARITH_FIXED_POINT) && defined(PARAMS_SPLINE)
#include "params_qspline_expected.h"
#elif defined(STSP_ARITH_FIXED_POINT)
#include "params_q_expected.h"
#elif defined(PARAMS_SPLINE)
#include "params_spline_expected.h"
#define PAR_THETA_A PSP_THETA_A
#define PAR_THETA_B PSP_THETA_B
#define PAR_MID PSP_MID
#else
#include "params_expected.h"
#endif
#endif

#define BENCH_REPS 4u
#define BENCH_TICKS 21u
#define BENCH_CALLS (2u * BENCH_REPS * (BENCH_TICKS + 3u))

#ifdef BENCH_HASH
static uint32_t fnv1a(uint32_t h, stsp_scalar_t v)
{
    uint32_t w, i;
#ifdef STSP_ARITH_FIXED_POINT
    w = (uint32_t)(int32_t)v; /* as tests/c/params_q_reference.py */
#else
    v = v + 0.0f; /* a zero as +0, as the specification's hash */
    memcpy(&w, &v, sizeof w);
#endif
    for (i = 0u; i < 4u; ++i) {
        h = (h ^ ((w >> (8u * i)) & 0xFFu)) * 0x01000193u;
    }
    return h;
}

/* One run as tests/c/test_params.c's run(): theta0 before tick 0, theta1 before tick `at`. */
static uint32_t run(const float *theta0, uint32_t at, const float *theta1)
{
    static stsp_param_t pc;
    stsp_scalar_t x[NX], u[NU];
    uint32_t h = 0x811C9DC5u, j, c;
    if (stsp_param_init(&pc, &G(table), &G(params)) != STSP_OK) {
        return 0u;
    }
    if ((theta0 != NULL) && (stsp_set_params(&pc, theta0) != STSP_OK)) {
        return 0u;
    }
    for (j = 0u; j < N_TICKS; ++j) {
        if ((theta1 != NULL) && (j == at) && (stsp_set_params(&pc, theta1) != STSP_OK)) {
            return 0u;
        }
        for (c = 0u; c < NX; ++c) {
#ifdef STSP_ARITH_FIXED_POINT
            const int32_t step = (int32_t)(((int64_t)1 << STSP_Q_FRAC_BITS) / 20 - 1);
            x[c] = (stsp_scalar_t)(((int32_t)((7u * j + 13u * c) % 41u) - 20) * step);
#else
            x[c] = (float)((7u * j + 13u * c) % 41u) * 0.05f - 1.0f;
#endif
        }
        if (stsp_param_step(&pc, j, x, u) < 0) {
            return 0u;
        }
        for (c = 0u; c < NU; ++c) {
            h = fnv1a(h, u[c]);
        }
    }
    return h;
}

int main(void)
{
    static const float a[NP] = PAR_THETA_A;
    static const float b[NP] = PAR_THETA_B;
    printf("hash A 0x%08X\n", (unsigned)run(a, 0u, NULL));
    printf("hash B 0x%08X\n", (unsigned)run(NULL, G(table).stage_start[1], b));
    printf("hash C 0x%08X\n", (unsigned)run(a, PAR_MID, b));
    return 0;
}
#else
typedef struct {
    uint32_t tick;
    int16_t status;
    uint8_t kind;
} bench_call_t;

static bench_call_t calls[BENCH_CALLS];
static uint32_t n_calls;

static void record(uint32_t tick, stsp_status_t st, uint8_t kind)
{
    if (n_calls < BENCH_CALLS) {
        bench_call_t *rec = &calls[n_calls++];
        rec->tick = tick;
        rec->status = (int16_t)st;
        rec->kind = kind;
    }
}

__attribute__((noinline, noclone)) static void bench_plain(stsp_ctrl_t *c, uint32_t tick,
                                                           const stsp_scalar_t *x)
{
    stsp_scalar_t u[NU];
    record(tick, stsp_step(c, tick, x, u), 0u);
}

__attribute__((noinline, noclone)) static void bench_param(stsp_param_t *p, uint32_t tick,
                                                           const stsp_scalar_t *x)
{
    stsp_scalar_t u[NU];
    record(tick, stsp_param_step(p, tick, x, u), 1u);
}

int main(void)
{
    static stsp_ctrl_t ctrl;
    static stsp_param_t pc;
    static const stsp_f32_t theta[NP] = BENCH_THETA;
    const uint32_t sw = G(table).stage_start[1];
#ifdef STSP_ARITH_FIXED_POINT
    /* x = (-1, 5, 0, 0) in the states' Q scales (x_exp 3, 3, 4, 3) */
    stsp_scalar_t x[NX] = {(stsp_scalar_t)-(1L << (STSP_Q_FRAC_BITS - 3)),
                           (stsp_scalar_t)(5L << (STSP_Q_FRAC_BITS - 3)), 0, 0};
#else
    stsp_f32_t x[NX] = BENCH_X;
    const stsp_f32_t x0 = x[0];
#endif
    uint32_t rep, k;
    if ((stsp_init(&ctrl, &G(table)) != STSP_OK) ||
        (stsp_param_init(&pc, &G(table), &G(params)) != STSP_OK) ||
        (stsp_set_params(&pc, theta) != STSP_OK)) {
        printf("bench: init failed\n");
        return 1;
    }
    for (rep = 0u; rep < BENCH_REPS; ++rep) {
        (void)stsp_reset(&ctrl);
        (void)stsp_param_reset(&pc);
#ifdef STSP_ARITH_FIXED_POINT
        x[0] = (stsp_scalar_t)(x[0] + (stsp_scalar_t)(1L << (STSP_Q_FRAC_BITS - 10)));
#else
        x[0] = x0 + 0.01f * (float)rep;
#endif
        for (k = 0u; k < BENCH_TICKS; ++k) {
            bench_plain(&ctrl, k, x);
            bench_param(&pc, k, x);
        }
        for (k = sw - 1u; k <= sw + 1u; ++k) {
            bench_plain(&ctrl, k, x);
            bench_param(&pc, k, x);
        }
    }
    for (k = 0u; k < n_calls; ++k) {
        printf("call %u kind %u tick %u status %d\n", (unsigned)k, (unsigned)calls[k].kind,
               (unsigned)calls[k].tick, (int)calls[k].status);
    }
    return 0;
}
#endif
