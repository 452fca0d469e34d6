/* Instruction-count bench for tools/arm/count_instructions.sh (QEMU mps2-an386, Cortex-M4F).
 *
 * For each of three tables, repeats BENCH_REPS times: reset, then tick 0 (latch of stage 0),
 * ticks 1..BENCH_RUN-1, the stage-0 tick just before the switch (reached by a skip:
 * STSP_WARN_TICK_SKIPPED), the switch tick (latch of stage 1), and BENCH_RUN-1 more stage-1
 * ticks. The tables: 0 = the robot table as generated (no actuator limits: +-FLT_MAX),
 * 1 = a RAM copy with limits +-1000 (never reached: the cost of the limit check alone),
 * 2 = a RAM copy with limits +-0.5 (the commands exceed them: the cost of clamping, status
 * STSP_WARN_SATURATED). Copies 1 and 2 share the flash gain arrays; only the header, the two
 * limit arrays and the CRC (stsp_table_crc32) differ. The x values do not change the executed
 * path (no data-dependent branches for finite x, except the clamping in table 2).
 * Fixed-point builds (STSP_ARITH_Q15/Q31) use the robot's Q tables, the same states converted
 * to Q units, and the limits in command units: +-(2^F - 2) (inactive) and +-0.5 converted.
 * With BENCH_SPLINE (float32 only) the table is tools/arm/spline_bench_table.c, a spline table
 * of the robot's shape (30 spans of 100 ticks per stage, 10 entries), its CRC computed here;
 * each repetition also steps ticks 95..104 after tick 9 (95 by a skip), so that tick 100 starts
 * a new span.
 * After the loop it prints one line per stsp_step call, in call order, which the script
 * pairs with the calls it finds in QEMU's execution trace, and the table's dimensions:
 *     call <index> table <0|1|2> tick <tick> stage <stage> latch <0|1> status <status> span <0|1>
 *     table nx <nx> nu <nu> n_latch <n_latch> stage_n_latch <np0> <np1> ...
 * (span 1: the tick starts a new spline span inside its stage; always 0 for a per-tick table). */
#include <stdint.h>
#include <stdio.h>

#include "stospline/stsp_controller.h"

#include "bench_table_line.h"
#ifdef BENCH_SPLINE
#include "spline_bench_table.h"
#define ROBOT_TABLE spline_bench_table
#define ROBOT_NX SPLINE_BENCH_NX
#define ROBOT_NU SPLINE_BENCH_NU
#define BENCH_SPAN_TICKS SPLINE_BENCH_SPAN_TICKS
#define BENCH_SPAN_RUN 10u
#else
#include "robot_variant.h"
#define BENCH_SPAN_RUN 0u
#endif

#define BENCH_REPS 10u
#define BENCH_RUN 10u
#define BENCH_TABLES 3u
#define BENCH_CALLS (BENCH_TABLES * BENCH_REPS * (2u * (BENCH_RUN + 1u) + BENCH_SPAN_RUN))

typedef struct {
    uint32_t tick;
    int16_t status;
    uint8_t stage;
    uint8_t latch;
    uint8_t table;
    uint8_t span;
} bench_call_t;

static bench_call_t calls[BENCH_CALLS];
static uint32_t n_calls;

static void bench_step(stsp_ctrl_t *c, uint32_t tick, const stsp_scalar_t *x, uint8_t table)
{
    stsp_scalar_t u[ROBOT_NU];
    uint16_t stage_before = c->stage, latched_before = c->latched;
    stsp_status_t st = stsp_step(c, tick, x, u);
    if (n_calls < BENCH_CALLS) {
        bench_call_t *rec = &calls[n_calls++];
        const int new_stage_latches =
            (c->stage != stage_before) && (c->table->stage_n_latch[c->stage] > 0u);
        rec->tick = tick;
        rec->status = (int16_t)st;
        rec->stage = (uint8_t)c->stage;
        rec->table = table;
        rec->latch = (uint8_t)(((latched_before == 0u) || new_stage_latches) ? 1u : 0u);
        rec->span = 0u;
#ifdef BENCH_SPLINE
        {
            const uint32_t in_stage = tick - c->table->stage_start[c->stage];
            rec->span = (uint8_t)(((in_stage > 0u) && ((in_stage % BENCH_SPAN_TICKS) == 0u))
                                      ? 1u
                                      : 0u);
        }
#endif
    }
}

/* State j = milli / 1000 in the build's arithmetic (Q: x_q = x 2^(F - x_exp[j]), integers). */
static stsp_scalar_t bench_state(const stsp_table_t *t, uint32_t j, int32_t milli)
{
#ifdef STSP_ARITH_FIXED_POINT
    return (stsp_scalar_t)(((int64_t)milli * ((int64_t)1 << (STSP_Q_FRAC_BITS - t->x_exp[j]))) /
                           1000);
#else
    (void)t;
    (void)j;
    return (stsp_f32_t)milli / 1000.0f;
#endif
}

static int bench_table(const stsp_table_t *table, uint8_t label)
{
    static const int32_t x0_milli[ROBOT_NX] = {-5000, 0, 1000, 0};
    stsp_scalar_t x[ROBOT_NX];
    stsp_ctrl_t ctrl;
    const uint32_t sw = table->stage_start[1]; /* first tick of stage 1 */
    uint32_t rep, k, i;
    stsp_status_t st = stsp_init(&ctrl, table);
    if (st != STSP_OK) {
        printf("bench: stsp_init of table %u returned %d\n", (unsigned)label, (int)st);
        return 1;
    }
    for (rep = 0u; rep < BENCH_REPS; ++rep) {
        (void)stsp_reset(&ctrl);
        for (i = 0u; i < ROBOT_NX; ++i) {
            x[i] = bench_state(table, i, x0_milli[i] + 10 * (int32_t)rep);
        }
        for (k = 0u; k < BENCH_RUN; ++k) {
            bench_step(&ctrl, k, x, label);
        }
#ifdef BENCH_SPLINE
        for (k = 0u; k < BENCH_SPAN_RUN; ++k) {
            bench_step(&ctrl, BENCH_SPAN_TICKS - (BENCH_SPAN_RUN / 2u) + k, x, label);
        }
#endif
        for (k = 0u; k < BENCH_RUN + 2u; ++k) {
            bench_step(&ctrl, sw - 1u + k, x, label);
        }
    }
    return 0;
}

int main(void)
{
#ifdef STSP_ARITH_FIXED_POINT
    static stsp_scalar_t wide_lo[ROBOT_NU], wide_hi[ROBOT_NU], tight_lo[ROBOT_NU],
        tight_hi[ROBOT_NU];
#else
    static const stsp_f32_t wide_lo[ROBOT_NU] = {-1000.0f, -1000.0f};
    static const stsp_f32_t wide_hi[ROBOT_NU] = {1000.0f, 1000.0f};
    static const stsp_f32_t tight_lo[ROBOT_NU] = {-0.5f, -0.5f};
    static const stsp_f32_t tight_hi[ROBOT_NU] = {0.5f, 0.5f};
#endif
    stsp_table_t wide = ROBOT_TABLE, tight = ROBOT_TABLE;
#ifdef BENCH_SPLINE
    stsp_table_t plain = ROBOT_TABLE; /* the generated file leaves the CRC to us */
#endif
    uint32_t i;
#ifdef STSP_ARITH_FIXED_POINT
    for (i = 0u; i < ROBOT_NU; ++i) {
        const int64_t one = (int64_t)1 << STSP_Q_FRAC_BITS;
        wide_hi[i] = (stsp_scalar_t)(one - 2);
        wide_lo[i] = (stsp_scalar_t)(2 - one);
        tight_hi[i] = (stsp_scalar_t)(one >> (ROBOT_TABLE.u_exp[i] + 1)); /* 0.5 */
        tight_lo[i] = (stsp_scalar_t)-tight_hi[i];
    }
#endif
    wide.u_min = wide_lo;
    wide.u_max = wide_hi;
    wide.crc32 = stsp_table_crc32(&wide);
    tight.u_min = tight_lo;
    tight.u_max = tight_hi;
    tight.crc32 = stsp_table_crc32(&tight);
#ifdef BENCH_SPLINE
    plain.crc32 = stsp_table_crc32(&plain);
    if (bench_table(&plain, 0u) != 0 || bench_table(&wide, 1u) != 0 ||
        bench_table(&tight, 2u) != 0) {
        return 1;
    }
#else
    if (bench_table(&ROBOT_TABLE, 0u) != 0 || bench_table(&wide, 1u) != 0 ||
        bench_table(&tight, 2u) != 0) {
        return 1;
    }
#endif
    for (i = 0u; i < n_calls; ++i) {
        printf("call %lu table %u tick %lu stage %u latch %u status %d span %u\n",
               (unsigned long)i, (unsigned)calls[i].table, (unsigned long)calls[i].tick,
               (unsigned)calls[i].stage, (unsigned)calls[i].latch, (int)calls[i].status,
               (unsigned)calls[i].span);
    }
    printf("bench: %lu calls, sizeof(stsp_ctrl_t) %lu\n", (unsigned long)n_calls,
           (unsigned long)sizeof(stsp_ctrl_t));
    bench_print_table_line(&ROBOT_TABLE);
    return 0;
}
