/* libFuzzer target: a table changed after a successful stsp_init() (built by CMakeLists.txt
 * with clang, -fsanitize=fuzzer,address,undefined, once per arithmetic variant; the tests
 * fuzz_step_verify, fuzz_step_verify_q15 and fuzz_step_verify_q31 run it for a bounded time).
 *
 * Each input builds a valid table whose header, band dual or spline gains (one table in three
 * has spline gains, stages of up to 40 ticks: float32 stsp_spline_t, 1..8 spans per stage;
 * Q15/Q31 stsp_qspline_t, spans of 2^k ticks, k mostly 0..3, now and then up to 9, shifts
 * 1..30, coefficients that keep init's row bound) and every array live in
 * heap blocks of exactly the size init validates (so ASan reports any access beyond them),
 * inits two instances (one on the table, one, the reference, on an untouched copy of its
 * header and band dual or spline header: same arrays), steps both, then changes the table:
 * header fields (dimensions, magic, version, kind, tick_hz, crc32, problem hash), array
 * addresses (NULL, another array, a one-element block), the band dual's header, its address,
 * the spline's header (a length by a step or to anything, an array address: NULL, another of
 * its arrays, a one-entry block; Q15/Q31: n_entries, n_coef and the six arrays span_log2,
 * row_start, col, shift, coef_start, coef), its address (gone, another header, back), and bytes
 * of any array (the spline's knots, span_log2, index arrays, cols, shifts and coefficients
 * too: the steps must stay inside the validated arrays, stsp_spline.c); then
 * interleaves steps (ticks in order, repeated, skipped, backwards, past the end; states with
 * NaN/Inf/huge entries; x and u in separate, shared or overlapping blocks of exactly the
 * validated nx and nu), resets, conversions and stsp_verify().
 *
 * Invariants (any broken one aborts, as any sanitizer report): until verify stops it, the
 * instance on the changed table behaves bit for bit as the reference (the header changes do
 * not reach it; changed data reach both alike), with a known status, u the safe command
 * u_hold as init copied it on an error (even when the table's u_hold changed since);
 * stsp_verify() returns STSP_ERR_TABLE_CHANGED exactly when the header (magic, version, kind,
 * a dimension, an array address, the band dual's or the spline's header or address) differs
 * from the one init saw, else STSP_ERR_BAD_CRC exactly when the CRC over the validated arrays
 * (with the current tick_hz and problem hash) differs from the crc32 field, else STSP_OK;
 * after an error every step returns STSP_ERR_NOT_INITIALIZED with u that safe command, reset
 * and verify STSP_ERR_NOT_INITIALIZED. */
#include <float.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fuzz_input.h"
#include "stospline/stsp_controller.h"

#define FV_MAX_NX 6u
#define FV_MAX_NU 4u
#define FV_MAX_N_LATCH 5u
#define FV_MAX_NS 4u
#define FV_MAX_STAGE_TICKS 4u
#define FV_MAX_SPLINE_STAGE_TICKS 40u /* a spline table's stages (at most 8 spans each) */
#define FV_MAX_SPANS 8u
#define FV_MAX_CALLS 40u
#define FV_MAX_BLOCKS 48u

/* -DFV_STATS: count what the inputs reached and print it at exit (not in the ctest build). */
#ifdef FV_STATS
enum { FVS_INPUTS, FVS_BAND, FVS_SPLINE, FVS_HDR, FVS_DATA, FVS_SPLINE_HDR, FVS_SPLINE_DATA,
       FVS_VERIFY_OK, FVS_VERIFY_CHANGED, FVS_VERIFY_CRC, FVS_STEPS_CHANGED,
       FVS_SPLINE_STEPS_CHANGED, FVS_STOPPED_STEPS, FVS_SHARED, FVS_N };
static const char *const fvs_names[FVS_N] = {
    "inputs", "band tables", "spline tables", "header changes", "data changes",
    "  on spline tables: header", "  on spline tables: data", "verify OK", "verify TABLE_CHANGED",
    "verify BAD_CRC", "steps on a changed table", "  of them spline tables",
    "steps when stopped", "steps with shared x/u"};
static unsigned long fvs[FVS_N];
static void fvs_print(void)
{
    int i;
    for (i = 0; i < FVS_N; ++i) {
        (void)fprintf(stderr, "FV_STATS %-26s %lu\n", fvs_names[i], fvs[i]);
    }
}
#define FVS(k) (++fvs[(k)])
#else
#define FVS(k) ((void)0)
#endif

/* Heap blocks of one input, each exactly as long as asked; freed at the end. */
typedef struct {
    void *p[FV_MAX_BLOCKS];
    size_t size[FV_MAX_BLOCKS];
    uint32_t n;
} fv_blocks_t;

static void *fv_alloc(fv_blocks_t *b, size_t size)
{
    void *p;
    fuzz_check(b->n < FV_MAX_BLOCKS);
    p = calloc(1u, (size > 0u) ? size : 1u);
    fuzz_check(p != NULL);
    b->p[b->n] = p;
    b->size[b->n] = size;
    ++b->n;
    return p;
}

static void fv_free(fv_blocks_t *b)
{
    uint32_t i;
    for (i = 0u; i < b->n; ++i) {
        free(b->p[i]);
    }
}

static uint32_t fv_lcg(uint32_t *seed)
{
    *seed = *seed * 1664525u + 1013904223u;
    return *seed >> 8;
}

/* Small table values: any row of the law or the latch (at most 1 + 6 + 5 terms) stays below
 * 2^F - 1 in the fixed-point builds. */
static stsp_scalar_t fv_small(uint32_t *seed)
{
    const int32_t r = (int32_t)(fv_lcg(seed) % 2048u) - 1024;
#ifdef STSP_ARITH_FIXED_POINT
    return (stsp_scalar_t)((int64_t)r * (((int64_t)1 << STSP_Q_FRAC_BITS) / 16384));
#else
    return (float)r / 256.0f;
#endif
}

static void fv_fill(uint32_t *seed, stsp_scalar_t *a, uint32_t count)
{
    uint32_t i;
    for (i = 0u; i < count; ++i) {
        a[i] = fv_small(seed);
    }
}

/* A state entry: mostly modest, now and then a range end or (float32) NaN/Inf/huge. */
static stsp_scalar_t fv_state(fuzz_in_t *in)
{
    const uint32_t sel = fuzz_u8(in);
#ifdef STSP_ARITH_FIXED_POINT
    const int64_t one = (int64_t)1 << STSP_Q_FRAC_BITS;
    if (sel < 240u) {
        return (stsp_scalar_t)(((int64_t)fuzz_u8(in) - 128) * (one / 128));
    }
    return (sel & 1u) ? (stsp_scalar_t)(one - 1) : (stsp_scalar_t)(-one);
#else
    static const float specials[6] = {1e38f, -3e38f, FLT_MIN, 0.0f, 0.0f, 0.0f};
    float f;
    uint32_t bits;
    if (sel < 230u) {
        return ((float)fuzz_u8(in) - 128.0f) / 16.0f;
    }
    if (sel < 250u) {
        return specials[sel % 6u];
    }
    bits = (sel & 1u) ? 0x7FC00000u : ((sel & 2u) ? 0x7F800000u : 0xFF800000u);
    memcpy(&f, &bits, sizeof f);
    return f;
#endif
}

/* The table and what was changed in it. */
typedef struct {
    stsp_table_t *t;        /* the table (heap) the instance under test is bound to */
    stsp_table_t *orig;     /* its header as init saw it (heap; the reference's table) */
    stsp_bandqp_t *band;    /* the table's band dual (heap), or NULL */
    stsp_bandqp_t *band0;   /* its header as init saw it (the reference's band dual) */
    stsp_spline_gains_t *spline;  /* the table's spline gains (heap), or NULL */
    stsp_spline_gains_t *spline0; /* their header as init saw it (the reference's) */
    uint32_t spline_arrays; /* arrays[spline_arrays..] are the spline's (data changes) */
    void *arrays[24];       /* every array block, for data changes */
    size_t sizes[24];
    stsp_scalar_t hold0[STSP_MAX_NU]; /* u_hold as init saw it: what a refused step writes */
    uint32_t n_arrays;
} fv_table_t;

static void fv_add_array(fv_table_t *tb, void *p, size_t size)
{
    if (p != NULL) {
        tb->arrays[tb->n_arrays] = p;
        tb->sizes[tb->n_arrays] = size;
        ++tb->n_arrays;
    }
}

#define FV_ARRAY(tb, blocks, type, count) \
    ((type *)fv_array((tb), (blocks), sizeof(type) * (size_t)(count)))

static void *fv_array(fv_table_t *tb, fv_blocks_t *blocks, size_t size)
{
    void *p = fv_alloc(blocks, size);
    fv_add_array(tb, p, size);
    return p;
}

/* An array of the spline gains: a block of exactly `size` bytes, registered for data changes
 * unless empty (a stage may store no entry: col and coef may be empty, but not NULL). */
static void *fv_spline_array(fv_table_t *tb, fv_blocks_t *blocks, size_t size)
{
    return (size > 0u) ? fv_array(tb, blocks, size) : fv_alloc(blocks, 0u);
}

#ifdef STSP_ARITH_FIXED_POINT
/* Valid fixed-point spline gains for t (stsp_qspline_t): per stage spans of 2^k ticks (k
 * mostly 0..3, so several spans in a stage of up to 40 ticks, now and then up to 9: one span),
 * per (stage, input) none, all or a random subset of the operands stored, shifts 1..30, and
 * coefficients within +-2^F/64 (a gain is at most 3 of them plus the rounding, so a row of at
 * most 12 stays below 2^F - 1: init's row bound holds at every tick); every array in its own
 * block of exactly its size. */
static void fv_build_qspline(fv_blocks_t *blocks, fv_table_t *tb, stsp_table_t *t,
                             uint32_t *seed)
{
    const uint32_t ns = t->n_stages, nu = t->nu, nz = (uint32_t)t->nx + 1u + t->n_latch;
    const int64_t one = (int64_t)1 << STSP_Q_FRAC_BITS;
    uint32_t kk[FV_MAX_NS], stride[FV_MAX_NS], mask[FV_MAX_NS * FV_MAX_NU];
    uint32_t ne = 0u, nc = 0u, s, i, k, c;
    uint8_t *span_log2, *col, *shift;
    uint16_t *row_start;
    uint32_t *coef_start;
    stsp_scalar_t *coef;
    stsp_qspline_t *sp;
    for (s = 0u; s < ns; ++s) {
        const uint32_t T = t->stage_start[s + 1u] - t->stage_start[s];
        const uint32_t pick = fv_lcg(seed) % 8u;
        kk[s] = (pick == 0u) ? fv_lcg(seed) % 10u : fv_lcg(seed) % 4u;
        stride[s] = ((T + (1u << kk[s]) - 1u) >> kk[s]) + 3u;
        for (i = 0u; i < nu; ++i) {
            const uint32_t sel = fv_lcg(seed) % 8u;    /* none, all, or a random subset */
            const uint32_t m = ((sel == 0u) ? 0u : (sel == 1u) ? ~0u : fv_lcg(seed)) &
                               ((1u << nz) - 1u);
            mask[s * nu + i] = m;
            for (c = 0u; c < nz; ++c) {
                if ((m >> c) & 1u) {
                    ++ne;
                    nc += stride[s];
                }
            }
        }
    }
    span_log2 = (uint8_t *)fv_spline_array(tb, blocks, ns);
    row_start = (uint16_t *)fv_spline_array(tb, blocks, sizeof(uint16_t) * (ns * nu + 1u));
    col = (uint8_t *)fv_spline_array(tb, blocks, ne);
    shift = (uint8_t *)fv_spline_array(tb, blocks, ne);
    coef_start = (uint32_t *)fv_spline_array(tb, blocks, sizeof(uint32_t) * (ns + 1u));
    coef = (stsp_scalar_t *)fv_spline_array(tb, blocks, sizeof(stsp_scalar_t) * nc);
    ne = nc = 0u;
    row_start[0] = 0u;
    for (s = 0u; s < ns; ++s) {
        span_log2[s] = (uint8_t)kk[s];
        coef_start[s] = nc;
        for (i = 0u; i < nu; ++i) {
            for (c = 0u; c < nz; ++c) {
                if ((mask[s * nu + i] >> c) & 1u) {
                    col[ne] = (uint8_t)c;
                    shift[ne] = (uint8_t)(1u + fv_lcg(seed) % 30u);
                    ++ne;
                    for (k = 0u; k < stride[s]; ++k) {
                        coef[nc++] = (stsp_scalar_t)(((int64_t)(fv_lcg(seed) % 4096u) - 2048) *
                                                     one / 131072);
                    }
                }
            }
            row_start[s * nu + i + 1u] = (uint16_t)ne;
        }
    }
    coef_start[ns] = nc;
    sp = (stsp_qspline_t *)fv_alloc(blocks, sizeof *sp);
    sp->n_entries = ne;
    sp->n_coef = nc;
    sp->span_log2 = span_log2;
    sp->row_start = row_start;
    sp->col = col;
    sp->shift = shift;
    sp->coef_start = coef_start;
    sp->coef = coef;
    sp->ops = &stsp_spline_ops;
    t->spline = sp;
    tb->spline = sp;
}
#else

/* Valid spline gains for t (float32): per stage 1..8 spans on distinct integer breakpoints,
 * per (stage, input) none, all or a random subset of the operands stored, small
 * coefficients; every array
 * in its own block of exactly its size. */
static void fv_build_spline(fv_blocks_t *blocks, fv_table_t *tb, stsp_table_t *t,
                            uint32_t *seed)
{
    const uint32_t ns = t->n_stages, nu = t->nu, nz = (uint32_t)t->nx + 1u + t->n_latch;
    uint32_t spans[FV_MAX_NS], bp[FV_MAX_NS][FV_MAX_SPANS], mask[FV_MAX_NS * FV_MAX_NU];
    uint32_t nk = 0u, ne = 0u, nc = 0u, s, i, k, c;
    uint32_t *knot_start, *coef_start;
    uint16_t *row_start;
    uint8_t *col;
    float *knot, *coef;
    stsp_spline_t *sp;
    for (s = 0u; s < ns; ++s) {
        const uint32_t T = t->stage_start[s + 1u] - t->stage_start[s];
        const uint32_t want = 1u + fv_lcg(seed) % ((T < FV_MAX_SPANS) ? T : FV_MAX_SPANS);
        uint32_t nb = 0u;
        for (k = 0u; (k + 1u < want) && (T > 1u); ++k) {
            const uint32_t v = 1u + fv_lcg(seed) % (T - 1u);
            uint32_t j;
            int dup = 0;
            for (j = 0u; j < nb; ++j) {
                dup = dup || (bp[s][j] == v);
            }
            if (!dup) {
                for (j = nb; (j > 0u) && (bp[s][j - 1u] > v); --j) {
                    bp[s][j] = bp[s][j - 1u];
                }
                bp[s][j] = v;
                ++nb;
            }
        }
        spans[s] = nb + 1u;
        nk += spans[s] + 7u;
        for (i = 0u; i < nu; ++i) {
            const uint32_t pick = fv_lcg(seed) % 8u;    /* none, all, or a random subset */
            const uint32_t m = ((pick == 0u) ? 0u : (pick == 1u) ? ~0u : fv_lcg(seed)) &
                               ((1u << nz) - 1u);
            mask[s * nu + i] = m;
            for (c = 0u; c < nz; ++c) {
                if ((m >> c) & 1u) {
                    ++ne;
                    nc += spans[s] + 3u;
                }
            }
        }
    }
    knot_start = (uint32_t *)fv_spline_array(tb, blocks, sizeof(uint32_t) * (ns + 1u));
    knot = (float *)fv_spline_array(tb, blocks, sizeof(float) * nk);
    row_start = (uint16_t *)fv_spline_array(tb, blocks, sizeof(uint16_t) * (ns * nu + 1u));
    col = (uint8_t *)fv_spline_array(tb, blocks, ne);
    coef_start = (uint32_t *)fv_spline_array(tb, blocks, sizeof(uint32_t) * (ns + 1u));
    coef = (float *)fv_spline_array(tb, blocks, sizeof(float) * nc);
    nk = ne = nc = 0u;
    row_start[0] = 0u;
    for (s = 0u; s < ns; ++s) {
        const uint32_t T = t->stage_start[s + 1u] - t->stage_start[s];
        knot_start[s] = nk;
        coef_start[s] = nc;
        for (k = 0u; k < 4u; ++k) {
            knot[nk + k] = 0.0f;
            knot[nk + spans[s] + 3u + k] = (float)T;
        }
        for (k = 0u; k + 1u < spans[s]; ++k) {
            knot[nk + 4u + k] = (float)bp[s][k];
        }
        nk += spans[s] + 7u;
        for (i = 0u; i < nu; ++i) {
            for (c = 0u; c < nz; ++c) {
                if ((mask[s * nu + i] >> c) & 1u) {
                    col[ne++] = (uint8_t)c;
                    for (k = 0u; k < spans[s] + 3u; ++k) {
                        coef[nc++] = fv_small(seed);
                    }
                }
            }
            row_start[s * nu + i + 1u] = (uint16_t)ne;
        }
    }
    knot_start[ns] = nk;
    coef_start[ns] = nc;
    sp = (stsp_spline_t *)fv_alloc(blocks, sizeof *sp);
    sp->n_knots = nk;
    sp->n_entries = ne;
    sp->n_coef = nc;
    sp->knot_start = knot_start;
    sp->knot = knot;
    sp->row_start = row_start;
    sp->col = col;
    sp->coef_start = coef_start;
    sp->coef = coef;
    sp->ops = &stsp_spline_ops;
    t->spline = sp;
    tb->spline = sp;
}
#endif

/* A valid table (init accepts it) from the input: dimensions, stages, a seeded generator for
 * the values, limits, and (float32) a band dual or spline gains now and then. */
static void fv_build(fuzz_in_t *in, fv_blocks_t *blocks, fv_table_t *tb)
{
    const uint32_t nx = 1u + fuzz_u8(in) % FV_MAX_NX;
    const uint32_t nu = 1u + fuzz_u8(in) % FV_MAX_NU;
    const uint32_t n_latch = fuzz_u8(in) % (FV_MAX_N_LATCH + 1u);
    const uint32_t ns = 1u + fuzz_u8(in) % FV_MAX_NS;
    const uint32_t limits = fuzz_u8(in) % 3u;
    uint32_t seed = fuzz_u32(in);
    stsp_table_t *t = (stsp_table_t *)fv_alloc(blocks, sizeof *t);
    uint32_t *start = FV_ARRAY(tb, blocks, uint32_t, ns + 1u);
    uint16_t *stage_n_latch = FV_ARRAY(tb, blocks, uint16_t, ns);
    stsp_scalar_t *lo = FV_ARRAY(tb, blocks, stsp_scalar_t, nu);
    stsp_scalar_t *hi = FV_ARRAY(tb, blocks, stsp_scalar_t, nu);
    stsp_scalar_t *hold = FV_ARRAY(tb, blocks, stsp_scalar_t, nu);
    uint32_t s, i, nt = 0u;
    const int spline = (fuzz_u8(in) % 3u) == 1u;
    int band = 0;
    for (s = 0u; s < ns; ++s) {
        start[s] = nt;
        nt += 1u + fuzz_u8(in) % (spline ? FV_MAX_SPLINE_STAGE_TICKS : FV_MAX_STAGE_TICKS);
        stage_n_latch[s] = (uint16_t)((n_latch > 0u) ? fuzz_u8(in) % (n_latch + 1u) : 0u);
    }
    start[ns] = nt;
#ifndef STSP_ARITH_FIXED_POINT
    band = !spline && (n_latch > 0u) && ((fuzz_u8(in) % 3u) == 0u);
    if (band) {
        const uint32_t q_max = (n_latch < STSP_BANDQP_MAX) ? n_latch : STSP_BANDQP_MAX;
        stage_n_latch[0] = (uint16_t)(1u + fuzz_u8(in) % q_max);
        for (s = 1u; s < ns; ++s) {
            stage_n_latch[s] = 0u;
        }
    }
#endif
    memset(t, 0, sizeof *t);
    t->magic = STSP_TABLE_MAGIC;
    t->format_version = STSP_FORMAT_VERSION;
    t->scalar_kind = STSP_SCALAR_KIND;
    t->nx = (uint16_t)nx;
    t->nu = (uint16_t)nu;
    t->n_latch = (uint16_t)n_latch;
    t->n_stages = (uint16_t)ns;
    t->n_ticks = nt;
    t->tick_hz = 1u + fuzz_u8(in);
    t->stage_start = start;
    t->stage_n_latch = stage_n_latch;
    if (!spline) {
        t->K = FV_ARRAY(tb, blocks, stsp_scalar_t, nt * nu * nx);
        fv_fill(&seed, (stsp_scalar_t *)t->K, nt * nu * nx);
        t->k0 = FV_ARRAY(tb, blocks, stsp_scalar_t, nt * nu);
        fv_fill(&seed, (stsp_scalar_t *)t->k0, nt * nu);
    }
    if (n_latch > 0u) {
        if (!spline) {
            t->L = FV_ARRAY(tb, blocks, stsp_scalar_t, nt * nu * n_latch);
            fv_fill(&seed, (stsp_scalar_t *)t->L, nt * nu * n_latch);
        }
        t->Lambda = FV_ARRAY(tb, blocks, stsp_scalar_t, ns * n_latch * nx);
        fv_fill(&seed, (stsp_scalar_t *)t->Lambda, ns * n_latch * nx);
        t->lambda0 = FV_ARRAY(tb, blocks, stsp_scalar_t, ns * n_latch);
        fv_fill(&seed, (stsp_scalar_t *)t->lambda0, ns * n_latch);
    }
    for (i = 0u; i < nu; ++i) {
        const stsp_scalar_t a = fv_small(&seed), b = fv_small(&seed);
#ifdef STSP_ARITH_FIXED_POINT
        const int64_t one = (int64_t)1 << STSP_Q_FRAC_BITS;
        lo[i] = (limits == 0u) ? (stsp_scalar_t)(-one) : (stsp_scalar_t)((a < 0) ? a : -a);
        hi[i] = (limits == 0u) ? (stsp_scalar_t)(one - 1) : (stsp_scalar_t)((b > 0) ? b : -b);
#else
        lo[i] = (limits == 0u) ? -FLT_MAX : ((a < 0.0f) ? a : -a);
        hi[i] = (limits == 0u) ? FLT_MAX : ((b > 0.0f) ? b : -b);
#endif
    }
    for (i = 0u; i < nu; ++i) {                 /* the safe command: a limit, or 0 */
        const uint32_t pick = fv_lcg(&seed) % 3u;
        hold[i] = (pick == 0u) ? lo[i] : ((pick == 1u) ? hi[i] : (stsp_scalar_t)0);
        tb->hold0[i] = hold[i];
    }
    t->u_min = lo;
    t->u_max = hi;
    t->u_hold = hold;
#ifdef STSP_ARITH_FIXED_POINT
    {
        int8_t *xe = FV_ARRAY(tb, blocks, int8_t, nx);
        int8_t *ue = FV_ARRAY(tb, blocks, int8_t, nu);
        for (i = 0u; i < nx; ++i) {
            xe[i] = (int8_t)((int32_t)(fv_lcg(&seed) % 17u) - 8);
        }
        for (i = 0u; i < nu; ++i) {
            ue[i] = (int8_t)((int32_t)(fv_lcg(&seed) % 17u) - 8);
        }
        t->x_exp = xe;
        t->u_exp = ue;
        if (n_latch > 0u) {
            int8_t *ve = FV_ARRAY(tb, blocks, int8_t, n_latch);
            for (i = 0u; i < n_latch; ++i) {
                ve[i] = (int8_t)((int32_t)(fv_lcg(&seed) % 17u) - 8);
            }
            t->v_exp = ve;
        }
    }
#endif
    tb->band = NULL;
    tb->spline = NULL;
    tb->spline_arrays = tb->n_arrays;
    if (spline) {
#ifdef STSP_ARITH_FIXED_POINT
        fv_build_qspline(blocks, tb, t, &seed);
#else
        fv_build_spline(blocks, tb, t, &seed);
#endif
    }
    if (band) {
        const uint32_t q = stage_n_latch[0];
        stsp_bandqp_t *b = (stsp_bandqp_t *)fv_alloc(blocks, sizeof *b);
        double *Nt = FV_ARRAY(tb, blocks, double, q * nx);
        double *mt = FV_ARRAY(tb, blocks, double, q);
        double *W = FV_ARRAY(tb, blocks, double, q * q);
        double *blo = FV_ARRAY(tb, blocks, double, q);
        double *bhi = FV_ARRAY(tb, blocks, double, q);
        uint32_t j;
        for (i = 0u; i < q * nx; ++i) {
            Nt[i] = (double)((int32_t)(fv_lcg(&seed) % 64u) - 32) / 16.0;
        }
        for (i = 0u; i < q; ++i) {
            mt[i] = (double)((int32_t)(fv_lcg(&seed) % 64u) - 32) / 16.0;
            blo[i] = -(double)(fv_lcg(&seed) % 16u) / 4.0;
            bhi[i] = ((fv_lcg(&seed) % 4u) == 0u) ? blo[i] : (double)(fv_lcg(&seed) % 16u) / 4.0;
            for (j = 0u; j < q; ++j) {
                W[i * q + j] = (i == j) ? 2.0 + (double)(fv_lcg(&seed) % 8u)
                                        : (double)((int32_t)(fv_lcg(&seed) % 9u) - 4) / 16.0;
            }
        }
        for (i = 0u; i < q; ++i) { /* symmetric */
            for (j = 0u; j < i; ++j) {
                W[i * q + j] = W[j * q + i];
            }
        }
        b->q = (uint16_t)q;
        b->nx = (uint16_t)nx;
        b->Nt = Nt;
        b->mt = mt;
        b->W = W;
        b->lo = blo;
        b->hi = bhi;
        b->solve_f32 = stsp_bandqp_solve_f32;
        t->band_qp = b;
        tb->band = b;
    }
    for (i = 0u; i < (uint32_t)sizeof t->problem_sha256; ++i) {
        t->problem_sha256[i] = (uint8_t)fv_lcg(&seed);
    }
    t->crc32 = stsp_table_crc32(t);
    tb->t = t;
    tb->orig = (stsp_table_t *)fv_alloc(blocks, sizeof *t);
    *tb->orig = *t;
    tb->band0 = NULL;
    if (tb->band != NULL) {
        tb->band0 = (stsp_bandqp_t *)fv_alloc(blocks, sizeof *tb->band0);
        *tb->band0 = *tb->band;
        tb->orig->band_qp = tb->band0;
    }
    tb->spline0 = NULL;
    if (tb->spline != NULL) {
        tb->spline0 = (stsp_spline_gains_t *)fv_alloc(blocks, sizeof *tb->spline0);
        *tb->spline0 = *tb->spline;
        tb->orig->spline = tb->spline0;
    }
}

/* A byte of an array (data: the CRC covers it). */
static void fv_change_data(fv_table_t *tb, uint32_t which, uint32_t value)
{
    const uint32_t a = which % tb->n_arrays;
    uint8_t *bytes = (uint8_t *)tb->arrays[a];
    bytes[value % tb->sizes[a]] ^= (uint8_t)(1u + (value >> 16) % 255u);
}

/* One change of the table, chosen by the input. */
static void fv_change(fuzz_in_t *in, fv_blocks_t *blocks, fv_table_t *tb)
{
    stsp_table_t *t = tb->t;
    const uint32_t kind = fuzz_u8(in) % 11u;
    const uint32_t which = fuzz_u8(in);
    const uint32_t value = fuzz_u32(in);
    switch (kind) {
    case 0u: /* a dimension: a small step or anything */
    case 1u: {
        const uint32_t v = ((value & 1u) != 0u) ? (value >> 24) : (value >> 1);
        const int32_t step = (int32_t)(value % 5u) - 2;
        switch (which % 6u) {
        case 0u: t->nx = (uint16_t)((kind == 0u) ? (int32_t)t->nx + step : (int32_t)v); break;
        case 1u: t->nu = (uint16_t)((kind == 0u) ? (int32_t)t->nu + step : (int32_t)v); break;
        case 2u: t->n_latch = (uint16_t)((kind == 0u) ? (int32_t)t->n_latch + step : (int32_t)v);
                 break;
        case 3u: t->n_stages = (uint16_t)((kind == 0u) ? (int32_t)t->n_stages + step
                                                       : (int32_t)v); break;
        case 4u: t->n_ticks = (kind == 0u) ? (uint32_t)((int32_t)t->n_ticks + step) : value; break;
        default: t->tick_hz = (kind == 0u) ? (uint32_t)((int32_t)t->tick_hz + step) : value;
                 break;
        }
        break;
    }
    case 2u: /* identity fields */
        switch (which % 4u) {
        case 0u: t->magic = value; break;
        case 1u: t->format_version = (uint16_t)value; break;
        case 2u: t->scalar_kind = (uint16_t)(value % 4u); break;
        default: t->crc32 ^= 1u << (value % 32u); break;
        }
        break;
    case 3u: { /* an array address: NULL, another array of the table, or a one-entry block */
        const stsp_scalar_t *arrays[8] = {t->K, t->k0, t->L, t->Lambda, t->lambda0, t->u_min,
                                          t->u_max, t->u_hold};
        const stsp_scalar_t *p = NULL;
        const uint32_t pick = value % 10u;
        if (pick < 8u) {
            p = arrays[pick];
        } else if (pick == 8u) {
            p = (const stsp_scalar_t *)fv_alloc(blocks, sizeof(stsp_scalar_t));
        } else {
            /* NULL */
        }
        switch (which % 12u) {
        case 0u: t->K = p; break;
        case 1u: t->k0 = p; break;
        case 2u: t->L = p; break;
        case 3u: t->Lambda = p; break;
        case 4u: t->lambda0 = p; break;
        case 5u: t->u_min = p; break;
        case 6u: t->u_max = p; break;
        case 7u: t->stage_start = (pick == 9u) ? NULL
                                  : (const uint32_t *)fv_alloc(blocks, sizeof(uint32_t)); break;
        case 8u: t->stage_n_latch = (pick == 9u) ? NULL
                               : (const uint16_t *)fv_alloc(blocks, sizeof(uint16_t)); break;
        case 11u: t->u_hold = p; break;
#ifdef STSP_ARITH_FIXED_POINT
        case 9u: t->x_exp = (const int8_t *)fv_alloc(blocks, 1u); break;
        default: t->v_exp = (pick == 9u) ? NULL : t->u_exp; break;
#else
        default: break;
#endif
        }
        break;
    }
    case 4u: /* the problem hash (covered by the CRC) */
        t->problem_sha256[which % 32u] ^= (uint8_t)(1u + value % 255u);
        break;
    case 5u: /* the band dual's or the spline's header (neither: a data change instead) */
        if (tb->band != NULL) {
            stsp_bandqp_t *b = tb->band;
            switch (which % 4u) {
            case 0u: b->q = (uint16_t)(value % 12u); break;
            case 1u: b->nx = (uint16_t)(value % 10u); break;
            case 2u: b->W = ((value & 1u) != 0u) ? b->mt : NULL; break;
            default: b->Nt = (const double *)fv_alloc(blocks, sizeof(double)); break;
            }
#ifdef STSP_ARITH_FIXED_POINT
        } else if (tb->spline != NULL) {
            /* a length by a small step or to anything, or an array address: NULL, another of
             * the spline's arrays, or a one-entry block (of the largest element type) */
            stsp_qspline_t *p = tb->spline;
            const uint32_t v = ((value & 1u) != 0u) ? (value >> 24) : (value >> 1);
            const uint32_t step = (value >> 8) % 5u;  /* -2..2 as an offset */
            const void *arrays[6] = {p->span_log2, p->row_start, p->col, p->shift,
                                     p->coef_start, p->coef};
            const uint32_t pick = (value >> 12) % 8u;
            const void *q = (pick < 6u) ? arrays[pick]
                            : (pick == 6u) ? fv_alloc(blocks, sizeof(uint32_t)) : NULL;
            switch (which % 8u) {
            case 0u: p->n_entries = ((which & 16u) != 0u) ? v : p->n_entries + step - 2u; break;
            case 1u: p->n_coef = ((which & 16u) != 0u) ? v : p->n_coef + step - 2u; break;
            case 2u: p->span_log2 = (const uint8_t *)q; break;
            case 3u: p->row_start = (const uint16_t *)q; break;
            case 4u: p->col = (const uint8_t *)q; break;
            case 5u: p->shift = (const uint8_t *)q; break;
            case 6u: p->coef_start = (const uint32_t *)q; break;
            default: p->coef = (const stsp_scalar_t *)q; break;
            }
#else
        } else if (tb->spline != NULL) {
            /* a length by a small step or to anything, or an array address: NULL, another of
             * the spline's arrays, or a one-entry block */
            stsp_spline_t *p = tb->spline;
            const uint32_t v = ((value & 1u) != 0u) ? (value >> 24) : (value >> 1);
            const uint32_t step = (value >> 8) % 5u;  /* -2..2 as an offset */
            const void *arrays[6] = {p->knot_start, p->knot, p->row_start, p->col,
                                     p->coef_start, p->coef};
            const uint32_t pick = (value >> 12) % 8u;
            const void *q = (pick < 6u) ? arrays[pick]
                            : (pick == 6u) ? fv_alloc(blocks, sizeof(uint32_t)) : NULL;
            switch (which % 9u) {
            case 0u: p->n_knots = ((which & 16u) != 0u) ? v : p->n_knots + step - 2u; break;
            case 1u: p->n_entries = ((which & 16u) != 0u) ? v : p->n_entries + step - 2u; break;
            case 2u: p->n_coef = ((which & 16u) != 0u) ? v : p->n_coef + step - 2u; break;
            case 3u: p->knot_start = (const uint32_t *)q; break;
            case 4u: p->knot = (const float *)q; break;
            case 5u: p->row_start = (const uint16_t *)q; break;
            case 6u: p->col = (const uint8_t *)q; break;
            case 7u: p->coef_start = (const uint32_t *)q; break;
            default: p->coef = (const float *)q; break;
            }
#endif
        } else {
            fv_change_data(tb, which, value);
        }
        break;
    case 6u: /* the band dual's address: a new one appears, or the present one goes */
        if (((which & 1u) != 0u) || (t->band_qp == NULL)) {
            stsp_bandqp_t *b = (stsp_bandqp_t *)fv_alloc(blocks, sizeof *b);
            double *d = (double *)fv_alloc(blocks, sizeof(double));
            b->q = (uint16_t)(1u + value % 8u);
            b->nx = t->nx;
            b->Nt = d; b->mt = d; b->W = d; b->lo = d; b->hi = d;
            t->band_qp = b;
        } else {
            t->band_qp = NULL;
        }
        break;
    case 7u: /* undo every header change so far (an A -> B -> A change is no change) */
        *t = *tb->orig;
        t->band_qp = tb->band;
        if (tb->band != NULL) {
            *tb->band = *tb->band0;
        }
        t->spline = tb->spline;
        if (tb->spline != NULL) {
            *tb->spline = *tb->spline0;
        }
        break;
    case 10u: /* the spline's address: gone, another header with the same arrays, or back */
        switch (value % 3u) {
        case 0u: t->spline = NULL; break;
        case 1u: {
            stsp_spline_gains_t *p = (stsp_spline_gains_t *)fv_alloc(blocks, sizeof *p);
            if (tb->spline0 != NULL) {
                *p = *tb->spline0;
            }
            t->spline = p;
            break;
        }
        default: t->spline = tb->spline; break;
        }
        break;
    default:
        fv_change_data(tb, which, value);
        break;
    }
}

/* Does the header differ from the one init saw, in anything verify must report as changed? */
static int fv_header_changed(const fv_table_t *tb)
{
    const stsp_table_t *t = tb->t, *o = tb->orig;
    int changed = (t->magic != o->magic) || (t->format_version != o->format_version) ||
                  (t->scalar_kind != o->scalar_kind) || (t->nx != o->nx) || (t->nu != o->nu) ||
                  (t->n_latch != o->n_latch) || (t->n_stages != o->n_stages) ||
                  (t->n_ticks != o->n_ticks) || (t->stage_start != o->stage_start) ||
                  (t->stage_n_latch != o->stage_n_latch) || (t->K != o->K) || (t->k0 != o->k0) ||
                  (t->L != o->L) || (t->Lambda != o->Lambda) || (t->lambda0 != o->lambda0) ||
                  (t->u_min != o->u_min) || (t->u_max != o->u_max) || (t->u_hold != o->u_hold);
#ifdef STSP_ARITH_FIXED_POINT
    changed = changed || (t->x_exp != o->x_exp) || (t->u_exp != o->u_exp) ||
              (t->v_exp != o->v_exp) || (t->band_qp != NULL);
    if (t->spline != tb->spline) {
        changed = 1;
    } else if (tb->spline != NULL) {
        const stsp_qspline_t *p = tb->spline, *p0 = tb->spline0;
        changed = changed || (p->n_entries != p0->n_entries) || (p->n_coef != p0->n_coef) ||
                  (p->span_log2 != p0->span_log2) || (p->row_start != p0->row_start) ||
                  (p->col != p0->col) || (p->shift != p0->shift) ||
                  (p->coef_start != p0->coef_start) || (p->coef != p0->coef);
    } else {
        /* gains per tick, as init saw */
    }
#else
    if (t->spline != tb->spline) {
        changed = 1;
    } else if (tb->spline != NULL) {
        const stsp_spline_t *p = tb->spline, *p0 = tb->spline0;
        changed = changed || (p->n_knots != p0->n_knots) || (p->n_entries != p0->n_entries) ||
                  (p->n_coef != p0->n_coef) || (p->knot_start != p0->knot_start) ||
                  (p->knot != p0->knot) || (p->row_start != p0->row_start) ||
                  (p->col != p0->col) || (p->coef_start != p0->coef_start) ||
                  (p->coef != p0->coef);
    } else {
        /* gains per tick, as init saw */
    }
    if (t->band_qp != tb->band) {
        changed = 1;
    } else if (tb->band != NULL) {
        const stsp_bandqp_t *b = tb->band, *b0 = tb->band0;
        changed = changed || (b->q != b0->q) || (b->nx != b0->nx) || (b->Nt != b0->Nt) ||
                  (b->mt != b0->mt) || (b->W != b0->W) || (b->lo != b0->lo) ||
                  (b->hi != b0->hi);
    } else {
        /* no band dual, as init saw */
    }
#endif
    return changed;
}

/* What stsp_verify() must return for the table as it is now. */
static stsp_status_t fv_expected_verify(const fv_table_t *tb)
{
    stsp_table_t probe;
    if (fv_header_changed(tb)) {
        return STSP_ERR_TABLE_CHANGED;
    }
    /* The validated header with the scalars the CRC reads from the current one. */
    probe = *tb->orig;
    probe.tick_hz = tb->t->tick_hz;
    memcpy(probe.problem_sha256, tb->t->problem_sha256, sizeof probe.problem_sha256);
    return (stsp_table_crc32(&probe) == tb->t->crc32) ? STSP_OK : STSP_ERR_BAD_CRC;
}

/* stsp_verify() on c, which must return the expected status (STSP_ERR_NOT_INITIALIZED once
 * stopped); returns the stopped flag after it. */
static uint32_t fv_verify(stsp_ctrl_t *c, const fv_table_t *tb, uint32_t stopped)
{
    const stsp_status_t expect = stopped ? STSP_ERR_NOT_INITIALIZED : fv_expected_verify(tb);
    const stsp_status_t st = stsp_verify(c);
    fuzz_check(st == expect);
    if (!stopped) {
        FVS((st == STSP_OK) ? FVS_VERIFY_OK : (st == STSP_ERR_TABLE_CHANGED)
                                                  ? FVS_VERIFY_CHANGED : FVS_VERIFY_CRC);
    }
    return (stopped || (st != STSP_OK)) ? 1u : 0u;
}

static int fv_known_status(stsp_status_t st)
{
    return ((st >= STSP_ERR_BAD_VALUES) && (st <= STSP_WARN_SATURATED)) ||
           (st == STSP_WARN_BAND_FALLBACK);
}

/* u[0..n) is the safe command init copied, bit for bit (whatever the table holds now). */
static int fv_is_hold(const stsp_scalar_t *u, const fv_table_t *tb, uint32_t n)
{
    uint32_t i;
    for (i = 0u; i < n; ++i) {
        if (memcmp(&u[i], &tb->hold0[i], sizeof u[i]) != 0) {
            return 0;
        }
    }
    return 1;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    fuzz_in_t in = {data, size};
    fv_blocks_t blocks;
    fv_table_t tb;
    stsp_ctrl_t c, ref;
    uint32_t nx, nu, n_changes, call, stopped = 0u, changed = 0u;
#ifdef FV_STATS
    static int registered = 0;
    if (!registered) {
        registered = 1;
        (void)atexit(fvs_print);
    }
    FVS(FVS_INPUTS);
#endif
    memset(&blocks, 0, sizeof blocks);
    memset(&tb, 0, sizeof tb);
    fv_build(&in, &blocks, &tb);
    fuzz_check(stsp_init(&c, tb.t) == STSP_OK);
    fuzz_check(stsp_init(&ref, tb.orig) == STSP_OK);
    if (tb.band != NULL) {
        FVS(FVS_BAND);
    }
    if (tb.spline != NULL) {
        FVS(FVS_SPLINE);
    }
    nx = tb.orig->nx;
    nu = tb.orig->nu;
    n_changes = fuzz_u8(&in) % 5u;
    for (call = 0u; (call < FV_MAX_CALLS) && (in.n > 0u); ++call) {
        const uint32_t op = fuzz_u8(&in) % 16u;
        stsp_status_t st, st_ref;
        if ((op < 2u) && (n_changes > 0u)) {
            fv_change(&in, &blocks, &tb);
            --n_changes;
            changed = 1u;
            FVS(fv_header_changed(&tb) ? FVS_HDR : FVS_DATA);
            if (tb.spline != NULL) {
                FVS(fv_header_changed(&tb) ? FVS_SPLINE_HDR : FVS_SPLINE_DATA);
            }
        } else if (op == 1u) {
            stopped = fv_verify(&c, &tb, stopped);
        } else if (op == 2u) {
            st = stsp_reset(&c);
            st_ref = stsp_reset(&ref);
            fuzz_check(st == (stopped ? STSP_ERR_NOT_INITIALIZED : STSP_OK));
            fuzz_check(st_ref == STSP_OK);
#ifdef STSP_ARITH_FIXED_POINT
        } else if (op == 3u) {
            /* The conversions: exactly nx (nu) entries read and written. */
            stsp_f32_t *xf = (stsp_f32_t *)malloc(sizeof(stsp_f32_t) * nx);
            stsp_scalar_t *xq = (stsp_scalar_t *)malloc(sizeof(stsp_scalar_t) * nx);
            stsp_scalar_t *xq_ref = (stsp_scalar_t *)malloc(sizeof(stsp_scalar_t) * nx);
            stsp_f32_t *uf = (stsp_f32_t *)malloc(sizeof(stsp_f32_t) * nu);
            stsp_f32_t *uf_ref = (stsp_f32_t *)malloc(sizeof(stsp_f32_t) * nu);
            stsp_scalar_t *uq = (stsp_scalar_t *)malloc(sizeof(stsp_scalar_t) * nu);
            uint32_t j;
            fuzz_check(xf && xq && xq_ref && uf && uf_ref && uq);
            for (j = 0u; j < nx; ++j) {
                xf[j] = ((float)fuzz_u8(&in) - 128.0f) / 8.0f;
            }
            for (j = 0u; j < nu; ++j) {
                uq[j] = fv_state(&in);
            }
            st = stsp_state_to_q(&c, xf, xq);
            st_ref = stsp_state_to_q(&ref, xf, xq_ref);
            fuzz_check(st == (stopped ? STSP_ERR_NOT_INITIALIZED : st_ref));
            fuzz_check(stopped || (memcmp(xq, xq_ref, sizeof(stsp_scalar_t) * nx) == 0));
            st = stsp_command_to_f32(&c, uq, uf);
            st_ref = stsp_command_to_f32(&ref, uq, uf_ref);
            fuzz_check(st == (stopped ? STSP_ERR_NOT_INITIALIZED : st_ref));
            fuzz_check(stopped || (memcmp(uf, uf_ref, sizeof(stsp_f32_t) * nu) == 0));
            free(xf); free(xq); free(xq_ref); free(uf); free(uf_ref); free(uq);
#endif
        } else {
            /* A step: x and u exactly nx and nu long, separate, the same block, or
             * overlapping (u = x + 1); the reference gets separate copies. */
            const uint32_t layout = fuzz_u8(&in) % 4u;
            const uint32_t sel = fuzz_u8(&in) % 8u;
            const uint32_t big = (nx > nu + 1u) ? nx : nu + 1u;
            stsp_scalar_t *xbuf = (stsp_scalar_t *)malloc(sizeof(stsp_scalar_t) * big);
            stsp_scalar_t *ubuf = (stsp_scalar_t *)malloc(sizeof(stsp_scalar_t) * nu);
            stsp_scalar_t *xr = (stsp_scalar_t *)malloc(sizeof(stsp_scalar_t) * nx);
            stsp_scalar_t *ur = (stsp_scalar_t *)malloc(sizeof(stsp_scalar_t) * nu);
            stsp_scalar_t *x, *u;
            uint32_t tick, j;
            fuzz_check(xbuf && ubuf && xr && ur);
            if (layout == 1u) {
                x = xbuf; u = xbuf;                      /* the same block */
                FVS(FVS_SHARED);
            } else if (layout == 2u) {
                x = xbuf; u = xbuf + 1;                  /* overlapping */
                FVS(FVS_SHARED);
            } else {
                x = xbuf; u = ubuf;
            }
            if ((layout == 0u) || (layout == 3u)) {
                /* separate: x exactly nx long, so ASan sees a read beyond it */
                free(xbuf);
                xbuf = (stsp_scalar_t *)malloc(sizeof(stsp_scalar_t) * nx);
                fuzz_check(xbuf != NULL);
                x = xbuf;
            }
            for (j = 0u; j < nx; ++j) {
                x[j] = fv_state(&in);
            }
            memcpy(xr, x, sizeof(stsp_scalar_t) * nx);
            switch (sel) {
            case 0u: case 1u: case 2u: tick = ref.next_tick; break;
            case 3u: tick = ref.next_tick + 1u + fuzz_u8(&in) % 3u; break;
            case 4u: tick = ref.next_tick - 1u; break;
            case 5u: tick = fuzz_u8(&in) % (tb.orig->n_ticks + 2u); break;
            case 6u: tick = tb.orig->n_ticks + fuzz_u8(&in) % 2u; break;
            default: tick = fuzz_u32(&in); break;
            }
            st = stsp_step(&c, tick, x, u);
            st_ref = stsp_step(&ref, tick, xr, ur);
            fuzz_check(fv_known_status(st_ref));
            if (stopped) {
                FVS(FVS_STOPPED_STEPS);
                fuzz_check(st == STSP_ERR_NOT_INITIALIZED);
                fuzz_check(fv_is_hold(u, &tb, nu));
            } else {
                if (changed) {
                    FVS(FVS_STEPS_CHANGED);
                    if (tb.spline != NULL) {
                        FVS(FVS_SPLINE_STEPS_CHANGED);
                    }
                }
                fuzz_check(st == st_ref);
                fuzz_check(memcmp(u, ur, sizeof(stsp_scalar_t) * nu) == 0);
                fuzz_check(c.next_tick == ref.next_tick && c.stage == ref.stage &&
                         c.latched == ref.latched && c.sat_mask == ref.sat_mask &&
                         c.stage_end == ref.stage_end &&
                         memcmp(c.v, ref.v, sizeof c.v) == 0);
                fuzz_check((st >= STSP_OK) || fv_is_hold(u, &tb, nu));
            }
            free(xbuf); free(ubuf); free(xr); free(ur);
        }
    }
    /* Last, verify (the expected status) and a step after it. */
    {
        stsp_scalar_t *x = (stsp_scalar_t *)calloc(nx, sizeof(stsp_scalar_t));
        stsp_scalar_t *u = (stsp_scalar_t *)calloc(nu, sizeof(stsp_scalar_t));
        stsp_status_t st;
        fuzz_check(x && u);
        stopped = fv_verify(&c, &tb, stopped);
        st = stsp_step(&c, c.next_tick, x, u);
        fuzz_check(stopped ? ((st == STSP_ERR_NOT_INITIALIZED) && fv_is_hold(u, &tb, nu))
                         : fv_known_status(st));
        free(x);
        free(u);
    }
    fv_free(&blocks);
    return 0;
}
