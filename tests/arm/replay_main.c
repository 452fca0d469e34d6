/* QEMU replay test: step fresh controllers on the target through the host build's recorded
 * calls and require the same answers: float32 (bit patterns, tolerance in ulp) or Q15/Q31
 * (integers, tolerance in command units), whichever variant the image is built for; per-tick
 * tables or (ROBOT_SPLINE) the robot's spline table.
 *
 * The records (tools/arm/make_replay.py) form runs, each on a fresh instance bound to the
 * robot table (or to a copy of its header with the run's limits and their CRC-32, which init
 * verifies). Per record: stsp_step(tick, x) must return the recorded status and command, and
 * leave next_tick, stage, latched (and, after STSP_WARN_SATURATED, sat_mask) as the host's
 * instance had them. A per-tick table's records are a subset of the 6000 ticks in increasing
 * order (the target gets STSP_WARN_TICK_SKIPPED after each gap); they include the first tick of
 * every stage, where the controller latches, so the latched multipliers equal the host's and
 * every recorded u is reproducible. A spline table's records are every call of the host's
 * closed loop (skips, repeats, non-finite and huge states, ticks past the end and backwards).
 * Every run must latch once per latching stage. Output through semihosting; exit status 0 on
 * success, 1 on any mismatch (QEMU exits with it). REPLAY_MAX_ULP (default 0) is the tolerance
 * in units in the last place; 0 means bit-identical.
 *
 * Testing the test: REPLAY_PERTURB_COEF=<n> (spline images; run_replay.sh --perturb-coef) binds
 * every run to a RAM copy of the spline whose coefficient n is one ulp (fixed point: one unit)
 * larger (smaller at the top of the range), with the table's
 * CRC-32 recomputed on the target so that init accepts it: the commands must then differ. */
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "replay_records.h"
#include "stospline/stsp_controller.h"

#ifndef REPLAY_MAX_ULP
#define REPLAY_MAX_ULP 0u
#endif
#define REPLAY_MAX_REPORTS 10u
#define REPLAY_STATUS_MIN (-13) /* STSP_ERR_TABLE_CHANGED */
#define REPLAY_STATUS_MAX 5     /* STSP_WARN_BAND_FALLBACK */

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

#ifdef REPLAY_PERTURB_COEF
#ifndef ROBOT_SPLINE
#error "REPLAY_PERTURB_COEF: spline images only"
#endif
#define REPLAY_MAX_COEF 4096u
static stsp_spline_gains_t perturbed_spline;
static stsp_scalar_t perturbed_coef[REPLAY_MAX_COEF];

/* t with its spline replaced by a RAM copy whose coefficient REPLAY_PERTURB_COEF is one ulp
 * (fixed point: one unit) up, or down at the top of the range, and the CRC recomputed (0 if
 * the table does not allow it). */
static int perturb_table(stsp_table_t *t)
{
    const stsp_spline_gains_t *sp = t->spline;
    if ((sp == NULL) || (sp->n_coef > REPLAY_MAX_COEF) ||
        ((uint32_t)(REPLAY_PERTURB_COEF) >= sp->n_coef)) {
        return 0;
    }
    perturbed_spline = *sp;
    (void)memcpy(perturbed_coef, sp->coef, sizeof(stsp_scalar_t) * sp->n_coef);
#ifdef STSP_ARITH_FIXED_POINT
    {
        const stsp_scalar_t c = perturbed_coef[REPLAY_PERTURB_COEF];
        const stsp_scalar_t d = (c < (stsp_scalar_t)(((uint32_t)1u << STSP_Q_FRAC_BITS) - 1u))
                                    ? (stsp_scalar_t)(c + 1) : (stsp_scalar_t)(c - 1);
        printf("replay: PERTURBED coefficient %u: %ld -> %ld\n", (unsigned)(REPLAY_PERTURB_COEF),
               (long)c, (long)d);
        perturbed_coef[REPLAY_PERTURB_COEF] = d;
    }
#else
    {
        uint32_t bits;
        (void)memcpy(&bits, &perturbed_coef[REPLAY_PERTURB_COEF], sizeof bits);
        printf("replay: PERTURBED coefficient %u: 0x%08lX -> 0x%08lX\n",
               (unsigned)(REPLAY_PERTURB_COEF), (unsigned long)bits, (unsigned long)(bits + 1u));
        bits += 1u; /* one ulp away from zero */
        (void)memcpy(&perturbed_coef[REPLAY_PERTURB_COEF], &bits, sizeof bits);
    }
#endif
    perturbed_spline.coef = perturbed_coef;
    t->spline = &perturbed_spline;
    t->crc32 = stsp_table_crc32(t);
    return 1;
}
#endif

/* One run: returns the number of failures (mismatched commands, statuses or fields, wrong
 * latch count, a table the target refuses). */
static uint32_t replay_run(uint32_t n, const replay_run_t *run)
{
    stsp_ctrl_t ctrl;
    stsp_table_t table = REPLAY_TABLE;
    stsp_status_t st;
    uint32_t r, i;
    uint32_t compared = 0u, identical = 0u, mismatches = 0u, bad_status = 0u, bad_fields = 0u;
    uint32_t max_ulp = 0u, latches = 0u, expect_latches = 1u, reports = 0u;
    uint32_t statuses[REPLAY_STATUS_MAX - REPLAY_STATUS_MIN + 1];
    (void)memset(statuses, 0, sizeof statuses);

    if (run->u_min != NULL) {
        table.u_min = run->u_min;
        table.u_max = run->u_max;
        table.crc32 = run->crc32;
        /* The target's CRC of the changed table must be the host's. */
        if (stsp_table_crc32(&table) != run->crc32) {
            printf("replay: run %lu: FAIL: crc32 of the table with its limits 0x%08lX, host "
                   "0x%08lX\n", (unsigned long)n, (unsigned long)stsp_table_crc32(&table),
                   (unsigned long)run->crc32);
            return 1u;
        }
    }
#ifdef REPLAY_PERTURB_COEF
    if (perturb_table(&table) == 0) {
        printf("replay: run %lu: FAIL: cannot perturb coefficient %u\n", (unsigned long)n,
               (unsigned)(REPLAY_PERTURB_COEF));
        return 1u;
    }
#endif
    for (i = 1u; i < table.n_stages; ++i) {
        expect_latches += (table.stage_n_latch[i] > 0u) ? 1u : 0u;
    }
    st = stsp_init(&ctrl, &table);
    if (st != STSP_OK) {
        printf("replay: run %lu: FAIL: stsp_init returned %d\n", (unsigned long)n, (int)st);
        return 1u;
    }
    for (r = 0u; r < run->count; ++r) {
        const replay_record_t *rec = &run->records[r];
        stsp_scalar_t u[REPLAY_NU];
        uint16_t stage_before = ctrl.stage, latched_before = ctrl.latched;
        st = stsp_step(&ctrl, rec->tick, rec->x, u);
        if ((st >= REPLAY_STATUS_MIN) && (st <= REPLAY_STATUS_MAX)) {
            ++statuses[st - REPLAY_STATUS_MIN];
        }
        if (st != (stsp_status_t)rec->status) {
            ++bad_status;
            if (reports++ < REPLAY_MAX_REPORTS) {
                printf("replay: run %lu record %lu tick %lu: status %d, host %d\n",
                       (unsigned long)n, (unsigned long)r, (unsigned long)rec->tick, (int)st,
                       (int)rec->status);
            }
        }
        if ((ctrl.next_tick != rec->next_tick) || (ctrl.stage != rec->stage) ||
            ((ctrl.latched != 0u) != (rec->latched != 0u)) ||
            ((st == STSP_WARN_SATURATED) && (ctrl.sat_mask != rec->sat_mask))) {
            ++bad_fields;
            if (reports++ < REPLAY_MAX_REPORTS) {
                printf("replay: run %lu record %lu tick %lu: next_tick %lu stage %u latched %u "
                       "sat_mask 0x%X, host %lu %u %u 0x%X\n", (unsigned long)n,
                       (unsigned long)r, (unsigned long)rec->tick, (unsigned long)ctrl.next_tick,
                       (unsigned)ctrl.stage, (unsigned)ctrl.latched, (unsigned)ctrl.sat_mask,
                       (unsigned long)rec->next_tick, (unsigned)rec->stage,
                       (unsigned)rec->latched, (unsigned)rec->sat_mask);
            }
        }
        /* A latch: the first successful step, or entering a stage that latches. */
        if ((st >= STSP_OK) &&
            ((latched_before == 0u) ||
             ((ctrl.stage != stage_before) && (table.stage_n_latch[ctrl.stage] > 0u)))) {
            ++latches;
            printf("replay: run %lu tick %lu latched stage %u\n", (unsigned long)n,
                   (unsigned long)rec->tick, (unsigned)ctrl.stage);
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
                if (reports++ < REPLAY_MAX_REPORTS) {
                    printf("replay: MISMATCH run %lu tick %lu u[%lu]: target 0x%08lX (%.9g) host "
                           "0x%08lX (%.9g), %lu ulp\n",
                           (unsigned long)n, (unsigned long)rec->tick, (unsigned long)i,
                           (unsigned long)f32_bits(u[i]), (double)u[i],
                           (unsigned long)f32_bits(rec->u[i]), (double)rec->u[i],
                           (unsigned long)d);
                }
                ++mismatches;
            }
        }
    }
    printf("replay: run %lu (%s): %lu calls, %lu commands compared, %lu bit-identical, max %lu "
           "ulp, %lu mismatches, %lu bad statuses, %lu bad fields, %lu latches (%lu expected)\n",
           (unsigned long)n, run->note, (unsigned long)run->count, (unsigned long)compared,
           (unsigned long)identical, (unsigned long)max_ulp, (unsigned long)mismatches,
           (unsigned long)bad_status, (unsigned long)bad_fields, (unsigned long)latches,
           (unsigned long)expect_latches);
    printf("replay: run %lu statuses:", (unsigned long)n);
    for (i = 0u; i < (uint32_t)(REPLAY_STATUS_MAX - REPLAY_STATUS_MIN + 1); ++i) {
        if (statuses[i] != 0u) {
            printf(" %d x %lu", (int)i + REPLAY_STATUS_MIN, (unsigned long)statuses[i]);
        }
    }
    printf("\n");
    return mismatches + bad_status + bad_fields + ((latches != expect_latches) ? 1u : 0u) +
           ((run->count == 0u) ? 1u : 0u);
}

int main(void)
{
    uint32_t n, failures = 0u;
    printf("replay: %lu run(s), table crc32 0x%08lX (host 0x%08lX), tolerance %u ulp\n",
           (unsigned long)replay_run_count, (unsigned long)REPLAY_TABLE.crc32,
           (unsigned long)replay_table_crc32, (unsigned)REPLAY_MAX_ULP);
    if (replay_table_crc32 != REPLAY_TABLE.crc32) {
        printf("replay: FAIL: records come from a different table\n");
        return 1;
    }
    for (n = 0u; n < replay_run_count; ++n) {
        failures += replay_run(n, &replay_runs[n]);
    }
    if ((failures != 0u) || (replay_run_count == 0u)) {
        printf("replay: FAIL\n");
        return 1;
    }
    printf("replay: PASS\n");
    return 0;
}
