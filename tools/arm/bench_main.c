/* Instruction-count bench for tools/arm/count_instructions.sh (QEMU mps2-an386, Cortex-M4F).
 *
 * Repeats BENCH_REPS times: reset, then tick 0 (latch of stage 0), ticks 1..BENCH_RUN-1,
 * the stage-0 tick just before the switch (reached by a skip: STSP_WARN_TICK_SKIPPED), the
 * switch tick (latch of stage 1), and BENCH_RUN-1 more stage-1 ticks. The x values do not
 * change the executed path (the law has no data-dependent branches for finite x). After the
 * loop it prints one line per stsp_step call, in call order, which the script pairs with the
 * calls it finds in QEMU's execution trace, and the table's dimensions:
 *     call <index> tick <tick> stage <stage> latch <0|1> status <status>
 *     table nx <nx> nu <nu> n_latch <n_latch> stage_np <np0> <np1> ... */
#include <stdint.h>
#include <stdio.h>

#include "robot_corridor.h"
#include "stospline/stsp_controller.h"

#define BENCH_REPS 10u
#define BENCH_RUN 10u
#define BENCH_CALLS (BENCH_REPS * 2u * (BENCH_RUN + 1u))

typedef struct {
    uint32_t tick;
    int16_t status;
    uint8_t stage;
    uint8_t latch;
} bench_call_t;

static bench_call_t calls[BENCH_CALLS];
static uint32_t n_calls;

static void bench_step(stsp_ctrl_t *c, uint32_t tick, const stsp_f32_t *x)
{
    stsp_f32_t u[ROBOT_CORRIDOR_NU];
    uint16_t stage_before = c->stage, latched_before = c->latched;
    stsp_status_t st = stsp_step(c, tick, x, u);
    if (n_calls < BENCH_CALLS) {
        bench_call_t *rec = &calls[n_calls++];
        rec->tick = tick;
        rec->status = (int16_t)st;
        rec->stage = (uint8_t)c->stage;
        rec->latch = (uint8_t)((latched_before == 0u ||
                                (c->stage != stage_before && c->table->stage_np[c->stage] > 0u))
                                   ? 1u
                                   : 0u);
    }
}

int main(void)
{
    static const stsp_f32_t x0[ROBOT_CORRIDOR_NX] = {-5.0f, 0.0f, 1.0f, 0.0f};
    stsp_f32_t x[ROBOT_CORRIDOR_NX];
    stsp_ctrl_t ctrl;
    const uint32_t sw = robot_corridor_table.stage_start[1]; /* first tick of stage 1 */
    uint32_t rep, k, i;
    stsp_status_t st = stsp_init(&ctrl, &robot_corridor_table);
    if (st != STSP_OK) {
        printf("bench: stsp_init returned %d\n", (int)st);
        return 1;
    }
    for (rep = 0u; rep < BENCH_REPS; ++rep) {
        (void)stsp_reset(&ctrl);
        for (i = 0u; i < ROBOT_CORRIDOR_NX; ++i) {
            x[i] = x0[i] + 0.01f * (stsp_f32_t)rep;
        }
        for (k = 0u; k < BENCH_RUN; ++k) {
            bench_step(&ctrl, k, x);
        }
        for (k = 0u; k < BENCH_RUN + 2u; ++k) {
            bench_step(&ctrl, sw - 1u + k, x);
        }
    }
    for (i = 0u; i < n_calls; ++i) {
        printf("call %lu tick %lu stage %u latch %u status %d\n", (unsigned long)i,
               (unsigned long)calls[i].tick, (unsigned)calls[i].stage, (unsigned)calls[i].latch,
               (int)calls[i].status);
    }
    printf("bench: %lu calls, sizeof(stsp_ctrl_t) %lu\n", (unsigned long)n_calls,
           (unsigned long)sizeof(stsp_ctrl_t));
    printf("table nx %u nu %u n_latch %u stage_np", (unsigned)robot_corridor_table.nx,
           (unsigned)robot_corridor_table.nu, (unsigned)robot_corridor_table.n_latch);
    for (i = 0u; i < robot_corridor_table.n_stages; ++i) {
        printf(" %u", (unsigned)robot_corridor_table.stage_np[i]);
    }
    printf("\n");
    return 0;
}
