/* Instruction-count bench of the estimator controller (tools/arm/count_estimator.py, QEMU
 * mps2-an386, Cortex-M4F) on gains/robot_position_sensor.* (float32) or, built with
 * STSP_ARITH_Q15 (STSP_ARITH_Q31), gains/robot_position_sensor_q15.* (_q31.*): BENCH_REPS
 * times, reset, then
 * ticks 0 .. 2 EVERY + 1 in order (tick 0: reading and latch of stage 0; EVERY, 2 EVERY:
 * readings; the others predict only), then, by a skip to the tick before stage 1 (the skip's
 * prediction over the missed ticks is its own line), the switch tick (reading and latch of
 * stage 1) and the one after it. Prints one line per stsp_est_step call, in call order:
 *     call <index> tick <tick> status <status> reading <0|1> sizeof <sizeof(stsp_est_t)>
 * With BENCH_HASH (Q15 or Q31) instead: the whole plan with the readings of
 * tests/c/estimator_q_expected.h (Q31: estimator_q31_expected.h; the one of EST_MISSING
 * withheld), printing
 *     hash 0x<FNV-1a over every tick's u_q and prediction x̂_q>
 * which must be that file's EST_HASH (the host's integer reference, bit for bit).
 * Built with STSP_EST_SPLINE: the spline tables (gains/robot_position_sensor_spline.*, the
 * filter's gains from its spline: stsp_est_init_spline()); with BENCH_HASH then the whole plan
 * on two instances, the spline's and a per-tick twin whose gains are the host's evaluation of
 * the spline (tests/c/estimator_spline_expected.h), readings from a fixed LCG, one withheld,
 * printing
 *     replay <ticks> ticks, <n> differing, hash 0x<FNV-1a over every u and prediction x̂>
 * (n must be 0: every command and prediction the same bits on the target). */
#include <stdint.h>
#include <stdio.h>

#include "estimator_tables.h" /* tests/c: the tables of the build's arithmetic */
#if defined(STSP_ARITH_Q15)
#include "estimator_q_expected.h"
#elif defined(STSP_ARITH_Q31)
#include "estimator_q31_expected.h"
#endif
#ifdef STSP_EST_SPLINE
#include <string.h>
#include "estimator_spline_expected.h"
#define BENCH_INIT(e) stsp_est_init_spline((e), &TABLE, &ESTIMATOR, &EST_GAIN_SPLINE)
#else
#define BENCH_INIT(e) stsp_est_init((e), &TABLE, &ESTIMATOR)
#endif

#define BENCH_REPS 4u
#define EVERY SENSOR(EVERY)
#define BENCH_CALLS (BENCH_REPS * (2u * EVERY + 5u))

#ifndef BENCH_HASH
typedef struct {
    uint32_t tick;
    int16_t status;
    uint8_t reading;
} bench_call_t;

static bench_call_t calls[BENCH_CALLS];
static uint32_t n_calls;

__attribute__((noinline, noclone)) static void bench_step(stsp_est_t *e, uint32_t tick,
                                                          const stsp_scalar_t *y)
{
    stsp_scalar_t u[SENSOR(NU)];
    const stsp_status_t st = stsp_est_step(e, tick, y, u);
    if (n_calls < BENCH_CALLS) {
        bench_call_t *rec = &calls[n_calls++];
        rec->tick = tick;
        rec->status = (int16_t)st;
        rec->reading = (uint8_t)(((tick % EVERY) == 0u) ? 1u : 0u);
    }
}

int main(void)
{
    static stsp_est_t est;
    const uint32_t sw = TABLE.stage_start[1];
#if defined(STSP_ARITH_Q15) || defined(STSP_ARITH_Q31)
    stsp_scalar_t y[2] = {est_y[0][0], est_y[0][1]};
#else
    stsp_scalar_t y[2] = {-5.0f, 1.0f};
#endif
    uint32_t rep, k;
    const stsp_status_t st = BENCH_INIT(&est);
    if (st != STSP_OK) {
        printf("bench: stsp_est_init returned %d\n", (int)st);
        return 1;
    }
    for (rep = 0u; rep < BENCH_REPS; ++rep) {
        (void)stsp_est_reset(&est);
#if defined(STSP_ARITH_Q15) || defined(STSP_ARITH_Q31)
        y[0] = (stsp_scalar_t)(est_y[0][0] + (int32_t)rep);
#else
        y[0] = -5.0f + 0.01f * (float)rep;
#endif
        for (k = 0u; k <= 2u * EVERY + 1u; ++k) {
            bench_step(&est, k, y);
        }
        bench_step(&est, sw - 1u, y);
        bench_step(&est, sw, y);
        bench_step(&est, sw + 1u, y);
    }
    for (k = 0u; k < n_calls; ++k) {
        printf("call %u tick %u status %d reading %u sizeof %u\n", (unsigned)k,
               (unsigned)calls[k].tick, (int)calls[k].status, (unsigned)calls[k].reading,
               (unsigned)sizeof(stsp_est_t));
    }
    return 0;
}
#elif defined(STSP_EST_SPLINE)
static uint32_t bits_of(float v)
{
    uint32_t b;
    v = v + 0.0f;
    memcpy(&b, &v, sizeof b);
    return b;
}

int main(void)
{
    static stsp_est_t spline;
    static stsp_est_t twin;
    static float gain[((SENSOR(N_TICKS) + EVERY - 1u) / EVERY) * SENSOR(NX) * SENSOR(NY)];
    stsp_est_table_t per_tick = ESTIMATOR;
    float y[2];
    float u[2];
    float v[2];
    uint32_t h = 0x811C9DC5u;
    uint32_t lcg = 20261129u;
    uint32_t differ = 0u;
    uint32_t j, r;
    memcpy(gain, est_spline_gain_bits, sizeof gain);
    per_tick.gain = gain;
    per_tick.crc32 = stsp_est_table_crc32(&per_tick);
    if ((BENCH_INIT(&spline) != STSP_OK) || (stsp_est_init(&twin, &TABLE, &per_tick) != STSP_OK)) {
        printf("bench: init failed\n");
        return 1;
    }
    for (j = 0u; j < SENSOR(N_TICKS); ++j) {
        const int sampled = ((j % EVERY) == 0u) && (j != 1000u);
        if (sampled) {
            for (r = 0u; r < 2u; ++r) {
                lcg = (lcg * 1664525u) + 1013904223u;
                y[r] = ((float)(lcg >> 8) / 16777216.0f) * 8192.0f - 4096.0f;
            }
        }
        (void)stsp_est_step(&spline, j, sampled ? y : NULL, u);
        (void)stsp_est_step(&twin, j, sampled ? y : NULL, v);
        differ += ((bits_of(u[0]) != bits_of(v[0])) || (bits_of(u[1]) != bits_of(v[1]))) ? 1u : 0u;
        h = est_fnv1a(est_fnv1a(h, bits_of(u[0])), bits_of(u[1]));
        for (r = 0u; r < SENSOR(NX); ++r) {
            differ += (bits_of(spline.xhat[r]) != bits_of(twin.xhat[r])) ? 1u : 0u;
            h = est_fnv1a(h, bits_of(spline.xhat[r]));
        }
    }
    printf("replay %u ticks, %u differing, hash 0x%08X\n", (unsigned)SENSOR(N_TICKS),
           (unsigned)differ, (unsigned)h);
    return 0;
}
#else
int main(void)
{
    static stsp_est_t est;
    stsp_scalar_t y[2];
    stsp_scalar_t u[2];
    uint32_t h = 0x811C9DC5u;
    uint32_t j, r;
    if (stsp_est_init(&est, &TABLE, &ESTIMATOR) != STSP_OK) {
        printf("bench: stsp_est_init failed\n");
        return 1;
    }
    for (j = 0u; j < SENSOR(N_TICKS); ++j) {
        const int sampled = (j % EVERY) == 0u;
        if (sampled) {
            y[0] = est_y[j / EVERY][0];
            y[1] = est_y[j / EVERY][1];
        }
        (void)stsp_est_step(&est, j, (sampled && (j != EST_MISSING)) ? y : NULL, u);
        h = est_fnv1a(est_fnv1a(h, (uint32_t)u[0]), (uint32_t)u[1]);
        for (r = 0u; r < SENSOR(NX); ++r) {
            h = est_fnv1a(h, (uint32_t)est.xhat[r]);
        }
    }
    printf("hash 0x%08X\n", (unsigned)h);
    return 0;
}
#endif
