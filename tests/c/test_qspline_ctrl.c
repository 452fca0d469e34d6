/* Unit tests of the fixed-point spline controller (stsp_step with a stsp_qspline_t table;
 * firmware/src/stsp_spline.c) on table Q (tests/c/qspline_table_q.h: nx = 2, nu = 2,
 * n_latch = 1, two stages). The reference is independent of the spline code: the gains of
 * every tick from tests/c/qspline_reference.py (exact rationals) put into a per-tick Q table,
 * run by the per-tick law, and the law written out here in int64 with floor division; every
 * command, status, saturation mask and latch must agree bit for bit, through tick skips,
 * repeats, stage changes and refused ticks, without and with actuator limits. Each bad table
 * is refused with its documented status (stsp_controller.h, stsp_qspline_t), including a row
 * bound broken at one tick only; stsp_verify() sees a changed spline header and a changed
 * coefficient. Built for Q15 and Q31, each also under ASan + UBSan; linked with the spline
 * code (-Wl,--undefined=stsp_spline_code, as a generated table's reference does). */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "stospline/stsp_controller.h"
#include "test_support.h"

#ifndef STSP_ARITH_FIXED_POINT
#error "test_qspline_ctrl.c tests the STSP_ARITH_Q15/Q31 builds"
#endif

#include "qspline_table_q.h"

#define NX 2u
#define NL 1u
#define F STSP_Q_FRAC_BITS
#define ONE ((int64_t)1 << F)
#define QMAX ((stsp_scalar_t)(ONE - 1))
#define QMIN ((stsp_scalar_t)(-ONE))

static const int64_t gains[N_TICKS][NU * NZ] = QSPLINE_EXPECTED;
static const uint16_t stage_n_latch[NS] = {1u, 1u};
static const int8_t x_exp[NX] = {1, -2};
static const int8_t u_exp[NU] = {3, 0};
static const int8_t v_exp[NL] = {2};
static stsp_scalar_t Lambda[NS * NL * NX], lambda0[NS * NL];
static stsp_scalar_t no_min[NU], no_max[NU], lo[NU], hi[NU], hold[NU];
static stsp_scalar_t K[N_TICKS * NU * NX], k0[N_TICKS * NU], L[N_TICKS * NU * NL];
static stsp_qspline_t q_gains;

/* a fraction of 2^F, rounded to an integer (exact for these multiples of 1/64) */
static stsp_scalar_t frac(int32_t num64)
{
    return (stsp_scalar_t)((int64_t)num64 * (ONE / 64));
}

static void fill(void)
{
    uint32_t t, i;
    Lambda[0] = frac(20); Lambda[1] = frac(-13); lambda0[0] = frac(5);
    Lambda[2] = frac(-9); Lambda[3] = frac(31); lambda0[1] = frac(-7);
    for (i = 0u; i < NU; ++i) {
        no_min[i] = QMIN;
        no_max[i] = QMAX;
        lo[i] = frac(-2);
        hi[i] = frac(3);
        hold[i] = frac(1);
    }
    /* the per-tick table of the same gains: g[i * NZ + col], col over z = [x, 1, v] */
    for (t = 0u; t < N_TICKS; ++t) {
        for (i = 0u; i < NU; ++i) {
            K[(t * NU + i) * NX + 0u] = (stsp_scalar_t)gains[t][i * NZ + 0u];
            K[(t * NU + i) * NX + 1u] = (stsp_scalar_t)gains[t][i * NZ + 1u];
            k0[t * NU + i] = (stsp_scalar_t)gains[t][i * NZ + 2u];
            L[t * NU + i] = (stsp_scalar_t)gains[t][i * NZ + 3u];
        }
    }
    q_gains = table_q();
}

static stsp_table_t common(const stsp_scalar_t *u_lo, const stsp_scalar_t *u_hi)
{
    stsp_table_t t = table_header(NX, NU, NL, NS, N_TICKS, 100u);
    t.stage_start = stage_start; t.stage_n_latch = stage_n_latch;
    t.Lambda = Lambda; t.lambda0 = lambda0;
    t.u_min = u_lo; t.u_max = u_hi; t.u_hold = hold;
    t.x_exp = x_exp; t.u_exp = u_exp; t.v_exp = v_exp;
    return t;
}

static stsp_table_t spline_table(const stsp_scalar_t *u_lo, const stsp_scalar_t *u_hi)
{
    stsp_table_t t = common(u_lo, u_hi);
    t.spline = &q_gains;
    t.crc32 = stsp_table_crc32(&t);
    return t;
}

static stsp_table_t per_tick_table(const stsp_scalar_t *u_lo, const stsp_scalar_t *u_hi)
{
    stsp_table_t t = common(u_lo, u_hi);
    t.K = K; t.k0 = k0; t.L = L;
    t.crc32 = stsp_table_crc32(&t);
    return t;
}

/* floor(a / 2^F + 1/2), exact (no shift of a negative value) */
static int64_t round_half_up(int64_t a)
{
    const int64_t n = a + (ONE / 2);
    int64_t q = n / ONE;
    if ((n % ONE) < 0) {
        --q;
    }
    return q;
}

/* The law written out: u[i] = round(k0 2^F + K x + L v) / 2^F, gains from the reference;
 * without the term of operand `skip` (NZ: none). */
static int64_t law_ref_skip(uint32_t tick, uint32_t i, const stsp_scalar_t *x, stsp_scalar_t v,
                            uint32_t skip)
{
    int64_t g[NZ];
    uint32_t j;
    for (j = 0u; j < NZ; ++j) {
        g[j] = (j == skip) ? 0 : gains[tick][i * NZ + j];
    }
    return round_half_up(g[2] * ONE + g[0] * x[0] + g[1] * x[1] + g[3] * v);
}

static int64_t law_ref(uint32_t tick, uint32_t i, const stsp_scalar_t *x, stsp_scalar_t v)
{
    return law_ref_skip(tick, i, x, v, NZ);
}

static stsp_scalar_t latch_ref(uint32_t stage, const stsp_scalar_t *x)
{
    return (stsp_scalar_t)round_half_up((int64_t)lambda0[stage] * ONE +
                                        (int64_t)Lambda[stage * NX] * x[0] +
                                        (int64_t)Lambda[stage * NX + 1u] * x[1]);
}

static uint32_t lcg(uint32_t *seed)
{
    *seed = *seed * 1664525u + 1013904223u;
    return *seed >> 8;
}

/* One tick sequence through both controllers and the written-out law. */
static void run_sequence(const stsp_scalar_t *u_lo, const stsp_scalar_t *u_hi, uint32_t seed0)
{
    /* in order, a repeat, a skip, backwards, a stage change by a skip, the end, past it */
    static const uint32_t ticks[] = {0u, 1u, 2u, 2u, 4u, 3u, 5u, 6u, 7u, 8u, 9u, 10u, 11u,
                                     13u, 14u, 14u, 15u, 16u, 17u, 16u, 0u};
    const stsp_table_t ts = spline_table(u_lo, u_hi);
    const stsp_table_t tp = per_tick_table(u_lo, u_hi);
    stsp_ctrl_t cs, cp;
    uint32_t seed = seed0, n;
    assert_int_equal(stsp_init(&cs, &ts), STSP_OK);
    assert_int_equal(stsp_init(&cp, &tp), STSP_OK);
    for (n = 0u; n < sizeof ticks / sizeof ticks[0]; ++n) {
        const uint32_t tick = ticks[n];
        stsp_scalar_t x[NX], us[NU], up[NU];
        stsp_status_t ss, sp;
        const uint16_t stage_before = cs.stage;
        const uint16_t latched_before = cs.latched;
        const stsp_scalar_t v_before = cs.v[0];
        uint32_t i;
        /* states over the whole Q range, the ends now and then */
        for (i = 0u; i < NX; ++i) {
            const uint32_t r = lcg(&seed);
            x[i] = ((r % 7u) == 0u) ? (((r >> 3) & 1u) ? QMAX : QMIN)
                                   : (stsp_scalar_t)((int64_t)(r % 65536u) * (ONE / 32768) - ONE);
        }
        ss = stsp_step(&cs, tick, x, us);
        sp = stsp_step(&cp, tick, x, up);
        assert_int_equal(ss, sp);
        assert_memory_equal(us, up, sizeof us);
        if (ss == STSP_WARN_SATURATED) {   /* sat_mask is defined after this status only */
            assert_int_equal(cs.sat_mask, cp.sat_mask);
        }
        assert_int_equal(cs.stage, cp.stage);
        assert_int_equal(cs.next_tick, cp.next_tick);
        assert_int_equal(cs.v[0], cp.v[0]);
        if (ss >= STSP_OK) {
            const uint32_t stage = (tick >= stage_start[1]) ? 1u : 0u;
            const stsp_scalar_t v = ((latched_before == 0u) || (stage != stage_before))
                                        ? latch_ref(stage, x) : v_before;
            uint16_t sat = 0u;
            assert_int_equal(cs.v[0], v);
            for (i = 0u; i < NU; ++i) {
                int64_t want = law_ref(tick, i, x, v);
                assert_true((want >= -(ONE - 1)) && (want <= ONE - 1));
                if (want > u_hi[i]) {
                    want = u_hi[i];
                    sat = (uint16_t)(sat | (1u << i));
                } else if (want < u_lo[i]) {
                    want = u_lo[i];
                    sat = (uint16_t)(sat | (1u << i));
                }
                assert_int_equal(us[i], want);
            }
            if (sat != 0u) {
                assert_int_equal(ss, STSP_WARN_SATURATED);
                assert_int_equal(cs.sat_mask, sat);
            }
        } else {
            assert_int_equal(us[0], hold[0]);
            assert_int_equal(us[1], hold[1]);
        }
    }
}

static void commands_match_the_reference(void **state)
{
    uint32_t seed;
    (void)state;
    for (seed = 1u; seed <= 40u; ++seed) {
        run_sequence(no_min, no_max, seed);
        run_sequence(lo, hi, seed);
    }
}

/* Statuses of the sequence itself (the comparison above holds for any): a repeat, a skip,
 * backwards, the end. */
static void tick_statuses(void **state)
{
    const stsp_table_t t = spline_table(no_min, no_max);
    const stsp_scalar_t x[NX] = {frac(1), frac(-1)};
    stsp_scalar_t u[NU];
    stsp_ctrl_t c;
    (void)state;
    assert_int_equal(stsp_init(&c, &t), STSP_OK);
    assert_int_equal(stsp_step(&c, 0u, x, u), STSP_OK);
    assert_int_equal(stsp_step(&c, 0u, x, u), STSP_WARN_TICK_REPEATED);
    assert_int_equal(stsp_step(&c, 3u, x, u), STSP_WARN_TICK_SKIPPED);
    assert_int_equal(stsp_step(&c, 1u, x, u), STSP_ERR_TICK_ORDER);
    assert_int_equal(stsp_step(&c, 12u, x, u), STSP_WARN_TICK_SKIPPED);
    assert_int_equal(c.stage, 1u);
    assert_int_equal(stsp_step(&c, 17u, x, u), STSP_ERR_TICK_RANGE);
    assert_int_equal(stsp_step(&c, 16u, x, u), STSP_WARN_TICK_SKIPPED);
    assert_int_equal(stsp_reset(&c), STSP_OK);
    assert_int_equal(stsp_step(&c, 0u, x, u), STSP_OK);
    assert_int_equal(stsp_verify(&c), STSP_OK);
}

/* init's status for table Q with one field of its spline changed (CRC recomputed when the
 * arrays are there: stsp_table_crc32's precondition; init checks for NULL first). */
static stsp_status_t init_with(const stsp_qspline_t *sp, int per_tick)
{
    stsp_table_t t = common(no_min, no_max);
    stsp_ctrl_t c;
    t.spline = sp;
    if (per_tick != 0) {
        t.K = K;
    }
    if ((sp->span_log2 != NULL) && (sp->row_start != NULL) && (sp->col != NULL) &&
        (sp->shift != NULL) && (sp->coef_start != NULL) && (sp->coef != NULL)) {
        t.crc32 = stsp_table_crc32(&t);
    }
    return stsp_init(&c, &t);
}

static void bad_tables_are_refused(void **state)
{
    static uint8_t bad_log2[NS];
    static uint32_t bad_cs[NS + 1u];
    static stsp_scalar_t bad_coef[48];
    stsp_qspline_t q;
    uint32_t i;
    (void)state;
    assert_int_equal(init_with(&q_gains, 0), STSP_OK);
    assert_int_equal(init_with(&q_gains, 1), STSP_ERR_BAD_DIMS);   /* K next to the spline */
    for (i = 0u; i < 6u; ++i) {                                     /* each array NULL */
        q = q_gains;
        switch (i) {
        case 0u: q.span_log2 = NULL; break;
        case 1u: q.row_start = NULL; break;
        case 2u: q.col = NULL; break;
        case 3u: q.shift = NULL; break;
        case 4u: q.coef_start = NULL; break;
        default: q.coef = NULL; break;
        }
        assert_int_equal(init_with(&q, 0), STSP_ERR_NULL);
    }
    memcpy(bad_log2, span_log2, sizeof bad_log2);
    bad_log2[0] = 10u;                                              /* spans of 1024 ticks */
    q = q_gains;
    q.span_log2 = bad_log2;
    assert_int_equal(init_with(&q, 0), STSP_ERR_BAD_DIMS);
    bad_log2[0] = 1u;                                               /* 5 spans: 48 != 8 x 3 + .. */
    assert_int_equal(init_with(&q, 0), STSP_ERR_BAD_DIMS);
    q = q_gains;
    q.n_entries = 5u;                                               /* lying lengths */
    assert_int_equal(init_with(&q, 0), STSP_ERR_BAD_DIMS);
    q = q_gains;
    q.n_coef = 47u;
    assert_int_equal(init_with(&q, 0), STSP_ERR_BAD_DIMS);
    memcpy(bad_cs, coef_start, sizeof bad_cs);
    bad_cs[1] = 17u;
    q = q_gains;
    q.coef_start = bad_cs;
    assert_int_equal(init_with(&q, 0), STSP_ERR_BAD_DIMS);
    /* the writable layout arrays of table Q, restored after each */
    shift[4] = 0u;
    assert_int_equal(init_with(&q_gains, 0), STSP_ERR_BAD_DIMS);
    shift[4] = 31u;
    assert_int_equal(init_with(&q_gains, 0), STSP_ERR_BAD_DIMS);
    shift[4] = 30u;
    col[5] = NZ;                                                    /* beyond z */
    assert_int_equal(init_with(&q_gains, 0), STSP_ERR_BAD_DIMS);
    col[5] = 0u;                                                    /* not increasing */
    assert_int_equal(init_with(&q_gains, 0), STSP_ERR_BAD_DIMS);
    col[5] = 3u;
    row_start[0] = 1u;
    assert_int_equal(init_with(&q_gains, 0), STSP_ERR_BAD_DIMS);
    row_start[0] = 0u;
    row_start[1] = 4u;                                              /* decreasing */
    assert_int_equal(init_with(&q_gains, 0), STSP_ERR_BAD_DIMS);
    row_start[1] = 2u;
    assert_int_equal(init_with(&q_gains, 0), STSP_OK);
    /* The row bound broken at tick 9 only: entry 0's and entry 1's coefficient 4 at the ends
     * of the range (P3 = 1 and P2 = 121 of 6 D^3 = 384 at tick 9; at most P2 = 64 elsewhere). */
    memcpy(bad_coef, coef, sizeof bad_coef);
    bad_coef[4] = QMIN;
    bad_coef[10] = QMAX;
    q = q_gains;
    q.coef = bad_coef;
    assert_int_equal(init_with(&q, 0), STSP_ERR_BAD_VALUES);
    bad_coef[10] = 5;                                               /* and restored: valid */
    assert_int_equal(init_with(&q, 0), STSP_OK);
}

/* A wrong CRC; stsp_verify() after the spline header or a coefficient changed. */
static void crc_and_verify(void **state)
{
    static stsp_scalar_t c2[48];
    static uint8_t s2[6];
    stsp_table_t t = spline_table(no_min, no_max);
    stsp_qspline_t other = q_gains;
    const stsp_scalar_t x[NX] = {0, 0};
    stsp_scalar_t u[NU];
    stsp_ctrl_t c;
    (void)state;
    t.crc32 ^= 1u;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_CRC);
    t.crc32 ^= 1u;
    assert_int_equal(stsp_init(&c, &t), STSP_OK);
    t.spline = &other;                       /* same contents, another address */
    assert_int_equal(stsp_verify(&c), STSP_ERR_TABLE_CHANGED);
    assert_int_equal(stsp_step(&c, 0u, x, u), STSP_ERR_NOT_INITIALIZED);
    assert_int_equal(u[0], hold[0]);
    t.spline = &q_gains;
    assert_int_equal(stsp_init(&c, &t), STSP_OK);
    q_gains.n_coef = 47u;                    /* the header's count changed */
    assert_int_equal(stsp_verify(&c), STSP_ERR_TABLE_CHANGED);
    q_gains.n_coef = 48u;
    memcpy(c2, coef, sizeof c2);
    q_gains.coef = c2;
    t.crc32 = stsp_table_crc32(&t);
    assert_int_equal(stsp_init(&c, &t), STSP_OK);
    c2[20] = (stsp_scalar_t)(c2[20] + 1);    /* a coefficient changed after init */
    assert_int_equal(stsp_verify(&c), STSP_ERR_BAD_CRC);
    q_gains.coef = coef;
    /* the shifts: covered by the CRC, and their array's address by the header check */
    t.crc32 = stsp_table_crc32(&t);
    assert_int_equal(stsp_init(&c, &t), STSP_OK);
    shift[0] = (uint8_t)(shift[0] + 1u);
    assert_int_equal(stsp_verify(&c), STSP_ERR_BAD_CRC);
    shift[0] = (uint8_t)(shift[0] - 1u);
    assert_int_equal(stsp_init(&c, &t), STSP_OK);
    memcpy(s2, shift, sizeof s2);
    q_gains.shift = s2;                      /* the same shifts at another address */
    assert_int_equal(stsp_verify(&c), STSP_ERR_TABLE_CHANGED);
    q_gains.shift = shift;
}

/* The spline arrays changed after init (until stsp_verify() notices; stsp_spline.c,
 * stsp_qspline_layout and stsp_qspline_law): every array a heap block of its exact size, x
 * too (the _san builds abort on any read beyond one). A stage whose layout no longer fits the
 * validated lengths (span_log2 beyond 9, a row end beyond n_entries or decreasing, coef_start
 * beyond n_coef, the tick's span beyond an entry's stride) commands 0; an operand index
 * beyond z contributes nothing; a scale outside 1..30 gives a wrong gain with no undefined
 * shift (the _san builds trap one): entry 4's scale 0 gives gain 0, as the reference's at
 * every tick of stage 1, so the commands are the reference's; 255 is not pinned. Every tick
 * in order, then verify: STSP_ERR_BAD_CRC. */
enum { CH_LOG2, CH_ROW_BEYOND, CH_ROW_DECREASING, CH_COEF_BEYOND, CH_STRIDE, CH_COL_255,
       CH_COL_NZ, CH_SHIFT_0, CH_SHIFT_255, CH_N };

/* -1: the command is 0 (the stage does not fit); -2: not pinned (in bounds only); else the
 * operand left out of the reference law (NZ: none). */
static int32_t changed_expect(uint32_t kase, uint32_t tick)
{
    const uint32_t stage = (tick >= stage_start[1]) ? 1u : 0u;
    switch (kase) {
    case CH_LOG2: return (stage == 0u) ? -1 : (int32_t)NZ;
    case CH_ROW_BEYOND: return (stage == 1u) ? -1 : (int32_t)NZ;
    case CH_ROW_DECREASING: return ((stage == 0u) || (tick >= 13u)) ? -1 : -2;
    case CH_COEF_BEYOND: return -1;
    case CH_STRIDE: return (stage == 0u) ? (int32_t)NZ : ((tick == 16u) ? -1 : -2);
    case CH_COL_255: case CH_COL_NZ: return (stage == 1u) ? 3 : (int32_t)NZ;
    case CH_SHIFT_255: return (stage == 1u) ? -2 : (int32_t)NZ;
    default: return (int32_t)NZ;
    }
}

static void changed_arrays_stay_in_bounds(void **state)
{
    uint8_t *hl = (uint8_t *)heap_copy(span_log2, sizeof span_log2);
    uint16_t *hr = (uint16_t *)heap_copy(row_start, sizeof row_start);
    uint8_t *hc = (uint8_t *)heap_copy(col, sizeof col);
    uint8_t *hs = (uint8_t *)heap_copy(shift, sizeof shift);
    uint32_t *hcs = (uint32_t *)heap_copy(coef_start, sizeof coef_start);
    stsp_scalar_t *hco = (stsp_scalar_t *)heap_copy(coef, sizeof coef);
    stsp_scalar_t *x = (stsp_scalar_t *)heap_copy(Lambda, sizeof(stsp_scalar_t) * NX);
    stsp_qspline_t q = q_gains;
    stsp_table_t t = common(no_min, no_max);
    uint32_t kase, seed = 7u;
    (void)state;
    q.span_log2 = hl; q.row_start = hr; q.col = hc; q.shift = hs;
    q.coef_start = hcs; q.coef = hco;
    t.spline = &q;
    t.crc32 = stsp_table_crc32(&t);
    for (kase = 0u; kase < (uint32_t)CH_N; ++kase) {
        stsp_ctrl_t c;
        stsp_scalar_t u[NU], v = 0;
        uint32_t tick, i;
        memcpy(hl, span_log2, sizeof span_log2);
        memcpy(hr, row_start, sizeof row_start);
        memcpy(hc, col, sizeof col);
        memcpy(hs, shift, sizeof shift);
        memcpy(hcs, coef_start, sizeof coef_start);
        assert_int_equal(stsp_init(&c, &t), STSP_OK);
        switch (kase) {
        case CH_LOG2: hl[0] = 200u; break;
        case CH_ROW_BEYOND: hr[4] = 9u; break;
        case CH_ROW_DECREASING: hr[2] = 1u; break;
        case CH_COEF_BEYOND: hcs[1] = 49u; break;
        case CH_STRIDE: hcs[1] = 20u; break;     /* stage 1: 28 / 3 entries, stride 9 of 10 */
        case CH_COL_255: hc[5] = 255u; break;    /* stage 1, input 1: L */
        case CH_COL_NZ: hc[5] = (uint8_t)NZ; break;
        case CH_SHIFT_0: hs[4] = 0u; break;      /* stage 1, input 1: K[0], scale 30 */
        default: hs[4] = 255u; break;
        }
        for (tick = 0u; tick < N_TICKS; ++tick) {
            for (i = 0u; i < NX; ++i) {
                x[i] = (stsp_scalar_t)((int64_t)(lcg(&seed) % 65536u) * (ONE / 32768) - ONE);
            }
            if ((tick == 0u) || (tick == stage_start[1])) {
                v = latch_ref((tick == 0u) ? 0u : 1u, x);
            }
            assert_int_equal(stsp_step(&c, tick, x, u), STSP_OK);
            for (i = 0u; i < NU; ++i) {
                const int32_t want = changed_expect(kase, tick);
                if (want == -1) {
                    assert_int_equal(u[i], 0);
                } else if (want >= 0) {
                    assert_int_equal(u[i], law_ref_skip(tick, i, x, v,
                                                         (i == 1u) ? (uint32_t)want : NZ));
                } else {
                    /* a wrong command, in bounds */
                }
            }
        }
        assert_int_equal(stsp_verify(&c), STSP_ERR_BAD_CRC);
        assert_int_equal(stsp_step(&c, 0u, x, u), STSP_ERR_NOT_INITIALIZED);
        assert_int_equal(u[0], hold[0]);
    }
    free(hl); free(hr); free(hc); free(hs); free(hcs); free(hco); free(x);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(commands_match_the_reference),
        cmocka_unit_test(tick_statuses),
        cmocka_unit_test(bad_tables_are_refused),
        cmocka_unit_test(crc_and_verify),
        cmocka_unit_test(changed_arrays_stay_in_bounds),
    };
    fill();
    return cmocka_run_group_tests(tests, NULL, NULL);
}
