/* libFuzzer target: the estimator controller (stsp_estimator.h) on the robot's position-sensor
 * tables, with the fuzzer choosing a corrupted estimator table (a header field, or gain words
 * with or without a matching CRC) and a run of steps (ticks forward, repeated, backwards or past
 * the plan; readings NULL or any bit pattern: NaN, Inf, huge), resets and verifies.
 * Invariants: every status is a defined one; a refused init leaves every step
 * STSP_ERR_NOT_INITIALIZED; a negative step status writes u_hold, a non-negative one a finite
 * command; nothing is read or written outside the arrays (ASan, UBSan). */
#include <math.h>
#include <string.h>

#include "fuzz_input.h"
#include "robot_position_sensor.h"

#include "fuzz_tables.h"

#define NX ROBOT_POSITION_SENSOR_NX
#define NU ROBOT_POSITION_SENSOR_NU
#define NY ROBOT_POSITION_SENSOR_NY
#define N_GAINS (((ROBOT_POSITION_SENSOR_N_TICKS + ROBOT_POSITION_SENSOR_EVERY - 1u) / \
                  ROBOT_POSITION_SENSOR_EVERY) * NX * NY)

/* stsp_est_init's precondition (as stsp_init's): each array is as long as the header says.
 * A corrupted ny (up to STSP_MAX_NY, beyond that refused before any read) or every (down to 1)
 * lengthens C and gain: the copies are as long as the largest the header can then describe. */
#define MAX_GAINS (ROBOT_POSITION_SENSOR_N_TICKS * NX * STSP_MAX_NY)
static float gains[MAX_GAINS];
static float out_rows[STSP_MAX_NY * NX];

static int step_status_ok(stsp_status_t st)
{
    return (st == STSP_OK) || (st == STSP_WARN_TICK_SKIPPED) ||
           (st == STSP_WARN_TICK_REPEATED) || (st == STSP_WARN_NO_MEASUREMENT) ||
           (st == STSP_ERR_TICK_RANGE) || (st == STSP_ERR_TICK_ORDER) ||
           (st == STSP_ERR_NONFINITE_STATE) || (st == STSP_ERR_NONFINITE_OUTPUT) ||
           (st == STSP_ERR_NONFINITE_MEASUREMENT) || (st == STSP_ERR_NOT_INITIALIZED);
}

/* A copy of the estimator table with one header field or some gain words changed. */
static void corrupt(fuzz_in_t *in, stsp_est_table_t *c)
{
    const uint32_t what = fuzz_u8(in) % 12u;
    const uint32_t v = fuzz_u32(in);
    switch (what) {
    case 0: c->magic = v; break;
    case 1: c->format_version = (uint16_t)v; break;
    case 2: c->scalar_kind = (uint16_t)v; break;
    case 3: c->nx = (uint16_t)v; break;
    case 4: c->nu = (uint16_t)v; break;
    case 5: c->ny = (uint16_t)v; break;
    case 6: c->n_stages = (uint16_t)v; break;
    case 7: c->n_ticks = v; break;
    case 8: c->every = v; break;
    case 9: c->problem_sha256[v % 32u] ^= (uint8_t)(1u + (v >> 8) % 255u); break;
    default: /* gain words, then (case 11) a CRC that matches them */
        fuzz_words(in, gains, N_GAINS, v);
        if (what == 11u) {
            c->crc32 = stsp_est_table_crc32(c);
        }
        break;
    }
}

/* The tables as shipped, validated once: an input that corrupts nothing starts from a copy of
 * this instance (a plain struct: it holds no pointer into itself), which spares the CRC of the
 * 432 KB gain table that makes init the costly part. */
static stsp_est_t shipped;
static stsp_status_t shipped_status = STSP_ERR_NOT_INITIALIZED;

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static stsp_est_table_t c;
    fuzz_in_t in = {data, size};
    stsp_est_t e;
    stsp_status_t st;
    uint32_t next = 0u;
    uint32_t i;
    if (shipped_status != STSP_OK) {
        shipped_status = stsp_est_init(&shipped, &robot_position_sensor_table,
                                       &robot_position_sensor_estimator);
        fuzz_check(shipped_status == STSP_OK);
    }
    if ((fuzz_u8(&in) % 4u) == 0u) {
        c = robot_position_sensor_estimator;
        memcpy(gains, robot_position_sensor_estimator.gain, N_GAINS * sizeof gains[0]);
        memcpy(out_rows, robot_position_sensor_estimator.C, NY * NX * sizeof out_rows[0]);
        c.gain = gains;
        c.C = out_rows;
        corrupt(&in, &c);
        st = stsp_est_init(&e, &robot_position_sensor_table, &c);
    } else {
        e = shipped;
        st = STSP_OK;
    }
    fuzz_check(fuzz_init_status_ok(st));
    for (i = 0u; i < 64u && in.n > 0u; ++i) {
        const uint32_t op = fuzz_u8(&in);
        float y[NY];
        float u[NU] = {1234.5f, -1234.5f};
        stsp_status_t s;
        uint32_t tick;
        if (op == 0xFEu) {
            s = stsp_est_reset(&e);
            fuzz_check((s == STSP_OK) || (s == STSP_ERR_NOT_INITIALIZED));
            next = 0u;
            continue;
        }
        if (op == 0xFFu) {
            s = stsp_est_verify(&e);
            fuzz_check((s == STSP_OK) || (s == STSP_ERR_NOT_INITIALIZED));
            continue;
        }
        tick = fuzz_tick(&in, op, next);
        fuzz_floats(&in, y, NY, 0);
        s = stsp_est_step(&e, tick, ((op & 4u) != 0u) ? NULL : y, u);
        fuzz_check(step_status_ok(s));
        if (st != STSP_OK) {
            fuzz_check(s == STSP_ERR_NOT_INITIALIZED);
            fuzz_check((u[0] == 1234.5f) && (u[1] == -1234.5f));  /* nu unknown: untouched */
        } else if (s < STSP_OK) {
            fuzz_check((u[0] == robot_position_sensor_table.u_hold[0]) &&
                       (u[1] == robot_position_sensor_table.u_hold[1]));
        } else {
            fuzz_check(isfinite(u[0]) && isfinite(u[1]));
            if (tick >= next) {
                next = tick + 1u;
            }
        }
    }
    return 0;
}
