/* Host timing of stsp_step on the robot table against a naive generic-loop controller
 * (tools/reports/firmware_report.sh runs it; not a test). Built twice by CMakeLists.txt: bench_host
 * (the generic controller) and bench_host_fixed (STSP_FIXED_NX/NU/N_LATCH = 4/2/4); the naive
 * implementation below is the same in both.
 *
 * The states come from the noise-free closed loop of the robot (so every tick sees a
 * realistic x), precomputed once. Each measurement runs the whole plan (reset, then the
 * 6000 ticks in order: two latch ticks, the rest ordinary) and divides by the number of
 * ticks; the report is the median over BENCH_PLANS plans, with the minimum and maximum.
 * Output, one line per implementation:
 *     bench <name> ns_per_tick_median <m> min <a> max <b> ticks <n> checksum <c> */
#define _POSIX_C_SOURCE 199309L
#include <float.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "robot_corridor.h"
#include "stospline/stsp_controller.h"

#define BENCH_PLANS 301
#define NT ROBOT_CORRIDOR_N_TICKS
#define NX ROBOT_CORRIDOR_NX
#define NU ROBOT_CORRIDOR_NU

static float states[NT][NX];

/* The controller as one would first write it: zero u, check every x, find the stage by a
 * linear search from stage 0, latch into the instance, evaluate the law with generic loops
 * over the table's dimensions, check and clamp every output. Same statuses as stsp_step for
 * the in-order run this bench does. */
typedef struct {
    const stsp_table_t *t;
    uint32_t next_tick;
    uint32_t stage;
    int latched;
    float v[STSP_MAX_LATCH];
} naive_ctrl_t;

static int naive_finite(float f)
{
    return isfinite(f) ? 1 : 0;
}

static int naive_step(naive_ctrl_t *c, uint32_t tick, const float *x, float *u)
{
    const stsp_table_t *t = c->t;
    uint32_t i, j, s = 0u;
    memset(u, 0, sizeof(float) * t->nu);
    if (tick >= t->n_ticks) {
        return STSP_ERR_TICK_RANGE;
    }
    for (j = 0u; j < t->nx; ++j) {
        if (!naive_finite(x[j])) {
            return STSP_ERR_NONFINITE_STATE;
        }
    }
    while (s + 1u < t->n_stages && t->stage_start[s + 1u] <= tick) {
        ++s;
    }
    if (!c->latched || (s != c->stage && t->stage_n_latch[s] > 0u)) {
        for (i = 0u; i < t->n_latch; ++i) {
            float acc = 0.0f;
            if (i < t->stage_n_latch[s]) {
                acc = t->lambda0[s * t->n_latch + i];
                for (j = 0u; j < t->nx; ++j) {
                    acc += t->Lambda[(s * t->n_latch + i) * t->nx + j] * x[j];
                }
            }
            c->v[i] = acc;
        }
        c->latched = 1;
    }
    c->stage = s;
    for (i = 0u; i < t->nu; ++i) {
        float acc = t->k0[tick * t->nu + i];
        for (j = 0u; j < t->nx; ++j) {
            acc += t->K[(tick * t->nu + i) * t->nx + j] * x[j];
        }
        for (j = 0u; j < t->n_latch; ++j) {
            acc += t->L[(tick * t->nu + i) * t->n_latch + j] * c->v[j];
        }
        if (!naive_finite(acc)) {
            memset(u, 0, sizeof(float) * t->nu);
            return STSP_ERR_NONFINITE_OUTPUT;
        }
        u[i] = -acc;
        if (u[i] > t->u_max[i]) {
            u[i] = t->u_max[i];
        } else if (u[i] < t->u_min[i]) {
            u[i] = t->u_min[i];
        }
    }
    c->next_tick = tick + 1u;
    return STSP_OK;
}

static double now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e9 + (double)ts.tv_nsec;
}

static int cmp_double(const void *a, const void *b)
{
    const double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static void report(const char *name, double *per_tick, double checksum)
{
    qsort(per_tick, BENCH_PLANS, sizeof per_tick[0], cmp_double);
    printf("bench %s ns_per_tick_median %.2f min %.2f max %.2f ticks %u checksum %.6g\n", name,
           per_tick[BENCH_PLANS / 2], per_tick[0], per_tick[BENCH_PLANS - 1], (unsigned)NT,
           checksum);
}

/* One controller under test: reset to the plan's start, and one tick. */
typedef void (*bench_reset_t)(void *ctrl);
typedef int (*bench_step_t)(void *ctrl, uint32_t tick, const float *x, float *u);

static void reset_stsp(void *ctrl)
{
    (void)stsp_reset((stsp_ctrl_t *)ctrl);
}

static int step_stsp(void *ctrl, uint32_t tick, const float *x, float *u)
{
    return stsp_step((stsp_ctrl_t *)ctrl, tick, x, u);
}

static void reset_naive(void *ctrl)
{
    naive_ctrl_t *c = (naive_ctrl_t *)ctrl;
    const stsp_table_t *t = c->t;
    memset(c, 0, sizeof *c);
    c->t = t;
}

static int step_naive(void *ctrl, uint32_t tick, const float *x, float *u)
{
    return naive_step((naive_ctrl_t *)ctrl, tick, x, u);
}

/* Times BENCH_PLANS whole plans (reset untimed, then the NT recorded states in order):
 * per_tick[plan] in ns. Returns the last plan's sum of commands (the checksum), or NAN when a
 * step does not return STSP_OK. */
static double time_plans(bench_reset_t reset, bench_step_t step, void *ctrl, double *per_tick)
{
    volatile float sink = 0.0f;
    float acc = 0.0f;
    float u[NU];
    uint32_t plan, tick;
    for (plan = 0u; plan < BENCH_PLANS; ++plan) {
        double t0, t1;
        acc = 0.0f;
        reset(ctrl);
        t0 = now_ns();
        for (tick = 0u; tick < NT; ++tick) {
            if (step(ctrl, tick, states[tick], u) != STSP_OK) {
                return NAN;
            }
            acc += u[0] + u[1];
        }
        t1 = now_ns();
        sink = acc;
        per_tick[plan] = (t1 - t0) / (double)NT;
    }
    (void)sink;
    return (double)acc;
}

int main(void)
{
    static double per_tick[BENCH_PLANS];
    double x[NX] = {-5.0, 0.0, 1.0, 0.0};
    const double h = 1.0 / (double)ROBOT_CORRIDOR_TICK_HZ;
    stsp_ctrl_t ctrl;
    naive_ctrl_t naive;
    uint32_t tick;
    float u[NU];

    /* States of the noise-free closed loop (exact ZOH of x'' = u per axis). */
    if (stsp_init(&ctrl, &robot_corridor_table) != STSP_OK) {
        return 1;
    }
    for (tick = 0u; tick < NT; ++tick) {
        int i;
        for (i = 0; i < (int)NX; ++i) {
            states[tick][i] = (float)x[i];
        }
        if (stsp_step(&ctrl, tick, states[tick], u) != STSP_OK) {
            return 1;
        }
        x[0] += h * x[1] + 0.5 * h * h * u[0];
        x[1] += h * u[0];
        x[2] += h * x[3] + 0.5 * h * h * u[1];
        x[3] += h * u[1];
    }

#ifdef STSP_FIXED_NX
    report("stsp_step_fixed_4_2_4", per_tick, time_plans(reset_stsp, step_stsp, &ctrl, per_tick));
#else
    report("stsp_step_generic", per_tick, time_plans(reset_stsp, step_stsp, &ctrl, per_tick));
#endif
    naive.t = &robot_corridor_table;
    report("naive_generic_loops", per_tick,
           time_plans(reset_naive, step_naive, &naive, per_tick));
    return 0;
}
