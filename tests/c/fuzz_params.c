/* libFuzzer target: runtime parameters (stsp_params.h) on the robot_goal tables, with the
 * fuzzer choosing a corrupted parameter table (a header field, or column words with or without
 * a matching CRC) and a run of operations: theta of any bit pattern (NaN, Inf, huge, inside
 * the range), steps (ticks forward, repeated, backwards or past the plan; states of any bit
 * pattern), resets and verifies. Invariants: every status is a defined one; a refused theta
 * leaves the commands those of the parameters before (checked against a twin instance that
 * never saw it); a refused init leaves every step STSP_ERR_NOT_INITIALIZED; a negative step
 * status writes u_hold, a non-negative one a finite command within the limits; nothing is read
 * or written outside the arrays (ASan, UBSan). Built for float32 (gains/robot_goal*) and,
 * as fuzz_params_q15/_q31, for the fixed-point parametric tables (gains/robot_goal_<arith>*:
 * states and column words of any integer, d_exp words too), and as fuzz_params_spline
 * (PARAMS_SPLINE) for the spline columns on the robot_goal spline table
 * (gains/robot_goal_spline*: coefficient words and n_spline_coef too), and as
 * fuzz_params_q15_spline/_q31_spline (PARAMS_SPLINE in Q15/Q31) for the fixed-point spline
 * columns (gains/robot_goal_<arith>_spline*: block words, scales included, and
 * n_spline_coef). */
#include <math.h>
#include <string.h>

#include "fuzz_input.h"
#if defined(STSP_ARITH_Q15) && defined(PARAMS_SPLINE)
#include "robot_goal_q15_spline_params.h"
#define G(name) robot_goal_q15_spline_##name
#define N_TICKS ROBOT_GOAL_Q15_SPLINE_N_TICKS
#elif defined(STSP_ARITH_Q31) && defined(PARAMS_SPLINE)
#include "robot_goal_q31_spline_params.h"
#define G(name) robot_goal_q31_spline_##name
#define N_TICKS ROBOT_GOAL_Q31_SPLINE_N_TICKS
#elif defined(STSP_ARITH_Q15)
#include "robot_goal_q15_params.h"
#define G(name) robot_goal_q15_##name
#define N_TICKS ROBOT_GOAL_Q15_N_TICKS
#elif defined(STSP_ARITH_Q31)
#include "robot_goal_q31_params.h"
#define G(name) robot_goal_q31_##name
#define N_TICKS ROBOT_GOAL_Q31_N_TICKS
#elif defined(PARAMS_SPLINE)
#include "robot_goal_spline_params.h"
#define G(name) robot_goal_spline_##name
#define N_TICKS ROBOT_GOAL_SPLINE_N_TICKS
#else
#include "robot_goal_params.h"
#define G(name) robot_goal_##name
#define N_TICKS ROBOT_GOAL_N_TICKS
#endif

#include "fuzz_tables.h"

#define NX 4u
#define NU 2u
#define NP 2u
#define N_LATCH 4u
#define N_STAGES 2u
/* S_k0's length: per tick, or the spline columns' coefficients */
#define N_COLS ((uint32_t)(sizeof G(S_k0) / sizeof G(S_k0)[0]))

/* A corrupted n_params (up to STSP_MAX_PARAMS, beyond that refused before any read)
 * lengthens every array: the copies are as long as the largest the header can describe (a
 * spline table's n_spline_coef must match n_params: at most NU STSP_MAX_PARAMS (n_knots - 4
 * n_stages), below N_TICKS NU STSP_MAX_PARAMS). */
static stsp_scalar_t cols[N_TICKS * NU * STSP_MAX_PARAMS];
static stsp_scalar_t lam[N_STAGES * N_LATCH * STSP_MAX_PARAMS];
static stsp_param_value_t nominal[STSP_MAX_PARAMS], lower[STSP_MAX_PARAMS],
    upper[STSP_MAX_PARAMS];

#ifdef STSP_ARITH_FIXED_POINT
static int8_t d_exp[STSP_MAX_PARAMS];
#define SENTINEL {1234, -1234}
#define FINITE(v) 1

/* A range word: the low and high words of the binary64 both v. */
static void set_word(double *a, uint32_t v)
{
    const uint64_t bits = ((uint64_t)v << 32) | v;
    memcpy(a, &bits, sizeof bits);
}

/* 1 + (v % 4) entries of a[0..n-1], each of any value at a place the fuzzer chooses. */
static void set_entries(fuzz_in_t *in, stsp_scalar_t *a, uint32_t n, uint32_t v)
{
    uint32_t k;
    for (k = 0u; k < 1u + (v % 4u); ++k) {
        const uint32_t bits = fuzz_u32(in);
        a[fuzz_u32(in) % n] = (stsp_scalar_t)(int32_t)bits;
    }
}

/* States of any integer. */
static void set_state(fuzz_in_t *in, stsp_scalar_t *x, uint32_t n, int moderate)
{
    uint32_t j;
    (void)moderate;
    for (j = 0u; j < n; ++j) {
        x[j] = (stsp_scalar_t)(int32_t)fuzz_u32(in);
    }
}
#else
#define SENTINEL {1234.5f, -1234.5f}
#define FINITE(v) isfinite(v)

static void set_word(float *a, uint32_t v)
{
    memcpy(a, &v, sizeof v);
}

#define set_entries fuzz_words
#define set_state fuzz_floats
#endif

static int step_status_ok(stsp_status_t st)
{
    return (st == STSP_OK) || (st == STSP_WARN_TICK_SKIPPED) ||
           (st == STSP_WARN_TICK_REPEATED) || (st == STSP_WARN_SATURATED) ||
           (st == STSP_ERR_TICK_RANGE) || (st == STSP_ERR_TICK_ORDER) ||
           (st == STSP_ERR_NONFINITE_STATE) || (st == STSP_ERR_NONFINITE_OUTPUT) ||
           (st == STSP_ERR_NOT_INITIALIZED);
}

/* A copy of the parameter table with one header field or some column words changed. */
static void corrupt(fuzz_in_t *in, stsp_params_table_t *c)
{
    const uint32_t what = fuzz_u8(in) % 13u;
    const uint32_t v = fuzz_u32(in);
    switch (what) {
    case 0: c->magic = v; break;
    case 1: c->format_version = (uint16_t)v; break;
    case 2: c->scalar_kind = (uint16_t)v; break;
    case 3: c->n_params = (uint16_t)v; break;
    case 4: c->nu = (uint16_t)v; break;
    case 5: c->n_latch = (uint16_t)v; break;
    case 6: c->n_stages = (uint16_t)v; break;
    case 7: c->n_ticks = v; break;
    case 8: c->problem_sha256[v % 32u] ^= (uint8_t)(1u + (v >> 8) % 255u); break;
    case 12: /* the spline columns' length (and n_params to match, when v says so) */
        c->n_spline_coef = v;
        if ((v & 1u) != 0u) {
            c->n_params = (uint16_t)(1u + (v >> 1) % STSP_MAX_PARAMS);
            c->n_spline_coef = (uint32_t)NU * c->n_params * (N_COLS / (NU * NP));
            c->crc32 = stsp_params_table_crc32(c);
        }
        break;
    case 9: /* a range word (lower or upper; fixed point: or d_exp), with a matching CRC */
#ifdef STSP_ARITH_FIXED_POINT
        if ((v & 2u) != 0u) {
            d_exp[(v >> 2) % NP] = (int8_t)(v >> 8);
            c->crc32 = stsp_params_table_crc32(c);
            break;
        }
#endif
        set_word(((v & 1u) != 0u) ? &lower[(v >> 2) % NP] : &upper[(v >> 2) % NP], v);
        c->crc32 = stsp_params_table_crc32(c);
        break;
    default: /* column words, then (case 11) a CRC that matches them */
        set_entries(in, cols, N_COLS, v);
        if (what == 11u) {
            c->crc32 = stsp_params_table_crc32(c);
        }
        break;
    }
}

/* The tables as shipped, validated once (a plain struct: it holds no pointer into itself). */
static stsp_param_t shipped;
static stsp_status_t shipped_status = STSP_ERR_NOT_INITIALIZED;

static void check_command(stsp_status_t init, stsp_status_t s, const stsp_scalar_t *u)
{
    static const stsp_scalar_t sentinel[NU] = SENTINEL;
    uint32_t i;
    if (init != STSP_OK) {
        fuzz_check(s == STSP_ERR_NOT_INITIALIZED);
        fuzz_check(memcmp(u, sentinel, sizeof sentinel) == 0); /* nu unknown: untouched */
    } else if (s < STSP_OK) {
        fuzz_check(memcmp(u, G(table).u_hold, NU * sizeof u[0]) == 0);
    } else {
        for (i = 0u; i < NU; ++i) {
            fuzz_check(FINITE(u[i]) && (u[i] >= G(table).u_min[i]) &&
                       (u[i] <= G(table).u_max[i]));
        }
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static stsp_params_table_t c;
    fuzz_in_t in = {data, size};
    stsp_param_t e;
    stsp_param_t twin;
    stsp_status_t st;
    const stsp_params_table_t *in_use = &G(params);
    uint32_t next = 0u;
    uint32_t i;
    if (shipped_status != STSP_OK) {
        shipped_status = stsp_param_init(&shipped, &G(table), &G(params));
        fuzz_check(shipped_status == STSP_OK);
    }
    if ((fuzz_u8(&in) % 4u) == 0u) {
        c = G(params);
        memcpy(cols, G(S_k0), N_COLS * sizeof cols[0]);
        memcpy(lam, G(S_lambda0), sizeof G(S_lambda0));
        memcpy(nominal, G(param_nominal), NP * sizeof nominal[0]);
        memcpy(lower, G(param_lower), NP * sizeof lower[0]);
        memcpy(upper, G(param_upper), NP * sizeof upper[0]);
#ifdef STSP_ARITH_FIXED_POINT
        memcpy(d_exp, G(param_d_exp), NP * sizeof d_exp[0]);
        c.d_exp = d_exp;
#endif
        c.S_k0 = cols;
        c.S_lambda0 = lam;
        c.nominal = nominal;
        c.lower = lower;
        c.upper = upper;
        corrupt(&in, &c);
        st = stsp_param_init(&e, &G(table), &c);
        in_use = &c;
    } else {
        e = shipped;
        st = STSP_OK;
    }
    fuzz_check(fuzz_init_status_ok(st));
    twin = e;
    for (i = 0u; i < 64u && in.n > 0u; ++i) {
        const uint32_t op = fuzz_u8(&in);
        stsp_scalar_t x[NX];
        stsp_scalar_t u[NU] = SENTINEL;
        stsp_scalar_t w[NU] = SENTINEL;
        stsp_status_t s;
        stsp_status_t t;
        uint32_t tick;
        uint32_t j;
        if (op == 0xFDu) {
            float theta[STSP_MAX_PARAMS] = {0.0f}; /* a corrupted n_params reads them all */
            fuzz_floats(&in, theta, NP, 0);
            s = stsp_set_params(&e, theta);
            fuzz_check((s == STSP_OK) || (s == STSP_ERR_PARAM_RANGE) ||
                       (s == STSP_ERR_NOT_INITIALIZED));
            if (s == STSP_OK) { /* only a finite theta inside the range is taken */
                for (j = 0u; j < NP; ++j) {
                    fuzz_check(isfinite(theta[j]) && (theta[j] >= in_use->lower[j]) &&
                               (theta[j] <= in_use->upper[j]));
                }
                fuzz_check(stsp_set_params(&twin, theta) == STSP_OK);
            }
            continue;
        }
        if (op == 0xFEu) {
            s = stsp_param_reset(&e);
            t = stsp_param_reset(&twin);
            fuzz_check((s == t) && ((s == STSP_OK) || (s == STSP_ERR_NOT_INITIALIZED)));
            next = 0u;
            continue;
        }
        if (op == 0xFFu) {
            s = stsp_param_verify(&e);
            fuzz_check((s == STSP_OK) || (s == STSP_ERR_NOT_INITIALIZED));
            (void)stsp_param_verify(&twin);
            continue;
        }
        tick = fuzz_tick(&in, op, next);
        set_state(&in, x, NX, (op & 4u) != 0u); /* moderate: commands within range, mostly */
        s = stsp_param_step(&e, tick, x, u);
        t = stsp_param_step(&twin, tick, x, w);
        fuzz_check(step_status_ok(s));
        fuzz_check((s == t) && (memcmp(u, w, sizeof u) == 0)); /* refused thetas changed nothing */
        check_command(st, s, u);
        if ((st == STSP_OK) && (s >= STSP_OK) && (tick >= next)) {
            next = tick + 1u;
        }
    }
    return 0;
}
