/* Unit tests of spline tables (stsp_spline_t, table format 5) on a small hand-made table S whose
 * commands are checked three ways: bit for bit against constants printed by
 * tests/c/spline_reference.py (numpy float32, the format's evaluation order, written
 * independently of the firmware), bit for bit against a reference evaluation written out here
 * (the literal loops of The NURBS Book A2.2, the same binary32 operations in the same order),
 * and against a double-precision evaluation of the splines by the Cox-de Boor recursion within
 * a tolerance. Built for the generic controller, for STSP_FIXED 2/2/2 (table S's shape) and
 * each under ASan + UBSan (CMakeLists.txt). */
#include <float.h>
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "stospline/stsp_controller.h"
#include "test_support.h"

/* Table S: nx = 2, nu = 2, n_latch = 2; stage 0 = ticks 0..9 (one multiplier latched, 3 spans:
 * knots 3, 7), stage 1 = ticks 10..21 (two multipliers, 2 spans: knot 5). Stored entries:
 * stage 0, input 0: K00, k0, L00; input 1: k0 only (so x[1] is used by no input in stage 0);
 * stage 1, input 0: none; input 1: K10, K11, k0, L10 (v[1] is latched but used by no input).
 * tests/c/spline_reference.py writes out the same table. */
#define S_NX 2u
#define S_NU 2u
#define S_N_LATCH 2u
#define S_NS 2u
#define S_NT 22u
#define S_N_KNOTS 19u
#define S_N_ENTRIES 8u
#define S_N_COEF 44u

static const uint32_t s_stage_start[S_NS + 1u] = {0u, 10u, 22u};
static const uint16_t s_stage_n_latch[S_NS] = {1u, 2u};
static const uint32_t s_knot_start[S_NS + 1u] = {0u, 10u, 19u};
static const float s_knot[S_N_KNOTS] = {0.0f, 0.0f, 0.0f, 0.0f, 3.0f, 7.0f, 10.0f, 10.0f, 10.0f,
                                        10.0f, 0.0f, 0.0f, 0.0f, 0.0f, 5.0f, 12.0f, 12.0f, 12.0f,
                                        12.0f};
static const uint16_t s_row_start[S_NS * S_NU + 1u] = {0u, 3u, 4u, 4u, 8u};
static const uint8_t s_col[S_N_ENTRIES] = {0u, 2u, 3u, 2u, 0u, 1u, 2u, 3u};
static const uint32_t s_coef_start[S_NS + 1u] = {0u, 24u, 44u};
static const float s_coef[S_N_COEF] = {
    0.5f, 0.625f, 0.75f, 0.5f, 0.25f, 0.125f,   /* stage 0: K00 */
    0.1f, 0.2f, -0.3f, 0.4f, 0.05f, -0.06f,     /* k0[0] */
    1.5f, 1.25f, 1.0f, 0.875f, 0.75f, 0.5f,     /* L00 */
    -0.2f, -0.1f, 0.0f, 0.1f, 0.2f, 0.3f,       /* k0[1] */
    0.9f, 0.8f, 0.7f, 0.6f, 0.5f,               /* stage 1: K10 */
    -1.1f, -1.2f, -1.3f, -1.4f, -1.5f,          /* K11 */
    0.01f, 0.02f, 0.03f, 0.04f, 0.05f,          /* k0[1] */
    2.0f, 1.5f, 1.0f, 0.5f, 0.25f};             /* L10 */
static const float s_Lambda[S_NS * S_N_LATCH * S_NX] = {0.5f,  -0.25f, 0.0f,   0.0f,
                                                        -1.0f, 0.75f,  100.0f, 2.0f};
static const float s_lambda0[S_NS * S_N_LATCH] = {0.125f, 0.0f, 0.3f, -0.2f};
static const float s_no_min[S_NU] = {-FLT_MAX, -FLT_MAX}, s_no_max[S_NU] = {FLT_MAX, FLT_MAX};
static const float s_tight_min[S_NU] = {-0.25f, -1.0f}, s_tight_max[S_NU] = {0.5f, 1.0f};
static const float s_hold[S_NU] = {0.5f, -0.25f};

/* tests/c/spline_reference.py (run it to regenerate): u[tick][i] bit patterns for the run of
 * ticks 0..21 with x = state(tick), and table S's CRC-32 from the documented serialization
 * (problem_sha256 = 0, 1, ..., 31). */
static const uint32_t SPLINE_EXPECTED_BITS[22][2] = {
    {0x3FB1999Au, 0x3E4CCCCDu}, /* 0: 1.38750005, 0.200000003 */
    {0x3F9129FAu, 0x3DEFE4A3u}, /* 1: 1.13409352, 0.117135309 */
    {0x3F6EC073u, 0x3D7969CDu}, /* 2: 0.932624042, 0.0608919151 */
    {0x3F34B87Fu, 0x3CA22B0Cu}, /* 3: 0.705940187, 0.019795917 */
    {0x3ECD505Fu, 0xBC833D3Du}, /* 4: 0.401003808, -0.0160204116 */
    {0x3D9B1A24u, 0xBD4CCCCEu}, /* 5: 0.075733453, -0.0500000045 */
    {0xBE44E034u, 0xBDABFD7Eu}, /* 6: -0.192261517, -0.0839795917 */
    {0xBEABCF33u, 0xBDF55792u}, /* 7: -0.33556518, -0.119795933 */
    {0xBEA13041u, 0xBE24C0DAu}, /* 8: -0.314821273, -0.16089192 */
    {0xBE2C8798u, 0xBE5E58B8u}, /* 9: -0.168485999, -0.21713531 */
    {0x00000000u, 0x403147AEu}, /* 10: 0, 2.76999998 */
    {0x00000000u, 0x3FB39BF6u}, /* 11: 0, 1.40319705 */
    {0x00000000u, 0x3E612860u}, /* 12: 0, 0.219880581 */
    {0x00000000u, 0xBF5393ACu}, /* 13: 0, -0.826472044 */
    {0x00000000u, 0xBFE3EA74u}, /* 14: 0, -1.78059244 */
    {0x00000000u, 0xC02BDDDFu}, /* 15: 0, -2.68541694 */
    {0x00000000u, 0xC064C980u}, /* 16: 0, -3.57479858 */
    {0x00000000u, 0xC08E774Eu}, /* 17: 0, -4.45206356 */
    {0x00000000u, 0xC0AA015Eu}, /* 18: 0, -5.31266689 */
    {0x00000000u, 0xC0C4D9E3u}, /* 19: 0, -6.1515975 */
    {0x00000000u, 0xC0DED3FEu}, /* 20: 0, -6.96337795 */
    {0x00000000u, 0xC0F7BF03u}, /* 21: 0, -7.74206686 */
};
#define TABLE_S_CRC32 0x9548F0FEu

/* Table S's spline arrays in writable storage, to corrupt them one at a time. */
typedef struct {
    uint32_t knot_start[S_NS + 1u];
    float knot[S_N_KNOTS];
    uint16_t row_start[S_NS * S_NU + 1u];
    uint8_t col[S_N_ENTRIES];
    uint32_t coef_start[S_NS + 1u];
    float coef[S_N_COEF + 4u]; /* room for a count off by up to 4 */
    uint32_t stage_start[S_NS + 1u];
    stsp_spline_t sp;
} spline_buf_t;

static void spline_buf_init(spline_buf_t *b)
{
    memcpy(b->knot_start, s_knot_start, sizeof b->knot_start);
    memcpy(b->knot, s_knot, sizeof b->knot);
    memcpy(b->row_start, s_row_start, sizeof b->row_start);
    memcpy(b->col, s_col, sizeof b->col);
    memcpy(b->coef_start, s_coef_start, sizeof b->coef_start);
    memset(b->coef, 0, sizeof b->coef);
    memcpy(b->coef, s_coef, sizeof s_coef);
    memcpy(b->stage_start, s_stage_start, sizeof b->stage_start);
    b->sp.n_knots = S_N_KNOTS;
    b->sp.n_entries = S_N_ENTRIES;
    b->sp.n_coef = S_N_COEF;
    b->sp.knot_start = b->knot_start;
    b->sp.knot = b->knot;
    b->sp.row_start = b->row_start;
    b->sp.col = b->col;
    b->sp.coef_start = b->coef_start;
    b->sp.coef = b->coef;
    b->sp.ops = &stsp_spline_ops;
}

/* Table S with spline sp and limits lo/hi, CRC set. */
static stsp_table_t make_s(const stsp_spline_t *sp, const float *lo, const float *hi)
{
    stsp_table_t t = table_header(S_NX, S_NU, S_N_LATCH, S_NS, S_NT, 100u);
    uint32_t i;
    t.stage_start = s_stage_start;
    t.stage_n_latch = s_stage_n_latch;
    t.Lambda = s_Lambda;
    t.lambda0 = s_lambda0;
    t.u_min = lo;
    t.u_max = hi;
    t.u_hold = s_hold;
    t.spline = sp;
    for (i = 0u; i < 32u; ++i) {
        t.problem_sha256[i] = (uint8_t)i;
    }
    t.crc32 = stsp_table_crc32(&t);
    return t;
}

static const stsp_spline_t s_spline = {S_N_KNOTS, S_N_ENTRIES, S_N_COEF, s_knot_start, s_knot,
                                       s_row_start, s_col, s_coef_start, s_coef, &stsp_spline_ops};

/* The state at tick t of the test runs (the same expression in spline_reference.py). */
static void state(uint32_t t, float *x)
{
    x[0] = (float)t * 0.37f - 1.1f;
    x[1] = 0.8f - (float)t * 0.21f;
}

/* ---- Reference evaluations ---------------------------------------------------------------- */

static uint32_t ref_stage(const stsp_table_t *t, uint32_t tick)
{
    uint32_t s = 0u;
    while (((s + 1u) < t->n_stages) && (t->stage_start[s + 1u] <= tick)) {
        ++s;
    }
    return s;
}

/* The span of `tick` (U[sigma + 3] <= tau < U[sigma + 4]) and the first tick after it. */
static uint32_t ref_span(const stsp_table_t *t, uint32_t tick, uint32_t *next)
{
    const stsp_spline_t *sp = t->spline;
    const uint32_t s = ref_stage(t, tick);
    const float *U = &sp->knot[sp->knot_start[s]];
    const uint32_t n_spans = sp->knot_start[s + 1u] - sp->knot_start[s] - 7u;
    const uint32_t first = t->stage_start[s];
    uint32_t sigma = 0u;
    while ((sigma + 1u < n_spans) && ((float)(tick - first) >= U[sigma + 4u])) {
        ++sigma;
    }
    *next = first + (uint32_t)U[sigma + 4u];
    return sigma;
}

/* White box: the span the instance recorded for its last step is the tick's, and it leaves the
 * ordinary path exactly at the span's end (stsp_span_t is private; the tests may look). */
static void check_span(const stsp_ctrl_t *c, const stsp_table_t *t, uint32_t tick)
{
    uint32_t next;
    const uint32_t sigma = ref_span(t, tick, &next);
    assert_int_equal(c->span.span, sigma);
    assert_int_equal(c->span.next, next);
    assert_int_equal(c->stage_end, 0u);
}

/* The spline format's evaluation, literally: A2.2 with its loops and the +0 adds, the folded
 * feed-forward, then the gains of x. */
static void ref_command(const stsp_table_t *t, uint32_t tick, const float *x, const float *v,
                        float *u)
{
    const stsp_spline_t *sp = t->spline;
    const uint32_t s = ref_stage(t, tick);
    const float *U = &sp->knot[sp->knot_start[s]];
    const uint32_t n_spans = sp->knot_start[s + 1u] - sp->knot_start[s] - 7u;
    const float tau = (float)(tick - t->stage_start[s]);
    const float *coef = &sp->coef[sp->coef_start[s]];
    const uint32_t e0 = sp->row_start[s * t->nu];
    float left[4] = {0.0f, 0.0f, 0.0f, 0.0f}, right[4] = {0.0f, 0.0f, 0.0f, 0.0f};
    float N[4] = {1.0f, 0.0f, 0.0f, 0.0f};
    float z[8];
    uint32_t sigma = 0u, i, j, r, e;
    while ((sigma + 1u < n_spans) && !(tau < U[sigma + 4u])) {
        ++sigma;
    }
    i = sigma + 3u;
    for (j = 1u; j <= 3u; ++j) {
        float saved = 0.0f;
        left[j] = tau - U[i + 1u - j];
        right[j] = U[i + j] - tau;
        for (r = 0u; r < j; ++r) {
            const float temp = N[r] / (right[r + 1u] + left[j - r]);
            N[r] = saved + right[r + 1u] * temp;
            saved = left[j - r] * temp;
        }
        N[j] = saved;
    }
    for (j = 0u; j < t->nx; ++j) {
        z[j] = x[j];
    }
    z[t->nx] = 1.0f;
    for (j = 0u; j < t->n_latch; ++j) {
        z[t->nx + 1u + j] = v[j];
    }
    for (i = 0u; i < t->nu; ++i) {
        /* k0[i] + L[i] v folded into one spline (+0 - c z per coefficient over the entries
         * with an operand beyond x, in stored order), whose value starts the command; then
         * the gains of x. */
        float fold[4] = {0.0f, 0.0f, 0.0f, 0.0f};
        float acc, g;
        for (e = sp->row_start[s * t->nu + i]; e < sp->row_start[s * t->nu + i + 1u]; ++e) {
            const float *c = &coef[(e - e0) * (n_spans + 3u) + sigma];
            if (sp->col[e] >= t->nx) {
                for (r = 0u; r < 4u; ++r) {
                    fold[r] = fold[r] - c[r] * z[sp->col[e]];
                }
            }
        }
        acc = N[0] * fold[0];
        acc = acc + N[1] * fold[1];
        acc = acc + N[2] * fold[2];
        acc = acc + N[3] * fold[3];
        for (e = sp->row_start[s * t->nu + i]; e < sp->row_start[s * t->nu + i + 1u]; ++e) {
            const float *c = &coef[(e - e0) * (n_spans + 3u) + sigma];
            if (sp->col[e] < t->nx) {
                g = N[0] * c[0];
                g = g + N[1] * c[1];
                g = g + N[2] * c[2];
                g = g + N[3] * c[3];
                acc = acc - g * z[sp->col[e]];
            }
        }
        u[i] = acc;
    }
}

/* The latch of stage s, in the firmware's order (lambda0 + Lambda[0] x[0] + ...). */
static void ref_latch(const stsp_table_t *t, uint32_t s, const float *x, float *v)
{
    uint32_t c, j;
    for (c = 0u; c < t->n_latch; ++c) {
        float acc = 0.0f;
        if (c < t->stage_n_latch[s]) {
            acc = t->lambda0[s * t->n_latch + c];
            for (j = 0u; j < t->nx; ++j) {
                acc += t->Lambda[(s * t->n_latch + c) * t->nx + j] * x[j];
            }
        }
        v[c] = acc;
    }
}

/* B-spline k of degree p on knots U at tau by the Cox-de Boor recursion, in double (0/0 = 0),
 * with the last span closed at its right end. */
static double cox_de_boor(const float *U, uint32_t n_knots, uint32_t k, uint32_t p, double tau)
{
    double a = 0.0, b = 0.0;
    if (p == 0u) {
        const int last = (U[k + 1u] == U[n_knots - 1u]) && (tau == (double)U[n_knots - 1u]);
        return (((double)U[k] <= tau) && ((tau < (double)U[k + 1u]) || last) &&
                (U[k] < U[k + 1u]))
                   ? 1.0
                   : 0.0;
    }
    if (U[k + p] > U[k]) {
        a = (tau - U[k]) / ((double)U[k + p] - U[k]) * cox_de_boor(U, n_knots, k, p - 1u, tau);
    }
    if (U[k + p + 1u] > U[k + 1u]) {
        b = ((double)U[k + p + 1u] - tau) / ((double)U[k + p + 1u] - U[k + 1u]) *
            cox_de_boor(U, n_knots, k + 1u, p - 1u, tau);
    }
    return a + b;
}

/* The command in double: every B-spline of the stage, summed. */
static void ref_command_double(const stsp_table_t *t, uint32_t tick, const float *x,
                               const float *v, double *u)
{
    const stsp_spline_t *sp = t->spline;
    const uint32_t s = ref_stage(t, tick);
    const float *U = &sp->knot[sp->knot_start[s]];
    const uint32_t n_knots = sp->knot_start[s + 1u] - sp->knot_start[s];
    const uint32_t n_coef = n_knots - 4u;
    const double tau = (double)(tick - t->stage_start[s]);
    const float *coef = &sp->coef[sp->coef_start[s]];
    const uint32_t e0 = sp->row_start[s * t->nu];
    uint32_t i, e, k;
    for (i = 0u; i < t->nu; ++i) {
        double acc = 0.0;
        for (e = sp->row_start[s * t->nu + i]; e < sp->row_start[s * t->nu + i + 1u]; ++e) {
            const uint32_t j = sp->col[e];
            const double zj = (j < t->nx) ? x[j] : ((j == t->nx) ? 1.0 : v[j - t->nx - 1u]);
            double g = 0.0;
            for (k = 0u; k < n_coef; ++k) {
                g += (double)coef[(e - e0) * n_coef + k] * cox_de_boor(U, n_knots, k, 3u, tau);
            }
            acc -= g * zj;
        }
        u[i] = acc;
    }
}

/* ---- A model of the step contract for spline tables, to compare whole runs ---------------- */

typedef struct {
    uint32_t next;
    uint32_t stage;
    int latched;
    float v[S_N_LATCH];
} model_t;

static int all_finite(const float *a, uint32_t n)
{
    uint32_t i;
    for (i = 0u; i < n; ++i) {
        if (!isfinite(a[i])) {
            return 0;
        }
    }
    return 1;
}

/* What stsp_step must return and write for table t (S's shape) from model state m. */
static stsp_status_t model_step(const stsp_table_t *t, model_t *m, uint32_t tick, const float *x,
                                float *u, uint16_t *sat_mask)
{
    stsp_status_t st = STSP_OK;
    float v_new[S_N_LATCH];
    uint32_t s, i;
    int relatch;
    uint16_t mask = 0u;
    if (tick >= t->n_ticks) {
        return STSP_ERR_TICK_RANGE;
    }
    if ((m->next > 0u) && ((tick + 1u) < m->next)) {
        return STSP_ERR_TICK_ORDER;
    }
    if ((m->next > 0u) && ((tick + 1u) == m->next)) {
        st = STSP_WARN_TICK_REPEATED;
    }
    if (tick > m->next) {
        st = STSP_WARN_TICK_SKIPPED;
    }
    s = ref_stage(t, tick);
    relatch = !m->latched || ((s != m->stage) && (t->stage_n_latch[s] > 0u));
    if (relatch) {
        ref_latch(t, s, x, v_new);
    } else {
        memcpy(v_new, m->v, sizeof v_new);
    }
    if (!all_finite(x, t->nx)) {
        return STSP_ERR_NONFINITE_STATE;
    }
    if (!all_finite(v_new, t->n_latch)) {
        return STSP_ERR_NONFINITE_OUTPUT;
    }
    ref_command(t, tick, x, v_new, u);
    if (!all_finite(u, t->nu)) {
        return STSP_ERR_NONFINITE_OUTPUT;
    }
    for (i = 0u; i < t->nu; ++i) {
        if (u[i] > t->u_max[i]) {
            u[i] = t->u_max[i];
            mask = (uint16_t)(mask | (1u << i));
        } else if (u[i] < t->u_min[i]) {
            u[i] = t->u_min[i];
            mask = (uint16_t)(mask | (1u << i));
        }
    }
    if (mask != 0u) {
        st = STSP_WARN_SATURATED;
        *sat_mask = mask;
    }
    if (relatch) {
        memcpy(m->v, v_new, sizeof v_new);
        m->latched = 1;
    }
    m->stage = s;
    if ((tick + 1u) > m->next) {
        m->next = tick + 1u;
    }
    return st;
}

/* One step of the controller against the model: status, command bits, the read-only fields,
 * and on an error u_hold and the instance unchanged. */
static void check_step(stsp_ctrl_t *c, const stsp_table_t *t, model_t *m, uint32_t tick,
                       const float *x)
{
    stsp_ctrl_t before;
    float u[S_NU] = {42.0f, 42.0f}, want[S_NU] = {0.0f, 0.0f};
    uint16_t mask = 0u;
    stsp_status_t st, expect;
    uint32_t i;
    memcpy(&before, c, sizeof before);
    expect = model_step(t, m, tick, x, want, &mask);
    st = stsp_step(c, tick, x, u);
    assert_int_equal(st, expect);
    if (st < STSP_OK) {
        for (i = 0u; i < S_NU; ++i) {
            assert_int_equal(f32_bits(u[i]), f32_bits(t->u_hold[i]));
        }
        assert_memory_equal(&before, c, sizeof before);
        return;
    }
    for (i = 0u; i < S_NU; ++i) {
        assert_int_equal(f32_bits(u[i]), f32_bits(want[i]));
    }
    if (st == STSP_WARN_SATURATED) {
        assert_int_equal(c->sat_mask, mask);
    }
    assert_int_equal(c->next_tick, m->next);
    assert_int_equal(c->stage, m->stage);
    check_span(c, t, tick);
}

static stsp_table_t table_s;
static stsp_ctrl_t ctrl;

static int setup(void **state_)
{
    (void)state_;
    table_s = make_s(&s_spline, s_no_min, s_no_max);
    return (stsp_init(&ctrl, &table_s) == STSP_OK) ? 0 : -1;
}

/* ---- Tests -------------------------------------------------------------------------------- */

/* The serialization of a spline table (after u_hold: counts, index arrays as u32, knots and
 * coefficients as binary32; no K, k0, L) as spline_reference.py computes it with zlib. */
static void test_crc_pinned(void **state_)
{
    (void)state_;
    assert_int_equal(table_s.crc32, TABLE_S_CRC32);
    assert_int_equal(stsp_table_crc32(&table_s), TABLE_S_CRC32);
}

/* Ticks 0..21 in order: span changes at 3, 7, 15; stage change and latch at 10. */
static void test_run_matches_references(void **state_)
{
    float x[S_NX], u[S_NU], want[S_NU], v[S_N_LATCH] = {0.0f, 0.0f};
    double dbl[S_NU];
    uint32_t tick, i;
    (void)state_;
    for (tick = 0u; tick < S_NT; ++tick) {
        state(tick, x);
        if ((tick == 0u) || (tick == 10u)) {
            ref_latch(&table_s, (tick == 0u) ? 0u : 1u, x, v);
        }
        assert_int_equal(stsp_step(&ctrl, tick, x, u), STSP_OK);
        ref_command(&table_s, tick, x, v, want);
        ref_command_double(&table_s, tick, x, v, dbl);
        for (i = 0u; i < S_NU; ++i) {
            assert_int_equal(f32_bits(u[i]), SPLINE_EXPECTED_BITS[tick][i]);
            assert_int_equal(f32_bits(u[i]), f32_bits(want[i]));
            assert_true(fabs((double)u[i] - dbl[i]) <= 1e-5 * (1.0 + fabs(dbl[i])));
        }
        assert_int_equal(ctrl.stage, (tick < 10u) ? 0u : 1u);
        assert_int_equal(ctrl.next_tick, tick + 1u);
        assert_int_equal(ctrl.latched, 1u);
        check_span(&ctrl, &table_s, tick);
    }
    /* Unused entries are zero, not NaN: input 0 has no entry in stage 1. */
    assert_int_equal(f32_bits(u[0]), 0u);
}

/* Skips (the span found by search from the stage's first span or the current one), a stage
 * entered late (latched at that tick), repeats on and after span boundaries, the last tick,
 * backwards: each against the model. */
static void test_skips_and_repeats(void **state_)
{
    static const uint32_t runs[][12] = {
        {0u, 8u, 9u, 15u, 16u, 16u, 17u, 21u, 21u, 20u, 22u, 21u},
        {0u, 1u, 2u, 3u, 3u, 4u, 7u, 7u, 6u, 14u, 15u, 15u},
        {5u, 6u, 2u, 9u, 10u, 10u, 11u, 12u, 13u, 14u, 19u, 20u},
        {21u, 0u, 21u, 20u, 21u, 22u, 4000000000u, 21u, 21u, 21u, 21u, 21u},
        {9u, 10u, 9u, 11u, 12u, 13u, 14u, 15u, 16u, 17u, 18u, 19u},
    };
    uint32_t r, k;
    (void)state_;
    for (r = 0u; r < sizeof runs / sizeof runs[0]; ++r) {
        stsp_ctrl_t c;
        model_t m;
        memset(&m, 0, sizeof m);
        assert_int_equal(stsp_init(&c, &table_s), STSP_OK);
        for (k = 0u; k < 12u; ++k) {
            float x[S_NX];
            state(runs[r][k] % 64u, x);
            x[0] += 0.01f * (float)k; /* a new state on repeats */
            check_step(&c, &table_s, &m, runs[r][k], x);
        }
    }
}

/* A seeded random walk over ticks (in order, repeated, skipped, backwards, past the end) and
 * states (NaN, Inf, huge, subnormal), with and without limits, against the model. */
static void test_random_walk(void **state_)
{
    static const float limits[2][2][S_NU] = {{{-FLT_MAX, -FLT_MAX}, {FLT_MAX, FLT_MAX}},
                                             {{-0.25f, -1.0f}, {0.5f, 1.0f}}};
    uint32_t seed = 12345u, lim, n;
    (void)state_;
    for (lim = 0u; lim < 2u; ++lim) {
        const stsp_table_t t = make_s(&s_spline, limits[lim][0], limits[lim][1]);
        stsp_ctrl_t c;
        model_t m;
        uint32_t tick = 0u;
        memset(&m, 0, sizeof m);
        assert_int_equal(stsp_init(&c, &t), STSP_OK);
        for (n = 0u; n < 20000u; ++n) {
            float x[S_NX];
            uint32_t move;
            seed = seed * 1103515245u + 12345u;
            move = (seed >> 16) % 16u;
            if (move < 9u) {
                tick = tick + 1u;
            } else if (move < 11u) {
                tick = (tick > 0u) ? tick - 1u : 0u;
            } else if (move < 13u) {
                tick = tick + 1u + ((seed >> 8) % 6u);
            } else if (move == 13u) {
                tick = (seed >> 4) % 24u;
            } else if (move == 14u) {
                (void)stsp_reset(&c);
                memset(&m, 0, sizeof m);
                tick = 0u;
            } else {
                tick = tick + 2u;
            }
            state(tick % 23u, x);
            switch ((seed >> 20) % 24u) {
            case 0u: x[(seed >> 3) & 1u] = NAN; break;
            case 1u: x[(seed >> 3) & 1u] = INFINITY; break;
            case 2u: x[(seed >> 3) & 1u] = -INFINITY; break;
            case 3u: x[(seed >> 3) & 1u] = 3e37f; break;
            case 4u: x[0] = 3e38f; x[1] = 3e38f; break;
            case 5u: x[(seed >> 3) & 1u] = 1e-40f; break;
            default: break;
            }
            check_step(&c, &t, &m, tick, x);
            if (tick > 30u) {
                tick = 0u;
                (void)stsp_reset(&c);
                memset(&m, 0, sizeof m);
            }
        }
    }
}

/* After the last tick: STSP_ERR_TICK_RANGE, u_hold, instance unchanged; the last tick again is
 * a repeat. */
static void test_tick_range_end(void **state_)
{
    float x[S_NX], u[S_NU];
    stsp_ctrl_t before;
    uint32_t tick;
    (void)state_;
    for (tick = 0u; tick < S_NT; ++tick) {
        state(tick, x);
        assert_int_equal(stsp_step(&ctrl, tick, x, u), STSP_OK);
    }
    memcpy(&before, &ctrl, sizeof before);
    assert_int_equal(stsp_step(&ctrl, S_NT, x, u), STSP_ERR_TICK_RANGE);
    assert_int_equal(f32_bits(u[0]), f32_bits(s_hold[0]));
    assert_int_equal(f32_bits(u[1]), f32_bits(s_hold[1]));
    assert_memory_equal(&before, &ctrl, sizeof before);
    assert_int_equal(stsp_step(&ctrl, S_NT - 1u, x, u), STSP_WARN_TICK_REPEATED);
    assert_int_equal(f32_bits(u[1]), SPLINE_EXPECTED_BITS[S_NT - 1u][1]);
    /* reset: the plan again from tick 0, bit for bit */
    assert_int_equal(stsp_reset(&ctrl), STSP_OK);
    state(0u, x);
    assert_int_equal(stsp_step(&ctrl, 0u, x, u), STSP_OK);
    assert_int_equal(f32_bits(u[0]), SPLINE_EXPECTED_BITS[0][0]);
}

/* A NaN or Inf in a state entry that no input of the stage uses (x[1] in stage 0) is still
 * STSP_ERR_NONFINITE_STATE, on ordinary, span-start, latch and skipped ticks; and a latch that
 * overflows in a multiplier no input uses (v[1] in stage 1) is STSP_ERR_NONFINITE_OUTPUT. */
static void test_nonfinite_unused_operands(void **state_)
{
    static const float bad[3] = {NAN, INFINITY, -INFINITY};
    /* ticks stepped before, then the tick: the latch, ordinary, a span's first, ordinary, a
     * skip */
    static const uint32_t before_tick[5][2] = {{0u, 0u}, {1u, 1u}, {3u, 3u}, {5u, 5u},
                                               {2u, 6u}};
    float x[S_NX], u[S_NU];
    uint32_t b, p, t;
    (void)state_;
    for (b = 0u; b < 3u; ++b) {
        for (p = 0u; p < 5u; ++p) {
            stsp_ctrl_t c, before;
            const uint32_t tick = before_tick[p][1];
            assert_int_equal(stsp_init(&c, &table_s), STSP_OK);
            for (t = 0u; t < before_tick[p][0]; ++t) {
                state(t, x);
                assert_int_equal(stsp_step(&c, t, x, u), STSP_OK);
            }
            state(tick, x);
            x[1] = bad[b];
            memcpy(&before, &c, sizeof before);
            assert_int_equal(stsp_step(&c, tick, x, u), STSP_ERR_NONFINITE_STATE);
            assert_int_equal(f32_bits(u[0]), f32_bits(s_hold[0]));
            assert_memory_equal(&before, &c, sizeof before);
        }
    }
    {
        stsp_ctrl_t c, before;
        float want[S_NU], v[S_N_LATCH];
        assert_int_equal(stsp_init(&c, &table_s), STSP_OK);
        for (t = 0u; t < 10u; ++t) {
            state(t, x);
            assert_int_equal(stsp_step(&c, t, x, u), STSP_OK);
        }
        x[0] = 3e37f; /* v[1] = -0.2 + 100 x[0] overflows; v[0] and the command do not */
        x[1] = 0.0f;
        ref_latch(&table_s, 1u, x, v);
        assert_true(isfinite(v[0]) && isinf(v[1]));
        v[1] = 0.0f;
        ref_command(&table_s, 10u, x, v, want);
        assert_true(isfinite(want[0]) && isfinite(want[1]));
        memcpy(&before, &c, sizeof before);
        assert_int_equal(stsp_step(&c, 10u, x, u), STSP_ERR_NONFINITE_OUTPUT);
        assert_int_equal(f32_bits(u[1]), f32_bits(s_hold[1]));
        assert_memory_equal(&before, &c, sizeof before);
    }
}

/* Limits: clamped, STSP_WARN_SATURATED with sat_mask, on ordinary and cold ticks. */
static void test_saturation(void **state_)
{
    const stsp_table_t t = make_s(&s_spline, s_tight_min, s_tight_max);
    stsp_ctrl_t c;
    model_t m;
    uint32_t tick, saturated = 0u;
    (void)state_;
    memset(&m, 0, sizeof m);
    assert_int_equal(stsp_init(&c, &t), STSP_OK);
    for (tick = 0u; tick < S_NT; ++tick) {
        float x[S_NX], want[S_NU];
        model_t peek = m;
        uint16_t mask = 0u;
        state(tick, x);
        if (model_step(&t, &peek, tick, x, want, &mask) == STSP_WARN_SATURATED) {
            ++saturated;
        }
        check_step(&c, &t, &m, tick, x);
    }
    assert_true(saturated >= 5u);
}

/* x and u in one buffer: the same status and command as separate buffers. */
static void test_state_and_command_share_a_buffer(void **state_)
{
    stsp_ctrl_t c;
    uint32_t tick;
    (void)state_;
    assert_int_equal(stsp_init(&c, &table_s), STSP_OK);
    for (tick = 0u; tick < S_NT; ++tick) {
        float xu[S_NX];
        state(tick, xu);
        assert_int_equal(stsp_step(&c, tick, xu, xu), STSP_OK);
        assert_int_equal(f32_bits(xu[0]), SPLINE_EXPECTED_BITS[tick][0]);
        assert_int_equal(f32_bits(xu[1]), SPLINE_EXPECTED_BITS[tick][1]);
    }
}

/* init with table S changed by `change`: the expected status, instance not ready. */
typedef void (*change_fn)(stsp_table_t *t, spline_buf_t *b);

static void expect_init(change_fn change, stsp_status_t expect, int recompute_crc)
{
    spline_buf_t b;
    stsp_table_t t;
    stsp_ctrl_t c;
    float x[S_NX] = {0.0f, 0.0f}, u[S_NU];
    spline_buf_init(&b);
    t = make_s(&b.sp, s_no_min, s_no_max);
    change(&t, &b);
    if (recompute_crc) {
        t.crc32 = stsp_table_crc32(&t);
    }
    assert_int_equal(stsp_init(&c, &t), expect);
    if (expect != STSP_OK) {
        assert_int_equal(stsp_step(&c, 0u, x, u), STSP_ERR_NOT_INITIALIZED);
    }
}

static const float any_gain[S_NT * S_NU * S_NX] = {0.0f};
static const double band_Nt[2] = {1.0, 0.0}, band_one[1] = {1.0}, band_lo[1] = {-1.0};
static const stsp_bandqp_t a_band = {1u, 2u, band_Nt, band_one, band_one, band_lo, band_one, stsp_bandqp_solve_f32};

static void ch_none(stsp_table_t *t, spline_buf_t *b) { (void)t; (void)b; }
static void ch_band(stsp_table_t *t, spline_buf_t *b) { (void)b; t->band_qp = &a_band; }
static void ch_K(stsp_table_t *t, spline_buf_t *b) { (void)b; t->K = any_gain; }
static void ch_k0(stsp_table_t *t, spline_buf_t *b) { (void)b; t->k0 = any_gain; }
static void ch_L(stsp_table_t *t, spline_buf_t *b) { (void)b; t->L = any_gain; }
static void ch_null_knot_start(stsp_table_t *t, spline_buf_t *b)
{
    (void)t;
    b->sp.knot_start = NULL;
}
static void ch_null_knot(stsp_table_t *t, spline_buf_t *b) { (void)t; b->sp.knot = NULL; }
static void ch_null_row_start(stsp_table_t *t, spline_buf_t *b) { (void)t; b->sp.row_start = NULL; }
static void ch_null_col(stsp_table_t *t, spline_buf_t *b) { (void)t; b->sp.col = NULL; }
static void ch_null_coef_start(stsp_table_t *t, spline_buf_t *b)
{
    (void)t;
    b->sp.coef_start = NULL;
}
static void ch_null_coef(stsp_table_t *t, spline_buf_t *b) { (void)t; b->sp.coef = NULL; }
static void ch_null_Lambda(stsp_table_t *t, spline_buf_t *b) { (void)b; t->Lambda = NULL; }
static void ch_knot_start0(stsp_table_t *t, spline_buf_t *b) { (void)t; b->knot_start[0] = 1u; }
static void ch_knot_start_end(stsp_table_t *t, spline_buf_t *b) { (void)t; b->sp.n_knots = 18u; }
static void ch_knot_start_down(stsp_table_t *t, spline_buf_t *b)
{
    (void)t;
    b->knot_start[1] = 25u; /* stage 0 would read past the knots (19) */
}
static void ch_short_knots(stsp_table_t *t, spline_buf_t *b)
{
    (void)t;
    b->knot_start[1] = 7u; /* stage 0: 7 knots, stage 1: 12 */
}
static void ch_knot_first(stsp_table_t *t, spline_buf_t *b) { (void)t; b->knot[2] = 1.0f; }
static void ch_knot_last(stsp_table_t *t, spline_buf_t *b) { (void)t; b->knot[8] = 9.0f; }
static void ch_knot_end_T(stsp_table_t *t, spline_buf_t *b)
{
    (void)t; /* stage 1's last four 11, not its tick count 12 */
    b->knot[15] = 11.0f; b->knot[16] = 11.0f; b->knot[17] = 11.0f; b->knot[18] = 11.0f;
}
static void ch_knot_order(stsp_table_t *t, spline_buf_t *b) { (void)t; b->knot[5] = 3.0f; }
static void ch_knot_zero(stsp_table_t *t, spline_buf_t *b) { (void)t; b->knot[4] = 0.0f; }
static void ch_knot_at_T(stsp_table_t *t, spline_buf_t *b) { (void)t; b->knot[5] = 10.0f; }
static void ch_knot_fraction(stsp_table_t *t, spline_buf_t *b) { (void)t; b->knot[5] = 6.5f; }
static void ch_knot_nan(stsp_table_t *t, spline_buf_t *b) { (void)t; b->knot[14] = NAN; }
static void ch_knot_neg_zero(stsp_table_t *t, spline_buf_t *b) { (void)t; b->knot[0] = -0.0f; }
static void ch_row_start0(stsp_table_t *t, spline_buf_t *b) { (void)t; b->row_start[0] = 1u; }
static void ch_row_start_down(stsp_table_t *t, spline_buf_t *b) { (void)t; b->row_start[2] = 2u; }
static void ch_row_start_end(stsp_table_t *t, spline_buf_t *b) { (void)t; b->sp.n_entries = 7u; }
static void ch_col(stsp_table_t *t, spline_buf_t *b) { (void)t; b->col[5] = 5u; }
/* Within a row the operands must increase: x's gains, then k0, then L (stage 0, input 0 is
 * [0, 2, 3]; stage 1, input 1 [0, 1, 2, 3]). */
static void ch_col_order(stsp_table_t *t, spline_buf_t *b) { (void)t; b->col[1] = 4u; }
static void ch_col_twice(stsp_table_t *t, spline_buf_t *b) { (void)t; b->col[5] = 0u; }
static void ch_col_x_last(stsp_table_t *t, spline_buf_t *b)
{
    (void)t;
    b->col[6] = 3u;
    b->col[7] = 1u;
}
static void ch_coef_start0(stsp_table_t *t, spline_buf_t *b) { (void)t; b->coef_start[0] = 1u; }
static void ch_coef_start_end(stsp_table_t *t, spline_buf_t *b) { (void)t; b->sp.n_coef = 43u; }
static void ch_coef_start_down(stsp_table_t *t, spline_buf_t *b)
{
    (void)t;
    b->coef_start[1] = 50u;
}
static void ch_coef_count(stsp_table_t *t, spline_buf_t *b)
{
    (void)t; /* stage 0 with 23 coefficients, stage 1 with 21: totals right, stages not */
    b->coef_start[1] = 23u;
}
static void ch_coef_remainder(stsp_table_t *t, spline_buf_t *b)
{
    (void)t; /* stage 1 with 21 coefficients: 4 entries x 5 and one more */
    b->coef_start[2] = 45u;
    b->sp.n_coef = 45u;
}
static void ch_coef_nan(stsp_table_t *t, spline_buf_t *b) { (void)t; b->coef[30] = NAN; }
static void ch_coef_inf(stsp_table_t *t, spline_buf_t *b) { (void)t; b->coef[0] = -INFINITY; }
static void ch_Lambda_nan(stsp_table_t *t, spline_buf_t *b)
{
    static const float bad[S_NS * S_N_LATCH * S_NX] = {0.5f, NAN, 0.0f, 0.0f,
                                                       -1.0f, 0.75f, 100.0f, 2.0f};
    (void)b;
    t->Lambda = bad;
}
static void ch_stage_too_long(stsp_table_t *t, spline_buf_t *b)
{
    /* stage 1 of 2^24 ticks: its knots are not exact integers beyond 2^24 */
    b->stage_start[2] = 10u + 16777216u;
    b->knot[15] = 16777216.0f; b->knot[16] = 16777216.0f; b->knot[17] = 16777216.0f;
    b->knot[18] = 16777216.0f;
    t->stage_start = b->stage_start;
    t->n_ticks = b->stage_start[2];
}
static void ch_stage_longest(stsp_table_t *t, spline_buf_t *b)
{
    /* 2^24 - 1 ticks: accepted (no per-tick arrays, whatever n_ticks) */
    b->stage_start[2] = 10u + 16777215u;
    b->knot[15] = 16777215.0f; b->knot[16] = 16777215.0f; b->knot[17] = 16777215.0f;
    b->knot[18] = 16777215.0f;
    t->stage_start = b->stage_start;
    t->n_ticks = b->stage_start[2];
}

/* A spline band table (format 5 with a band dual): table S latching both multipliers once, at
 * stage 0, through a non-symmetric band dual (W = [[2, 1], [0, 1]], triangular with a
 * positive diagonal: a P-matrix; row 0 the equality 0.5, row 1 the band [-1, 1]; e = x0).
 * From x0 = (1.5, 3) by hand: row 1 inactive gives y1 = 3 > 1; at its lower bound lam1 = 4 > 0
 * (wrong sign); at its upper bound W lam = (1, 2): lam = (-0.5, 2). Every command of the run
 * equals, bit for bit, that of the same spline table without the band dual whose stage-0
 * latch is the constant v = (-0.5, 2); the band table's CRC covers the dual (W changed: a
 * different CRC). A table latching at two stages is refused (ch_band, test_init_refusals). */
static const uint16_t sb_n_latch[S_NS] = {2u, 0u};
static const double sb_Nt[4] = {1.0, 0.0, 0.0, 1.0}, sb_mt[2] = {0.0, 0.0};
static const double sb_W[4] = {2.0, 1.0, 0.0, 1.0}, sb_W_other[4] = {2.0, 1.0, 0.0, 1.5};
static const double sb_lo[2] = {0.5, -1.0}, sb_hi[2] = {0.5, 1.0};
static const float sb_Lambda[S_NS * S_N_LATCH * S_NX] = {0.0f,  0.0f,  0.0f,   0.0f,
                                                         -1.0f, 0.75f, 100.0f, 2.0f};
static const float sb_lambda0[S_NS * S_N_LATCH] = {-0.5f, 2.0f, 0.3f, -0.2f};

static void test_spline_band_table(void **state_)
{
    const stsp_bandqp_t qp = {2u, S_NX, sb_Nt, sb_mt, sb_W, sb_lo, sb_hi, stsp_bandqp_solve_f32};
    const stsp_bandqp_t other = {2u, S_NX, sb_Nt, sb_mt, sb_W_other, sb_lo, sb_hi, stsp_bandqp_solve_f32};
    stsp_table_t band = make_s(&s_spline, s_no_min, s_no_max);
    stsp_table_t plain = make_s(&s_spline, s_no_min, s_no_max);
    stsp_ctrl_t cb, cp;
    float x[S_NX], ub[S_NU], up[S_NU];
    uint32_t tick, i, crc;
    (void)state_;
    band.stage_n_latch = sb_n_latch;
    band.band_qp = &qp;
    band.crc32 = stsp_table_crc32(&band);
    plain.stage_n_latch = sb_n_latch;
    plain.Lambda = sb_Lambda;
    plain.lambda0 = sb_lambda0;
    plain.crc32 = stsp_table_crc32(&plain);
    assert_int_equal(stsp_init(&cb, &band), STSP_OK);
    assert_int_equal(stsp_init(&cp, &plain), STSP_OK);
    for (tick = 0u; tick < S_NT; ++tick) {
        if (tick == 0u) {
            x[0] = 1.5f;
            x[1] = 3.0f;
        } else {
            state(tick, x);
        }
        assert_int_equal(stsp_step(&cb, tick, x, ub), STSP_OK);
        assert_int_equal(stsp_step(&cp, tick, x, up), STSP_OK);
        for (i = 0u; i < S_NU; ++i) {
            assert_int_equal(f32_bits(ub[i]), f32_bits(up[i]));
        }
        assert_true((cb.v[0] == -0.5f) && (cb.v[1] == 2.0f));
    }
    crc = band.crc32;
    band.band_qp = &other;
    assert_int_not_equal(stsp_table_crc32(&band), crc);
    assert_int_equal(stsp_init(&cb, &band), STSP_ERR_BAD_CRC);
}

/* Every refusal of a spline table's layout and values, each with its status; the CRC is
 * recomputed (but over NULL arrays: stsp_table_crc32() needs valid ones, and init refuses
 * them before the CRC), so the status is the check's. */
static void test_init_refusals(void **state_)
{
    static const struct {
        change_fn change;
        stsp_status_t expect;
    } cases[] = {
        {ch_none, STSP_OK},
        {ch_band, STSP_ERR_BAD_DIMS}, /* a band dual, but table S latches at stage 1 too */
        {ch_K, STSP_ERR_BAD_DIMS},
        {ch_k0, STSP_ERR_BAD_DIMS},
        {ch_L, STSP_ERR_BAD_DIMS},
        {ch_null_knot_start, STSP_ERR_NULL},
        {ch_null_knot, STSP_ERR_NULL},
        {ch_null_row_start, STSP_ERR_NULL},
        {ch_null_col, STSP_ERR_NULL},
        {ch_null_coef_start, STSP_ERR_NULL},
        {ch_null_coef, STSP_ERR_NULL},
        {ch_null_Lambda, STSP_ERR_NULL},
        {ch_knot_start0, STSP_ERR_BAD_DIMS},
        {ch_knot_start_end, STSP_ERR_BAD_DIMS},
        {ch_knot_start_down, STSP_ERR_BAD_DIMS},
        {ch_short_knots, STSP_ERR_BAD_DIMS},
        {ch_knot_first, STSP_ERR_BAD_DIMS},
        {ch_knot_last, STSP_ERR_BAD_DIMS},
        {ch_knot_end_T, STSP_ERR_BAD_DIMS},
        {ch_knot_order, STSP_ERR_BAD_DIMS},
        {ch_knot_zero, STSP_ERR_BAD_DIMS},
        {ch_knot_at_T, STSP_ERR_BAD_DIMS},
        {ch_knot_fraction, STSP_ERR_BAD_DIMS},
        {ch_knot_nan, STSP_ERR_BAD_DIMS},
        {ch_knot_neg_zero, STSP_OK}, /* -0 == 0: the same basis, bit for bit */
        {ch_row_start0, STSP_ERR_BAD_DIMS},
        {ch_row_start_down, STSP_ERR_BAD_DIMS},
        {ch_row_start_end, STSP_ERR_BAD_DIMS},
        {ch_col, STSP_ERR_BAD_DIMS},
        {ch_col_order, STSP_ERR_BAD_DIMS},
        {ch_col_twice, STSP_ERR_BAD_DIMS},
        {ch_col_x_last, STSP_ERR_BAD_DIMS},
        {ch_coef_start0, STSP_ERR_BAD_DIMS},
        {ch_coef_start_end, STSP_ERR_BAD_DIMS},
        {ch_coef_start_down, STSP_ERR_BAD_DIMS},
        {ch_coef_count, STSP_ERR_BAD_DIMS},
        {ch_coef_remainder, STSP_ERR_BAD_DIMS},
        {ch_coef_nan, STSP_ERR_BAD_VALUES},
        {ch_coef_inf, STSP_ERR_BAD_VALUES},
        {ch_Lambda_nan, STSP_ERR_BAD_VALUES},
        {ch_stage_too_long, STSP_ERR_BAD_DIMS},
        {ch_stage_longest, STSP_OK},
    };
    uint32_t i;
    (void)state_;
    for (i = 0u; i < sizeof cases / sizeof cases[0]; ++i) {
        print_message("case %u\n", (unsigned)i);
        expect_init(cases[i].change, cases[i].expect, cases[i].expect != STSP_ERR_NULL);
    }
}

/* A stage of 2^24 - 1 ticks (n_ticks far beyond any per-tick table): a skip to its last tick
 * evaluates the last span. */
static void test_long_stage(void **state_)
{
    spline_buf_t b;
    stsp_table_t t;
    stsp_ctrl_t c;
    float x[S_NX], u[S_NU], want[S_NU], v[S_N_LATCH];
    (void)state_;
    spline_buf_init(&b);
    t = make_s(&b.sp, s_no_min, s_no_max);
    ch_stage_longest(&t, &b);
    b.knot[14] = 8000000.0f; /* stage 1's interior knot */
    t.crc32 = stsp_table_crc32(&t);
    assert_int_equal(stsp_init(&c, &t), STSP_OK);
    state(0u, x);
    assert_int_equal(stsp_step(&c, 0u, x, u), STSP_OK);
    state(3u, x);
    assert_int_equal(stsp_step(&c, t.n_ticks - 1u, x, u), STSP_WARN_TICK_SKIPPED);
    ref_latch(&t, 1u, x, v);
    ref_command(&t, t.n_ticks - 1u, x, v, want);
    assert_int_equal(f32_bits(u[1]), f32_bits(want[1]));
    assert_int_equal(stsp_step(&c, t.n_ticks, x, u), STSP_ERR_TICK_RANGE);
}

/* A coefficient or a knot changed (still a valid layout) without a new CRC: STSP_ERR_BAD_CRC. */
static void ch_coef_value(stsp_table_t *t, spline_buf_t *b) { (void)t; b->coef[40] = 1.25f; }
static void ch_knot_value(stsp_table_t *t, spline_buf_t *b) { (void)t; b->knot[4] = 4.0f; }
static void ch_col_value(stsp_table_t *t, spline_buf_t *b) { (void)t; b->col[1] = 1u; }
static void test_crc_mismatch(void **state_)
{
    (void)state_;
    expect_init(ch_coef_value, STSP_ERR_BAD_CRC, 0);
    expect_init(ch_knot_value, STSP_ERR_BAD_CRC, 0);
    expect_init(ch_col_value, STSP_ERR_BAD_CRC, 0);
    expect_init(ch_knot_value, STSP_OK, 1);
}

/* stsp_verify(): a changed spline header (a count, an address, the code pointer, the table's
 * spline pointer, even to an equal copy) is STSP_ERR_TABLE_CHANGED; changed spline data STSP_ERR_BAD_CRC; both
 * stop the instance, whose steps then write u_hold. */
static void test_verify_spline_header(void **state_)
{
    uint32_t k;
    (void)state_;
    for (k = 0u; k < 13u; ++k) {
        spline_buf_t b;
        stsp_spline_t copy;
        stsp_table_t t;
        stsp_ctrl_t c;
        float x[S_NX], u[S_NU];
        stsp_status_t expect = STSP_ERR_TABLE_CHANGED;
        spline_buf_init(&b);
        t = make_s(&b.sp, s_no_min, s_no_max);
        assert_int_equal(stsp_init(&c, &t), STSP_OK);
        state(0u, x);
        assert_int_equal(stsp_step(&c, 0u, x, u), STSP_OK);
        assert_int_equal(stsp_verify(&c), STSP_OK);
        copy = b.sp;
        switch (k) {
        case 0u: b.sp.n_coef = 40u; break;
        case 1u: b.sp.n_knots = 20u; break;
        case 2u: b.sp.n_entries = 9u; break;
        case 3u: b.sp.coef = s_coef; break; /* the same values elsewhere */
        case 4u: b.sp.col = s_col; break;
        case 5u: t.spline = &copy; break;  /* an equal header at another address */
        case 6u: b.sp.knot_start = s_knot_start; break;
        case 7u: b.sp.knot = s_knot; break;
        case 8u: b.sp.row_start = s_row_start; break;
        case 9u: b.sp.coef_start = s_coef_start; break;
        case 10u: t.spline = NULL; break;  /* the spline gone */
        case 11u: b.sp.ops = NULL; break;  /* the code pointer */
        default: b.coef[3] = 0.75f; expect = STSP_ERR_BAD_CRC; break;
        }
        assert_int_equal(stsp_verify(&c), expect);
        assert_int_equal(stsp_step(&c, 1u, x, u), STSP_ERR_NOT_INITIALIZED);
        assert_int_equal(f32_bits(u[0]), f32_bits(s_hold[0]));
        assert_int_equal(stsp_verify(&c), STSP_ERR_NOT_INITIALIZED);
    }
}

/* Spline arrays changed after init (until stsp_verify() notices): the controller keeps to the
 * lengths init validated whatever the index arrays, operand indices and knots hold, so wrong
 * commands but no access outside them (the _san builds run this with every array in a heap
 * block of its exact size). */
static void test_changed_arrays_stay_in_bounds(void **state_)
{
    uint32_t k, tick;
    (void)state_;
    for (k = 0u; k < 11u; ++k) {
        uint32_t *knot_start = heap_copy(s_knot_start, sizeof s_knot_start);
        float *knot = heap_copy(s_knot, sizeof s_knot);
        uint16_t *row_start = heap_copy(s_row_start, sizeof s_row_start);
        uint8_t *col = heap_copy(s_col, sizeof s_col);
        uint32_t *coef_start = heap_copy(s_coef_start, sizeof s_coef_start);
        float *coef = heap_copy(s_coef, sizeof s_coef);
        uint32_t *stage_start = heap_copy(s_stage_start, sizeof s_stage_start);
        stsp_spline_t sp = {S_N_KNOTS, S_N_ENTRIES, S_N_COEF, knot_start, knot, row_start,
                            col, coef_start, coef, &stsp_spline_ops};
        stsp_table_t t = make_s(&sp, s_no_min, s_no_max);
        stsp_ctrl_t c;
        t.stage_start = stage_start;
        assert_int_equal(stsp_init(&c, &t), STSP_OK);
        /* x in a heap block of its exact size too: the test itself is not built with ASan,
         * so a read past a stack array here would go unnoticed. */
        static const float no_state[S_NX] = {0.0f, 0.0f};
        float *x = heap_copy(no_state, sizeof no_state);
        for (tick = 0u; tick < 24u; ++tick) {
            float u[S_NU];
            stsp_status_t st;
            if (tick == 2u + k) {
                switch (k) {
                case 0u: memset(col, 0xFF, S_N_ENTRIES); break;
                case 1u: knot_start[1] = 0xFFFFFFF0u; knot_start[2] = 3u; break;
                case 2u: row_start[1] = 0xFFFFu; row_start[4] = 0xFFFFu; break;
                case 3u: coef_start[1] = 0xFFFFFFFFu; coef_start[0] = 40u; break;
                case 4u: knot[14] = NAN; knot[5] = 1e30f; knot[4] = -5.0f; break;
                case 5u: knot[14] = 4.5f; knot[15] = 2.0f; knot[5] = 100.0f; break;
                case 6u: stage_start[1] = 0xFFFFFFFFu; stage_start[2] = 3u; break;
                case 7u: row_start[3] = 0u; row_start[2] = 8u; break;
                case 8u: knot_start[1] = 18u; coef_start[1] = 43u; row_start[2] = 7u; break;
                /* a gain of x now naming x[nx], x[nx + 1]: just past x, where ASan's redzone
                 * is (0xFF above reads far beyond it) */
                case 9u: col[0] = (uint8_t)S_NX; col[4] = (uint8_t)(S_NX + 1u); break;
                default: memset(knot, 0xFF, sizeof s_knot); memset(coef, 0xFF, sizeof s_coef);
                    break;
                }
            }
            state(tick, x);
            st = stsp_step(&c, (tick % 7u == 6u) ? tick + 3u : tick, x, u);
            assert_true((st >= STSP_OK) || (st == STSP_ERR_TICK_RANGE) ||
                        (st == STSP_ERR_TICK_ORDER) || (st == STSP_ERR_NONFINITE_OUTPUT));
            st = stsp_step(&c, (tick % 7u == 6u) ? tick + 3u : tick, x, u); /* a repeat */
        }
        assert_int_equal(stsp_verify(&c), STSP_ERR_BAD_CRC);
        free(knot_start); free(knot); free(row_start); free(col); free(coef_start); free(coef);
        free(stage_start);
        free(x);
    }
}

/* A stage whose entries x (S + 3) wraps uint32 to the coefficient count given: refused
 * (the check divides, it does not multiply). One stage of 65 535 ticks, 65 534 spans (65 541
 * knots), 65 535 entries: 65 535 x 65 537 = 2^32 + 65 499. */
static void test_no_wraparound(void **state_)
{
    const uint32_t n_spans = 65534u, n_knots = n_spans + 7u, n_entries = 65535u;
    const uint32_t n_coef = 65499u;
    static const uint16_t one_latch[1] = {2u};
    static const float lam[S_N_LATCH * S_NX] = {0.0f};
    static const float lam0[S_N_LATCH] = {0.0f};
    uint32_t stage_start[2] = {0u, 65535u}, knot_start[2] = {0u, 0u};
    uint32_t coef_start[2] = {0u, 0u};
    uint16_t row_start[3] = {0u, 65535u, 65535u};
    float *knot = calloc(n_knots, sizeof *knot);
    uint8_t *col = calloc(n_entries, 1u);
    float *coef = calloc(n_coef, sizeof *coef);
    stsp_spline_t sp;
    stsp_table_t t = table_header(S_NX, S_NU, S_N_LATCH, 1u, 65535u, 100u);
    stsp_ctrl_t c;
    uint32_t i;
    (void)state_;
    assert_non_null(knot);
    assert_non_null(col);
    assert_non_null(coef);
    for (i = 0u; i < n_spans - 1u; ++i) {
        knot[4u + i] = (float)(i + 1u);
    }
    for (i = 0u; i < 4u; ++i) {
        knot[n_knots - 1u - i] = 65535.0f;
    }
    knot_start[1] = n_knots;
    coef_start[1] = n_coef;
    sp.n_knots = n_knots;
    sp.n_entries = n_entries;
    sp.n_coef = n_coef;
    sp.knot_start = knot_start;
    sp.knot = knot;
    sp.row_start = row_start;
    sp.col = col;
    sp.coef_start = coef_start;
    sp.coef = coef;
    sp.ops = &stsp_spline_ops;
    t.stage_start = stage_start;
    t.stage_n_latch = one_latch;
    t.Lambda = lam;
    t.lambda0 = lam0;
    t.u_min = s_no_min;
    t.u_max = s_no_max;
    t.u_hold = s_hold;
    t.spline = &sp;
    t.crc32 = stsp_table_crc32(&t);
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_DIMS);
    free(knot);
    free(col);
    free(coef);
}

#ifndef STSP_FIXED_NX
/* A table without multipliers (n_latch = 0: L, Lambda, lambda0 NULL), one input, one state:
 * u = -(g x + g0), one span. Generic build only (another shape). */
static void test_without_multipliers(void **state_)
{
    static const uint32_t st[2] = {0u, 4u}, ks[2] = {0u, 8u}, cs[2] = {0u, 8u};
    static const uint16_t nl[1] = {0u}, rs[2] = {0u, 2u};
    static const float kn[8] = {0.0f, 0.0f, 0.0f, 0.0f, 4.0f, 4.0f, 4.0f, 4.0f};
    static const uint8_t cl[2] = {0u, 1u};
    static const float cf[8] = {1.0f, 2.0f, 3.0f, 4.0f, 0.5f, 0.5f, 0.5f, 0.5f};
    static const float lo[1] = {-FLT_MAX}, hi[1] = {FLT_MAX}, hold[1] = {0.0f};
    const stsp_spline_t sp = {8u, 2u, 8u, ks, kn, rs, cl, cs, cf, &stsp_spline_ops};
    stsp_table_t t = table_header(1u, 1u, 0u, 1u, 4u, 10u);
    stsp_ctrl_t c;
    uint32_t tick;
    (void)state_;
    t.stage_start = st;
    t.stage_n_latch = nl;
    t.u_min = lo;
    t.u_max = hi;
    t.u_hold = hold;
    t.spline = &sp;
    t.crc32 = stsp_table_crc32(&t);
    assert_int_equal(stsp_init(&c, &t), STSP_OK);
    for (tick = 0u; tick < 4u; ++tick) {
        const float x[1] = {0.25f * (float)tick - 0.5f};
        float u[1], want[1];
        double dbl[1];
        assert_int_equal(stsp_step(&c, tick, x, u), STSP_OK);
        ref_command(&t, tick, x, NULL, want);
        ref_command_double(&t, tick, x, NULL, dbl);
        assert_int_equal(f32_bits(u[0]), f32_bits(want[0]));
        assert_true(fabs((double)u[0] - dbl[0]) <= 1e-6);
    }
}
#else
/* A fixed-shape build refuses a spline table of another shape. */
static void test_without_multipliers(void **state_)
{
    spline_buf_t b;
    stsp_table_t t;
    stsp_ctrl_t c;
    (void)state_;
    spline_buf_init(&b);
    t = make_s(&b.sp, s_no_min, s_no_max);
    t.nu = 1u;
    t.crc32 = stsp_table_crc32(&t);
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_DIMS);
}
#endif

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup(test_crc_pinned, setup),
        cmocka_unit_test_setup(test_run_matches_references, setup),
        cmocka_unit_test_setup(test_skips_and_repeats, setup),
        cmocka_unit_test_setup(test_random_walk, setup),
        cmocka_unit_test_setup(test_tick_range_end, setup),
        cmocka_unit_test_setup(test_nonfinite_unused_operands, setup),
        cmocka_unit_test_setup(test_saturation, setup),
        cmocka_unit_test_setup(test_state_and_command_share_a_buffer, setup),
        cmocka_unit_test(test_init_refusals),
        cmocka_unit_test(test_spline_band_table),
        cmocka_unit_test(test_long_stage),
        cmocka_unit_test(test_crc_mismatch),
        cmocka_unit_test(test_verify_spline_header),
        cmocka_unit_test(test_changed_arrays_stay_in_bounds),
        cmocka_unit_test(test_no_wraparound),
        cmocka_unit_test(test_without_multipliers),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
