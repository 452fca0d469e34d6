/* QEMU replay test: step a fresh controller on the target through the host build's recorded
 * closed-loop states and require the same commands: float32 (bit patterns, tolerance in ulp)
 * or Q15/Q31 (integers, tolerance in command units), whichever variant the image is built for.
 *
 * The records (tools/arm/make_replay.py) are a subset of the 6000 ticks in increasing order;
 * they include the first tick of every stage (0 and 3000), where the controller latches, so
 * the latched multipliers equal the host's and every recorded u is reproducible. Skipped ticks
 * must give STSP_WARN_TICK_SKIPPED, consecutive ones STSP_OK. Output through semihosting; exit
 * status 0 on success, 1 on any mismatch (QEMU exits with it). REPLAY_MAX_ULP (default 0) is
 * the tolerance in units in the last place; 0 means bit-identical. */
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "replay_records.h"
#include "stospline/stsp_controller.h"

#ifndef REPLAY_MAX_ULP
#define REPLAY_MAX_ULP 0u
#endif
#define REPLAY_MAX_REPORTS 10u

#ifdef STSP_ARITH_FIXED_POINT
/* Fixed point: the integer's two's complement bits, and the distance in command units. */
static uint32_t f32_bits(stsp_scalar_t value)
{
    return (uint32_t)(int32_t)value;
}

static uint32_t ulp_distance(stsp_scalar_t a, stsp_scalar_t b)
{
    int64_t d = (int64_t)a - (int64_t)b;
    return (uint32_t)((d < 0) ? -d : d);
}
#else
static uint32_t f32_bits(stsp_f32_t value)
{
    uint32_t bits;
    (void)memcpy(&bits, &value, sizeof bits);
    return bits;
}

/* Distance in representable binary32 values (both operands finite); +0 and -0 are 0 apart. */
static uint32_t ulp_distance(stsp_f32_t a, stsp_f32_t b)
{
    uint32_t ba = f32_bits(a), bb = f32_bits(b);
    /* Map sign-magnitude onto a monotone unsigned scale: negatives below 0x80000000. */
    uint32_t ka = (ba & 0x80000000u) ? 0x80000000u - (ba & 0x7FFFFFFFu) : 0x80000000u + ba;
    uint32_t kb = (bb & 0x80000000u) ? 0x80000000u - (bb & 0x7FFFFFFFu) : 0x80000000u + bb;
    return (ka > kb) ? ka - kb : kb - ka;
}
#endif

int main(void)
{
    stsp_ctrl_t ctrl;
    stsp_status_t st;
    uint32_t r, i, prev_tick = 0u;
    uint32_t compared = 0u, identical = 0u, mismatches = 0u, bad_status = 0u, max_ulp = 0u;
    uint32_t latches = 0u, order_errors = 0u, expect_latches = 1u;

    printf("replay: %lu records, table crc32 0x%08lX (host 0x%08lX), tolerance %u ulp\n",
           (unsigned long)replay_record_count, (unsigned long)REPLAY_TABLE.crc32,
           (unsigned long)replay_table_crc32, (unsigned)REPLAY_MAX_ULP);
    if (replay_table_crc32 != REPLAY_TABLE.crc32) {
        printf("replay: FAIL: records come from a different table\n");
        return 1;
    }
    for (i = 1u; i < REPLAY_TABLE.n_stages; ++i) {
        expect_latches += (REPLAY_TABLE.stage_n_latch[i] > 0u) ? 1u : 0u;
    }
    st = stsp_init(&ctrl, &REPLAY_TABLE);
    if (st != STSP_OK) {
        printf("replay: FAIL: stsp_init returned %d\n", (int)st);
        return 1;
    }
    for (r = 0u; r < replay_record_count; ++r) {
        const replay_record_t *rec = &replay_records[r];
        stsp_scalar_t u[REPLAY_NU];
        stsp_status_t expect;
        uint16_t stage_before = ctrl.stage, latched_before = ctrl.latched;
        if (r > 0u && rec->tick <= prev_tick) {
            ++order_errors;
            printf("replay: record %lu: tick %lu not after %lu\n", (unsigned long)r,
                   (unsigned long)rec->tick, (unsigned long)prev_tick);
        }
        expect = (rec->tick == ctrl.next_tick) ? STSP_OK : STSP_WARN_TICK_SKIPPED;
        st = stsp_step(&ctrl, rec->tick, rec->x, u);
        if (st != expect) {
            ++bad_status;
            printf("replay: tick %lu: status %d, expected %d\n", (unsigned long)rec->tick,
                   (int)st, (int)expect);
        }
        /* A latch: the first step, or entering a stage that latches (stage_n_latch > 0). */
        if (latched_before == 0u ||
            (ctrl.stage != stage_before && REPLAY_TABLE.stage_n_latch[ctrl.stage] > 0u)) {
            ++latches;
            printf("replay: tick %lu latched stage %u\n", (unsigned long)rec->tick,
                   (unsigned)ctrl.stage);
        }
        for (i = 0u; i < REPLAY_NU; ++i) {
            uint32_t d = ulp_distance(u[i], rec->u[i]);
            int same = f32_bits(u[i]) == f32_bits(rec->u[i]);
#if REPLAY_MAX_ULP == 0
            int ok = same;
#else
            int ok = d <= REPLAY_MAX_ULP;
#endif
            ++compared;
            identical += same ? 1u : 0u;
            if (d > max_ulp) {
                max_ulp = d;
            }
            if (!ok) {
                if (mismatches < REPLAY_MAX_REPORTS) {
                    printf("replay: MISMATCH tick %lu u[%lu]: target 0x%08lX (%.9g) host 0x%08lX "
                           "(%.9g), %lu ulp\n",
                           (unsigned long)rec->tick, (unsigned long)i,
                           (unsigned long)f32_bits(u[i]), (double)u[i],
                           (unsigned long)f32_bits(rec->u[i]), (double)rec->u[i],
                           (unsigned long)d);
                }
                ++mismatches;
            }
        }
        prev_tick = rec->tick;
    }
    printf("replay: %lu commands compared, %lu bit-identical, max %lu ulp, %lu mismatches, "
           "%lu bad statuses, %lu latches, ticks %lu..%lu\n",
           (unsigned long)compared, (unsigned long)identical, (unsigned long)max_ulp,
           (unsigned long)mismatches, (unsigned long)bad_status, (unsigned long)latches,
           (unsigned long)replay_records[0].tick, (unsigned long)prev_tick);
    if (mismatches != 0u || bad_status != 0u || order_errors != 0u ||
        latches != expect_latches || replay_record_count == 0u) {
        printf("replay: FAIL\n");
        return 1;
    }
    printf("replay: PASS\n");
    return 0;
}
