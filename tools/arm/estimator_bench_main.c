/* Instruction-count bench of the estimator controller (tools/arm/count_estimator.py, QEMU
 * mps2-an386, Cortex-M4F) on gains/robot_position_sensor.*: BENCH_REPS times, reset, then
 * ticks 0 .. 2 EVERY + 1 in order (tick 0: reading and latch of stage 0; EVERY, 2 EVERY:
 * readings; the others predict only), then, by a skip to the tick before stage 1 (the skip's
 * prediction over the missed ticks is its own line), the switch tick (reading and latch of
 * stage 1) and the one after it. Prints one line per stsp_est_step call, in call order:
 *     call <index> tick <tick> status <status> reading <0|1> sizeof <sizeof(stsp_est_t)> */
#include <stdint.h>
#include <stdio.h>

#include "robot_position_sensor.h"

#define BENCH_REPS 4u
#define EVERY ROBOT_POSITION_SENSOR_EVERY
#define BENCH_CALLS (BENCH_REPS * (2u * EVERY + 5u))

typedef struct {
    uint32_t tick;
    int16_t status;
    uint8_t reading;
} bench_call_t;

static bench_call_t calls[BENCH_CALLS];
static uint32_t n_calls;

__attribute__((noinline, noclone)) static void bench_step(stsp_est_t *e, uint32_t tick,
                                                          const stsp_f32_t *y)
{
    stsp_f32_t u[ROBOT_POSITION_SENSOR_NU];
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
    const uint32_t sw = robot_position_sensor_table.stage_start[1];
    stsp_f32_t y[2] = {-5.0f, 1.0f};
    uint32_t rep, k;
    const stsp_status_t st = stsp_est_init(&est, &robot_position_sensor_table,
                                           &robot_position_sensor_estimator);
    if (st != STSP_OK) {
        printf("bench: stsp_est_init returned %d\n", (int)st);
        return 1;
    }
    for (rep = 0u; rep < BENCH_REPS; ++rep) {
        (void)stsp_est_reset(&est);
        y[0] = -5.0f + 0.01f * (float)rep;
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
