/* Every tick of one table's plan, for tools/arm/board_timing.py (QEMU mps2-an386, Cortex-M4F).
 *
 * Compiled once per table with -include <name>.h and
 *   -DPLAN_TABLE=<name>_table -DPLAN_NX=<NAME>_NX -DPLAN_NU=<NAME>_NU -DPLAN_TICKS=<NAME>_N_TICKS
 * it steps ticks 0 .. PLAN_TICKS-1 in order, once each, from one fixed state (every entry 0.5:
 * the per-tick and spline laws take the same path for any finite state; only the clamping and
 * a band table's stage-0 latch depend on it), and prints one line per call in the format of
 * tools/arm/bench_main.c, which count_instructions.py's trace_calls() pairs with QEMU's trace:
 *     call <index> table 0 tick <tick> stage <stage> latch <0|1> status <status> span 0
 *     table nx <nx> nu <nu> n_latch <n_latch> stage_n_latch <np0> <np1> ... */
#include <stdint.h>
#include <stdio.h>

#include "stospline/stsp_controller.h"

#include "bench_table_line.h"

typedef struct {
    int16_t status;
    uint8_t stage;
    uint8_t latch;
} plan_call_t;

static plan_call_t calls[PLAN_TICKS];

/* Not inlined: the trace ends a call at the first instruction back in here. */
__attribute__((noinline)) void bench_step(stsp_ctrl_t *c, uint32_t tick, const stsp_scalar_t *x);

void bench_step(stsp_ctrl_t *c, uint32_t tick, const stsp_scalar_t *x)
{
    stsp_scalar_t u[PLAN_NU];
    const uint16_t stage_before = c->stage;
    const uint16_t latched_before = c->latched;
    const stsp_status_t st = stsp_step(c, tick, x, u);
    const int new_stage_latches =
        (c->stage != stage_before) && (c->table->stage_n_latch[c->stage] > 0u);
    calls[tick].status = (int16_t)st;
    calls[tick].stage = (uint8_t)c->stage;
    calls[tick].latch = (uint8_t)(((latched_before == 0u) || new_stage_latches) ? 1u : 0u);
}

int main(void)
{
    static stsp_ctrl_t ctrl;
    stsp_scalar_t x[PLAN_NX];
    uint32_t i;
    stsp_status_t st = stsp_init(&ctrl, &PLAN_TABLE);
    if (st != STSP_OK) {
        printf("plan: stsp_init returned %d\n", (int)st);
        return 1;
    }
    for (i = 0u; i < PLAN_NX; ++i) {
#ifdef STSP_Q_FRAC_BITS
        x[i] = (stsp_scalar_t)(1L << (STSP_Q_FRAC_BITS - 1)); /* half the Q range */
#else
        x[i] = 0.5f;
#endif
    }
    for (i = 0u; i < PLAN_TICKS; ++i) {
        bench_step(&ctrl, i, x);
    }
    for (i = 0u; i < PLAN_TICKS; ++i) {
        printf("call %lu table 0 tick %lu stage %u latch %u status %d span 0\n", (unsigned long)i,
               (unsigned long)i, (unsigned)calls[i].stage, (unsigned)calls[i].latch,
               (int)calls[i].status);
    }
    bench_print_table_line(&PLAN_TABLE);
    return 0;
}
