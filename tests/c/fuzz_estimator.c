/* libFuzzer target: the estimator controller (stsp_estimator.h) on the robot's position-sensor
 * tables, with the fuzzer choosing a corrupted estimator table (a header field, or gain words
 * with or without a matching CRC; fixed point also the exponents and shifts) and a run of steps
 * (ticks forward, repeated, backwards or past the plan; readings NULL or any bit pattern: NaN,
 * Inf, huge; fixed point any integer), resets and verifies. Built as fuzz_estimator (float32,
 * robot_position_sensor.*), fuzz_estimator_q15 (robot_position_sensor_q15.*) and
 * fuzz_estimator_q31 (robot_position_sensor_q31.*).
 * Invariants: every status is a defined one; a refused init leaves every step
 * STSP_ERR_NOT_INITIALIZED; a negative step status writes u_hold, a non-negative one a finite
 * command; nothing is read or written outside the arrays (ASan, UBSan: no signed overflow in
 * the fixed-point sums, whatever the corrupted table). */
#include <math.h>
#include <string.h>

#include "fuzz_input.h"
#include "estimator_tables.h"

#include "fuzz_tables.h"

#define NX SENSOR(NX)
#define NU SENSOR(NU)
#define NY SENSOR(NY)
#define N_GAINS (((SENSOR(N_TICKS) + SENSOR(EVERY) - 1u) / SENSOR(EVERY)) * NX * NY)

/* stsp_est_init's precondition (as stsp_init's): each array is as long as the header says.
 * A corrupted ny (up to STSP_MAX_NY, beyond that refused before any read) or every (down to 1)
 * lengthens C and gain: the copies are as long as the largest the header can then describe. */
#define MAX_GAINS (SENSOR(N_TICKS) * NX * STSP_MAX_NY)
static stsp_scalar_t gains[MAX_GAINS];
static stsp_scalar_t out_rows[STSP_MAX_NY * NX];
#ifdef STSP_ARITH_FIXED_POINT
/* y_exp, e_exp and shift copies, as long as a corrupted ny (<= STSP_MAX_NY) makes them */
static int8_t exps[2][STSP_MAX_NY];
static uint8_t shifts[STSP_MAX_NY + 2u * NX];

/* any integer readings */
static void fuzz_reading(fuzz_in_t *in, stsp_scalar_t *y)
{
    uint32_t j;
    for (j = 0u; j < NY; ++j) {
        y[j] = (stsp_scalar_t)(int32_t)fuzz_u32(in);
    }
}

/* 1 + (v % 4) words of a[0..n-1], any value */
static void fuzz_table_words(fuzz_in_t *in, stsp_scalar_t *a, uint32_t n, uint32_t v)
{
    uint32_t k;
    for (k = 0u; k < 1u + (v % 4u); ++k) {
        const uint32_t w = fuzz_u32(in);
        a[fuzz_u32(in) % n] = (stsp_scalar_t)(int32_t)w;
    }
}

static int finite_command(const stsp_scalar_t *u)
{
    (void)u;
    return 1;
}
#else
static void fuzz_reading(fuzz_in_t *in, stsp_scalar_t *y)
{
    fuzz_floats(in, y, NY, 0);
}

static void fuzz_table_words(fuzz_in_t *in, stsp_scalar_t *a, uint32_t n, uint32_t v)
{
    fuzz_words(in, a, n, v);
}

static int finite_command(const stsp_scalar_t *u)
{
    return isfinite(u[0]) && isfinite(u[1]);
}
#endif

static int step_status_ok(stsp_status_t st)
{
    return (st == STSP_OK) || (st == STSP_WARN_TICK_SKIPPED) ||
           (st == STSP_WARN_TICK_REPEATED) || (st == STSP_WARN_NO_MEASUREMENT) ||
           (st == STSP_ERR_TICK_RANGE) || (st == STSP_ERR_TICK_ORDER) ||
           (st == STSP_ERR_NONFINITE_STATE) || (st == STSP_ERR_NONFINITE_OUTPUT) ||
           (st == STSP_ERR_NONFINITE_MEASUREMENT) || (st == STSP_ERR_NOT_INITIALIZED) ||
           (st == STSP_WARN_STATE_CLAMPED);
}

/* A copy of the estimator table with one header field or some gain words changed. */
static void corrupt(fuzz_in_t *in, stsp_est_table_t *c)
{
#ifdef STSP_ARITH_FIXED_POINT
    const uint32_t what = fuzz_u8(in) % 15u;
#else
    const uint32_t what = fuzz_u8(in) % 12u;
#endif
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
#ifdef STSP_ARITH_FIXED_POINT
    case 12: /* an exponent, with a CRC that matches */
    case 13:
        exps[what - 12u][v % STSP_MAX_NY] = (int8_t)(v >> 8);
        c->crc32 = stsp_est_table_crc32(c);
        break;
    case 14: /* a shift, with a CRC that matches */
        shifts[v % (STSP_MAX_NY + 2u * NX)] = (uint8_t)(v >> 8);
        c->crc32 = stsp_est_table_crc32(c);
        break;
#endif
    default: /* gain words, then (case 11) a CRC that matches them */
        fuzz_table_words(in, gains, N_GAINS, v);
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
        shipped_status = stsp_est_init(&shipped, &TABLE, &ESTIMATOR);
        fuzz_check(shipped_status == STSP_OK);
    }
    if ((fuzz_u8(&in) % 4u) == 0u) {
        c = ESTIMATOR;
        memcpy(gains, ESTIMATOR.gain, N_GAINS * sizeof gains[0]);
        memcpy(out_rows, ESTIMATOR.C, NY * NX * sizeof out_rows[0]);
        c.gain = gains;
        c.C = out_rows;
#ifdef STSP_ARITH_FIXED_POINT
        memcpy(exps[0], ESTIMATOR.y_exp, NY);
        memcpy(exps[1], ESTIMATOR.e_exp, NY);
        memcpy(shifts, ESTIMATOR.shift, NY + 2u * NX);
        c.y_exp = exps[0];
        c.e_exp = exps[1];
        c.shift = shifts;
#endif
        corrupt(&in, &c);
        st = stsp_est_init(&e, &TABLE, &c);
    } else {
        e = shipped;
        st = STSP_OK;
    }
    fuzz_check(fuzz_init_status_ok(st));
    for (i = 0u; i < 64u && in.n > 0u; ++i) {
        const uint32_t op = fuzz_u8(&in);
        stsp_scalar_t y[NY];
        stsp_scalar_t u[NU] = {(stsp_scalar_t)1234, (stsp_scalar_t)-1234};
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
        fuzz_reading(&in, y);
        s = stsp_est_step(&e, tick, ((op & 4u) != 0u) ? NULL : y, u);
        fuzz_check(step_status_ok(s));
        if (st != STSP_OK) {
            fuzz_check(s == STSP_ERR_NOT_INITIALIZED);
            fuzz_check((u[0] == (stsp_scalar_t)1234) &&
                       (u[1] == (stsp_scalar_t)-1234));  /* nu unknown: untouched */
        } else if (s < STSP_OK) {
            fuzz_check((u[0] == TABLE.u_hold[0]) && (u[1] == TABLE.u_hold[1]));
        } else {
            fuzz_check(finite_command(u));
            if (tick >= next) {
                next = tick + 1u;
            }
        }
    }
    return 0;
}
