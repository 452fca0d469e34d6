/* Spline tables (stsp_spline_t in float32 builds, stsp_qspline_t in Q15/Q31 builds): their
 * every tick, their layout (and fixed point: value) checks at init and their part of the
 * CRC-32, reached only through the table's ops pointer (stsp_spline_ops, the last definition
 * here), so that a program without a spline table does not link this object. The float32 law
 * itself is below. */
#include "stsp_internal.h"
#include "stsp_crc32.h"

#ifdef STSP_ARITH_FIXED_POINT
#define STSP_CLAMP_NO_FIXUP 1 /* the Q spline ticks clamp before they write u */
#include "stsp_qspline.h"
#endif
#include "stsp_tick.h"
#include "stsp_knots.h"

#ifndef STSP_ARITH_FIXED_POINT
/* The law of a spline table (stsp_spline_t, float32 only), included once by stsp_spline.c
 * after the per-tick law: the stage layout and span search of the cold path, and the law at a span
 * (static, inlined into the spline ordinary tick and the cold path). Private: not installed. */

#ifndef STSP_FIXED_NX
/* The state entry of a gain of x in the generic build, col < nx on a table init accepted,
 * clamped whatever col holds now (a table changed after init: a wrong command, no access
 * outside x). An STSP_FIXED_* build reads no col on the ordinary tick (x_mask). */
static inline uint32_t stsp_x_index(uint32_t col, uint32_t nx)
{
    return (col < nx) ? col : (nx - 1u);
}
#endif

/* Cold path: stage s's layout into p (first tick, knots, entries, coefficients), read from the
 * spline arrays and bounded by the lengths init validated, whatever the arrays hold now: a
 * stage whose layout no longer fits them (a table changed after init, until stsp_verify()
 * notices) gets one span on the first eight knots and no entries, so a wrong command but no
 * access outside the arrays. p->knot and p->coef are the stage's first knot and coefficient.
 * Returns the stage's number of spans S. */
static uint32_t stsp_spline_stage(const stsp_header_t *h, uint32_t s, stsp_span_t *p)
{
    const stsp_spline_t *sp = &h->sp;
    const uint32_t nu = stsp_nu(h);
    const uint32_t k0 = sp->knot_start[s];
    const uint32_t k1 = sp->knot_start[s + 1u];
    const uint32_t c0 = sp->coef_start[s];
    const uint32_t e0 = sp->row_start[s * nu];
    uint32_t fits = 1u;
    uint32_t e1 = e0;
    uint32_t n_spans = 1u;
    uint32_t i;
    if ((k1 > sp->n_knots) || (k1 < k0) || ((k1 - k0) < 8u) || (c0 > sp->n_coef) ||
        (e0 > sp->n_entries)) {
        fits = 0u;
    }
    for (i = 0u; i < nu; ++i) {
        const uint32_t end = sp->row_start[(s * nu) + i + 1u];
        uint32_t k = e1;
        uint32_t mask = 0u;
        if ((end < e1) || (end > sp->n_entries)) {
            fits = 0u;
        } else {
            /* The row's gains of x: its first entries (init checked col increasing). */
            while ((k < end) && (sp->col[k] < stsp_nx(h))) {
                mask |= (uint32_t)1u << sp->col[k];
                ++k;
            }
            e1 = end;
        }
        p->k_end[i] = (uint16_t)(k - e0);
        p->x_mask[i] = mask;
        p->row_end[i] = (uint16_t)(e1 - e0);
    }
    if (fits != 0u) {
        n_spans = (k1 - k0) - 7u;
        if ((e1 - e0) > ((sp->n_coef - c0) / (n_spans + 3u))) {
            fits = 0u;
        }
    }
    if (fits != 0u) {
        p->knot = &sp->knot[k0];
        p->coef = &sp->coef[c0];
        p->col = &sp->col[e0];
    } else {
        n_spans = 1u;
        p->knot = sp->knot; /* n_knots >= 8: init checked every stage's */
        p->coef = sp->coef;
        p->col = sp->col;
        for (i = 0u; i < nu; ++i) {
            p->k_end[i] = 0u;
            p->row_end[i] = 0u;
            p->x_mask[i] = 0u;
        }
    }
    p->stride = n_spans + 3u;
    p->first = h->stage_start[s];
    return n_spans;
}

/* Input i's folded coefficients at fold[4 i .. 4 i + 3]: dst = src for the table's inputs. */
static void stsp_spline_copy_fold(const stsp_header_t *h, stsp_f32_t *dst, const stsp_f32_t *src)
{
    uint32_t i;
    for (i = 0u; i < (4u * stsp_nu(h)); ++i) {
        dst[i] = src[i];
    }
}

/* Cold path: record span p in the instance's dst, k_end, row_end and the fold only for the
 * table's inputs (the rest stays zero, as reset left it). */
static void stsp_spline_commit(const stsp_header_t *h, stsp_span_t *dst, const stsp_span_t *p)
{
    uint32_t i;
    dst->knot = p->knot;
    dst->inv = p->inv;
    dst->coef = p->coef;
    dst->col = p->col;
    dst->first = p->first;
    dst->next = p->next;
    dst->stride = p->stride;
    dst->span = p->span;
    dst->n_spans = p->n_spans;
    for (i = 0u; i < stsp_nu(h); ++i) {
        dst->k_end[i] = p->k_end[i];
        dst->row_end[i] = p->row_end[i];
        dst->x_mask[i] = p->x_mask[i];
    }
    stsp_spline_copy_fold(h, dst->fold, p->fold);
}

/* 1 / (U[sigma + 4] - U[sigma + 3]) for the span whose knots start at k = U[sigma + 1]: the
 * first division of The NURBS Book A2.2, 1 / (right1 + left1), which does not depend on tau
 * (right1 + left1 = (k[3] - tau) + (tau - k[2]), integers below 2^24 on a valid table: every
 * step exact, so the same bits as k[3] - k[2]). Once per span instead of once per tick. */
static stsp_f32_t stsp_span_inv(const stsp_f32_t *k)
{
    return 1.0f / (k[3] - k[2]);
}

/* The first tick after span sigma (of n_spans; `first`, the stage's first tick, and k, the
 * span's knots from U[sigma + 1]): `end` in the last span, else the tick of U[sigma + 4], an
 * integer in (tick - first, end - first) on a valid table (the conversion is then exact, and
 * the comparisons make it defined whatever a knot changed since init holds: else tick + 1). */
static uint32_t stsp_span_end(const stsp_f32_t *k_span, uint32_t sigma, uint32_t n_spans,
                              uint32_t tick, uint32_t first, uint32_t end)
{
    const uint32_t in_stage = tick - first;
    const uint32_t length = end - first;
    uint32_t next = end;
    if ((sigma + 1u) < n_spans) {
        const stsp_f32_t k = k_span[3];
        next = tick + 1u;
        if ((k > (stsp_f32_t)in_stage) && (k < (stsp_f32_t)length) &&
            ((uint32_t)k < length)) {
            next = first + (uint32_t)k;
        }
    }
    return next;
}

/* Cold path: the span of `tick` in stage s, into p (stage layout: stsp_spline_stage): the
 * first span sigma from `from` (bounded by S) with tau < U[sigma + 4], so U[sigma + 3] <= tau
 * on a valid table when U[from + 3] <= tau, at most S - 1 steps; and the tick it ends at, the
 * ordinary tick's bound (stsp_span_end). */
static void stsp_spline_span(const stsp_header_t *h, uint32_t s, uint32_t from, uint32_t tick,
                             uint32_t end, stsp_span_t *p)
{
    const uint32_t n_spans = stsp_spline_stage(h, s, p);
    const stsp_f32_t *U = p->knot;
    const uint32_t in_stage = tick - p->first;
    const stsp_f32_t tau = (stsp_f32_t)in_stage;
    uint32_t sigma = (from < n_spans) ? from : 0u;
    while (((sigma + 1u) < n_spans) && !(tau < U[sigma + 4u])) {
        ++sigma;
    }
    p->span = sigma;
    p->n_spans = n_spans;
    p->knot = &U[sigma + 1u];
    p->inv = stsp_span_inv(p->knot);
    p->next = stsp_span_end(p->knot, sigma, n_spans, tick, p->first, end);
    if (p->row_end[stsp_nu(h) - 1u] > 0u) {
        p->coef = &p->coef[sigma]; /* < the stage's S + 3 coefficients of its first entry */
    }
}

/* The four cubic B-splines N[0..3] that are nonzero on a span, at tau, from the span's knots
 * k[0..5] = U[i-2..i+3] (i = sigma + 3): The NURBS Book A2.2, operation for operation in the
 * order of stsp_controller.h, except that the first step of each round, saved + right[1] temp
 * with saved = +0, is right[1] temp: +0 + p is p for every p >= +0, and on a valid span every
 * term is >= +0 (left[k] >= 0, right[k] > 0, so no quotient or product is -0). */
static STSP_ALWAYS_INLINE void stsp_spline_basis(const stsp_f32_t *k, stsp_f32_t inv,
                                                 stsp_f32_t tau, stsp_f32_t *n)
{
    const stsp_f32_t left1 = tau - k[2];
    const stsp_f32_t left2 = tau - k[1];
    const stsp_f32_t left3 = tau - k[0];
    const stsp_f32_t right1 = k[3] - tau;
    const stsp_f32_t right2 = k[4] - tau;
    const stsp_f32_t right3 = k[5] - tau;
    stsp_f32_t n0;
    stsp_f32_t n1;
    stsp_f32_t n2;
    stsp_f32_t temp;
    stsp_f32_t saved;
    /* round 1 (N[0] = 1): temp = 1 / (right1 + left1), the span's inv (stsp_span_inv) */
    temp = inv;
    n0 = right1 * temp;
    n1 = left1 * temp;
    /* round 2 */
    temp = n0 / (right1 + left2);
    n0 = right1 * temp;
    saved = left2 * temp;
    temp = n1 / (right2 + left1);
    n1 = stsp_mla(saved, right2, temp);
    n2 = left1 * temp;
    /* round 3 */
    temp = n0 / (right1 + left3);
    n[0] = right1 * temp;
    saved = left3 * temp;
    temp = n1 / (right2 + left2);
    n[1] = stsp_mla(saved, right2, temp);
    saved = left2 * temp;
    temp = n2 / (right3 + left1);
    n[2] = stsp_mla(saved, right3, temp);
    n[3] = left1 * temp;
}

/* Cold path: the feed-forward of each input folded with the latch v into one spline, for the
 * span of p's stage (layout, k_end, row_end) whose first entry's coefficients are at coef:
 * for r = 0..3, over input i's entries after its
 * gains of x (k0[i]: z = 1; L[i][c]: z = v[c]) in stored order,
 *     fold[4 i + r] = ((+0 - c_e1[r] z_e1) - c_e2[r] z_e2) - ...
 * with c_e the entry's coefficients of the span (every product and difference rounded, not
 * fused), so that the ordinary tick evaluates one spline per input for k0[i] + L[i] v instead
 * of one per entry. A col changed since init is bounded: v's index clamped to n_latch - 1 (v
 * has STSP_MAX_LATCH >= 1 entries, zero beyond n_latch). */
static void stsp_spline_fold(const stsp_header_t *h, const stsp_span_t *p,
                             const stsp_f32_t *coef, const stsp_f32_t *v, stsp_f32_t *fold)
{
    const uint32_t nx = stsp_nx(h);
    const uint32_t n_latch = stsp_n_latch(h);
    uint32_t last = 0u; /* v's last index */
    uint32_t i;
    if (n_latch > 0u) {
        last = n_latch - 1u;
    }
    for (i = 0u; i < stsp_nu(h); ++i) {
        stsp_f32_t f[4] = {0.0f, 0.0f, 0.0f, 0.0f};
        uint32_t e;
        uint32_t r;
        for (e = p->k_end[i]; e < p->row_end[i]; ++e) {
            const uint32_t col = p->col[e];
            const uint32_t c = col - nx - 1u; /* wraps for col <= nx: clamped below */
            const stsp_f32_t z = (col == nx) ? 1.0f : v[(c < last) ? c : last];
            const stsp_f32_t *cf = &coef[e * p->stride];
            for (r = 0u; r < 4u; ++r) {
                f[r] = stsp_mls(f[r], cf[r], z);
            }
        }
        for (r = 0u; r < 4u; ++r) {
            fold[(4u * i) + r] = f[r];
        }
    }
}

/* g = ((n[0] c[0] + n[1] c[1]) + n[2] c[2]) + n[3] c[3], every product and sum rounded (not
 * fused): a gain from its four coefficients of the span. On a single-precision VFP one VLDM of
 * c and VMUL, three VMLA (chained: the bits of the C below, as for stsp_mla) in one asm
 * statement, so that the coefficients land in consecutive registers (s12-s15: caller-saved,
 * declared clobbered). */
static STSP_ALWAYS_INLINE stsp_f32_t
/* cppcheck-suppress misra-c2012-2.7 ; deviation D5: the parameters are asm operands */
stsp_spline_gain(const stsp_f32_t *c, const stsp_f32_t *n)
{
#if STSP_VFP_MAC
    stsp_f32_t g;
    __asm__ volatile("vldmia %[c], {s0-s3}\n\t"
                     "vmul.f32 %[g], %[n0], s0\n\t"
                     "vmla.f32 %[g], %[n1], s1\n\t"
                     "vmla.f32 %[g], %[n2], s2\n\t"
                     "vmla.f32 %[g], %[n3], s3"
                     : [g] "=&t"(g)
                     : [c] "r"(c), [n0] "t"(n[0]), [n1] "t"(n[1]), [n2] "t"(n[2]),
                       [n3] "t"(n[3]), "m"(c[0]), "m"(c[1]), "m"(c[2]), "m"(c[3])
                     : "s0", "s1", "s2", "s3");
    return g;
#else
    stsp_f32_t g = n[0] * c[0];
    g = stsp_mla(g, n[1], c[1]);
    g = stsp_mla(g, n[2], c[2]);
    return stsp_mla(g, n[3], c[3]);
#endif
}

/* acc - g x for one gain of x whose four coefficients of the span are c[0..3] (g as
 * stsp_spline_gain, then the product g x rounded and subtracted). On a single-precision VFP
 * one VLDM of c and VMUL, three VMLA, VMLS in one asm statement (g in a scratch register the
 * compiler picks). */
static STSP_ALWAYS_INLINE stsp_f32_t
/* cppcheck-suppress misra-c2012-2.7 ; deviation D5: the parameters are asm operands */
stsp_spline_entry(stsp_f32_t acc, const stsp_f32_t *c, const stsp_f32_t *n, stsp_f32_t x)
{
#if STSP_VFP_MAC
    stsp_f32_t r = acc;
    stsp_f32_t g; /* scratch: the gain */
    __asm__ volatile("vldmia %[c], {s0-s3}\n\t"
                     "vmul.f32 %[g], %[n0], s0\n\t"
                     "vmla.f32 %[g], %[n1], s1\n\t"
                     "vmla.f32 %[g], %[n2], s2\n\t"
                     "vmla.f32 %[g], %[n3], s3\n\t"
                     "vmls.f32 %[r], %[g], %[x]"
                     : [r] "+t"(r), [g] "=&t"(g)
                     : [c] "r"(c), [n0] "t"(n[0]), [n1] "t"(n[1]), [n2] "t"(n[2]),
                       [n3] "t"(n[3]), [x] "t"(x), "m"(c[0]), "m"(c[1]), "m"(c[2]), "m"(c[3])
                     : "s0", "s1", "s2", "s3");
    return r;
#else
    return stsp_mls(acc, stsp_spline_gain(c, n), x);
#endif
}

/* The spline law at `tick` in p's stage, in the span whose knots start at knot (U[sigma + 1]),
 * with inv its stsp_span_inv, whose first entry's coefficients at coef and whose folded feed-forward (stsp_spline_fold) is
 * fold, into y (x and u may overlap: y is never the caller's u): the basis once, then per
 * input i, acc = the folded spline's value (stsp_spline_gain of fold[4 i ..]) and, over the
 * row's gains of x in stored order, acc = acc - g x[col] (stsp_spline_entry). Returns nonzero
 * when the step needs the cold path: as stsp_law_alarm(), and also when the state is not finite
 * (an input need not use every x[j], so the command does not reveal it: the state's sum joins
 * the command's in the check; it also overflows for some huge finite states, a false alarm
 * the cold path clears). A col changed since init is bounded by stsp_x_index() (generic
 * build) or not read (x_mask, STSP_FIXED_* build). */
static STSP_ALWAYS_INLINE uint32_t stsp_spline_law(const stsp_header_t *h, const stsp_span_t *p,
                                                   const stsp_f32_t *knot, stsp_f32_t inv,
                                                   const stsp_f32_t *coef,
                                                   const stsp_f32_t *fold, uint32_t tick,
                                                   const stsp_f32_t *x, stsp_f32_t *y,
                                                   uint32_t limited)
{
    const uint32_t nx = stsp_nx(h);
    const uint32_t nu = stsp_nu(h);
    const uint32_t stride = p->stride;
    const uint32_t in_stage = tick - p->first; /* tau, exact: < 2^24 on a valid table */
    const uint8_t *col = p->col;
    stsp_f32_t n[4];
    stsp_f32_t total = -0.0f; /* of x, then of y: -0 + a = a, the compiler drops this add */
    uint32_t e = 0u;
    uint32_t i;
    uint32_t out = 0u;
    STSP_UNROLL
    for (i = 0u; i < nx; ++i) {
        total += x[i];
    }
    stsp_spline_basis(knot, inv, (stsp_f32_t)in_stage, n);
    STSP_UNROLL
    for (i = 0u; i < nu; ++i) {
        uint32_t off = e * stride; /* an offset, not a pointer: it may end beyond coef */
        stsp_f32_t acc = stsp_spline_gain(&fold[4u * i], n);
#ifdef STSP_FIXED_NX
        /* The row's gains of x by its bit mask of their columns (set on the cold path with
         * k_end): unrolled over j < nx with x[j] in a register, the entries in stored order
         * (increasing col), no column read. */
        const uint32_t mask = p->x_mask[i];
        uint32_t j;
        (void)col;
        STSP_UNROLL
        for (j = 0u; j < nx; ++j) {
            if ((mask & ((uint32_t)1u << j)) != 0u) {
                acc = stsp_spline_entry(acc, &coef[off], n, x[j]);
                off += stride;
            }
        }
#else
        const uint8_t *cp = &col[e];
        const uint8_t *const ce = &col[p->k_end[i]]; /* >= cp: k_end[i] >= row_end[i - 1] */
        while (cp < ce) {
            acc = stsp_spline_entry(acc, &coef[off], n, x[stsp_x_index(*cp, nx)]);
            ++cp;
            off += stride;
        }
#endif
        e = p->row_end[i];
        y[i] = acc;
    }
    if (limited != 0u) {
        out = stsp_law_alarm(h, y, limited);
    } else {
        STSP_UNROLL
        for (i = 0u; i < nu; ++i) {
            total += y[i];
        }
    }
    /* total - total is +0 for a finite total, NaN for NaN and +-Inf. */
    if (!((total - total) == 0.0f)) {
        out = 1u;
    }
    return out;
}

#endif

#ifdef STSP_ARITH_FIXED_POINT
/* The fixed-point spline part of stsp_table_crc32()'s serialization (called by stsp_crc_of):
 * counts, then the six arrays, index arrays (span_log2, row_start, col, shift, coef_start) as
 * u32 each, the coefficients as the table's scalars (little-endian int16 or int32). */
static uint32_t stsp_spline_crc(uint32_t crc, const stsp_qspline_t *sp, uint32_t ns, uint32_t nu)
{
    const uint32_t rows = (ns * nu) + 1u;
    uint32_t c = crc;
    uint32_t i;
    c = stsp_crc32_u32(c, sp->n_entries);
    c = stsp_crc32_u32(c, sp->n_coef);
    for (i = 0u; i < ns; ++i) {
        c = stsp_crc32_u32(c, (uint32_t)sp->span_log2[i]);
    }
    for (i = 0u; i < rows; ++i) {
        c = stsp_crc32_u32(c, (uint32_t)sp->row_start[i]);
    }
    for (i = 0u; i < sp->n_entries; ++i) {
        c = stsp_crc32_u32(c, (uint32_t)sp->col[i]);
    }
    for (i = 0u; i < sp->n_entries; ++i) {
        c = stsp_crc32_u32(c, (uint32_t)sp->shift[i]);
    }
    c = stsp_crc32_u32s(c, sp->coef_start, ns + 1u);
    return stsp_crc32_scalars(c, sp->coef, sp->n_coef);
}
/* A fixed-point spline table's layout (stsp_qspline_t): stsp_qspline_check with the validated
 * copy's dimensions. */
static stsp_status_t stsp_spline_check_dims(const stsp_header_t *h)
{
    const uint32_t nz = (uint32_t)h->nx + 1u + h->n_latch;
    return stsp_qspline_check(&h->sp, h->stage_start, h->n_stages, h->nu, nz);
}

/* Every law row of a fixed-point spline table, at every tick of every stage: the gains as
 * evaluated (exact, stsp_qspline_value) with |k0| + sum|K| + sum|L| <= 2^F - 1, the per-tick
 * format's row bound (stsp_check_values), so that stsp_spline_step's law cannot overflow and
 * every gain fits stsp_scalar_t (stsp_qspline_rows_check without columns). One evaluation per
 * stored entry and tick (init only). */
static stsp_status_t stsp_spline_check_values(const stsp_header_t *h)
{
    return stsp_qspline_rows_check(&h->sp, h->stage_start, h->n_stages, h->nu, NULL, 0u);
}

/* Stage s's layout at tick tau, re-read from the spline arrays on every tick and bounded by
 * the lengths init validated, whatever the arrays hold now (a table changed after init, until
 * stsp_verify() notices): span_log2 at most 9; the row ends from row_start[s nu] nondecreasing
 * and at most n_entries; coef_start[s] <= coef_start[s+1] <= n_coef; and the tick's span
 * inside each entry's stride (sigma + 4 <= stride), so that the last coefficient read,
 * coef_start[s] + (entries - 1) stride + sigma + 3, is below coef_start[s+1]. A stage that no
 * longer fits gets no entries (every input's command 0, then clamped): a wrong command, but no
 * access outside the validated arrays and no undefined shift. On a table that passed init it
 * always fits. Fills the span's basis p and returns the entries (0 if it does not fit), with
 * *k3 = 3k, *stride and *c the first coefficient the law reads. */
static STSP_ALWAYS_INLINE uint32_t stsp_qspline_layout(const stsp_header_t *h, uint32_t s,
                                                       uint32_t tau, uint32_t *p, uint32_t *k3,
                                                       uint32_t *stride,
                                                       const stsp_scalar_t **c)
{
    const stsp_qspline_t *sp = &h->sp;
    const uint32_t nu = stsp_nu(h);
    const uint32_t k_raw = sp->span_log2[s];
    const uint32_t k = (k_raw <= STSP_QSPLINE_MAX_SPAN_LOG2) ? k_raw : 0u;
    const uint32_t e0 = sp->row_start[s * nu];
    const uint32_t c0 = sp->coef_start[s];
    const uint32_t c1 = sp->coef_start[s + 1u];
    const uint32_t sigma = stsp_qspline_basis(k, tau, p);
    uint32_t fits = 1u;
    uint32_t prev = e0;
    uint32_t entries = 0u;
    uint32_t i;
    if ((k != k_raw) || (e0 > sp->n_entries) || (c0 > c1) || (c1 > sp->n_coef)) {
        fits = 0u;
    }
    for (i = 0u; i < nu; ++i) {
        const uint32_t end = sp->row_start[(s * nu) + i + 1u];
        if ((end < prev) || (end > sp->n_entries)) {
            fits = 0u;
        } else {
            prev = end;
        }
    }
    *stride = 0u;
    *c = sp->coef; /* no pointer arithmetic past the array when the stage has no entries */
    if (fits != 0u) {
        entries = prev - e0;
    }
    if (entries > 0u) {
        const uint32_t st = (c1 - c0) / entries;
        if ((st >= 4u) && (sigma <= (st - 4u))) {
            *stride = st;
            *c = &sp->coef[c0 + sigma];
        } else {
            entries = 0u;
        }
    }
    *k3 = 3u * k;
    return entries;
}

/* The fixed-point spline law at tick tau of stage s with multipliers v, into y (never the
 * caller's u): per input i, over its stored entries e in order, the gain g_e (stsp_qspline.h,
 * exact, one rounding) and
 *     acc = 2^(2F) + 2^(F-1) + sum_e g_e z[col_e],  z = [x, 0, v],
 *     y[i] = (acc >> F) - 2^F + g_k0     (g_k0: the gain of col nx, k0[i]; 0 if not stored)
 * the per-tick law (stsp_controller.c) with the evaluated gains, bit for bit (the sum is exact, so
 * its order does not matter). The stage's layout as stsp_qspline_layout bounds it; an entry's
 * operand index is bounded too (a table changed after init: an index beyond z contributes
 * nothing; a scale outside 1..30 gives a wrong gain, its shifts taken modulo 64 by
 * stsp_qspline_biased, no undefined shift; on a table that passed init neither happens). Returns stsp_law_alarm(). Time: the same at every tick of a stage (its
 * entries), the largest stage's at most. acc0: each input's accumulator to start from (the
 * parametric law's, with its columns' terms: stsp_qspline_param_law), or NULL for
 * stsp_q_start(). */
static STSP_ALWAYS_INLINE uint32_t stsp_qspline_law(const stsp_header_t *h, uint32_t s,
                                                    uint32_t tau, const stsp_scalar_t *x,
                                                    const stsp_scalar_t *v, stsp_scalar_t *y,
                                                    uint32_t limited, const stsp_uacc_t *acc0)
{
    const stsp_qspline_t *sp = &h->sp;
    const uint32_t nx = stsp_nx(h);
    const uint32_t nu = stsp_nu(h);
    const uint32_t n_latch = stsp_n_latch(h);
    const uint32_t nz = nx + 1u + n_latch;
    stsp_scalar_t z[STSP_MAX_NX + 1u + STSP_MAX_LATCH];
    uint32_t p[4];
    uint32_t k3;
    uint32_t stride;
    const stsp_scalar_t *c;
    const uint32_t entries = stsp_qspline_layout(h, s, tau, p, &k3, &stride, &c);
    const uint8_t *col = sp->col;
    const uint8_t *shift = sp->shift;
    uint32_t e = sp->row_start[s * nu];
    uint32_t i;
    for (i = 0u; i < nx; ++i) {
        z[i] = x[i];
    }
    z[nx] = (stsp_scalar_t)0;
    for (i = 0u; i < n_latch; ++i) {
        z[nx + 1u + i] = v[i];
    }
    for (i = 0u; i < nu; ++i) {
        const uint32_t end = (entries > 0u) ? sp->row_start[(s * nu) + i + 1u] : e;
        stsp_uacc_t acc = (acc0 != NULL) ? acc0[i] : stsp_q_start();
        stsp_scalar_t k0 = (stsp_scalar_t)0;
        for (; e < end; ++e) {
            const uint32_t j = col[e];
            const stsp_scalar_t g = stsp_qspline_narrow(c, p, k3 + shift[e]);
            acc = stsp_q_mac(acc, g, z[(j < nz) ? j : nx]);
            k0 = (j == nx) ? g : k0;
            c = &c[stride];
        }
        y[i] = stsp_q_round(acc, k0);
    }
    return stsp_law_alarm(h, y, limited);
}

/* Every tick of a fixed-point spline table but its ordinary one (stsp_spline_step): the
 * per-tick cold path's plan (range, order, stage, latch) and commit, the spline law at the
 * tick, the clamp. There is no non-finite case (integers). Out of line, so that the ordinary
 * tick keeps its registers. */
static STSP_NOINLINE stsp_status_t stsp_qspline_step_cold(stsp_ctrl_t *ctrl, uint32_t tick,
                                                          const stsp_scalar_t *x,
                                                          stsp_scalar_t *u)
{
    const stsp_header_t *h = &ctrl->checked;
    stsp_scalar_t v_new[STSP_MAX_LATCH];
    stsp_scalar_t y[STSP_MAX_NU];
    stsp_plan_t plan = {0u, 0u};
    stsp_status_t status;
    uint16_t mask = 0u;
    stsp_zero(v_new, STSP_MAX_LATCH);
    status = stsp_plan_tick(ctrl, tick, x, v_new, &plan);
    if (status < STSP_OK) {
        stsp_hold(ctrl, u);
        return status;
    }
    if (stsp_qspline_law(h, plan.stage, tick - h->stage_start[plan.stage], x, v_new, y,
                         ctrl->limited, NULL) != 0u) {
        const stsp_status_t st = stsp_limit(h, x, y, &mask);
        if (st != STSP_OK) {
            status = st; /* STSP_WARN_SATURATED over a tick warning */
        }
    }
    stsp_copy(u, y, stsp_nu(h));
    ctrl->sat_mask = mask;
    stsp_commit_tick(ctrl, tick, &plan, v_new);
    ctrl->stage_end = 0u;
    return status;
}

/* Every tick of a fixed-point spline table (its stage_end stays 0, so each leaves stsp_step's
 * ordinary path). The ordinary one is here: the expected tick (next_tick) of a latched
 * instance before the end of its stage (stsp_stage_end, as the plan reads it now). For it the
 * plan's checks all pass with STSP_OK, its stage search stays in the instance's stage and it
 * keeps the latched v, so this is the cold path's step without them: the spline law at the
 * tick on the kept v, the clamp, next_tick; the same status, command, mask and instance state
 * (test_qspline_ctrl.c runs both paths against the per-tick law). Anything else takes
 * stsp_qspline_step_cold. */
static stsp_status_t stsp_spline_step(stsp_ctrl_t *ctrl, uint32_t tick, const stsp_scalar_t *x,
                               stsp_scalar_t *u)
{
    const stsp_header_t *h = &ctrl->checked;
    const uint16_t stage = ctrl->stage;
    stsp_scalar_t y[STSP_MAX_NU];
    stsp_status_t status = STSP_OK;
    uint16_t mask = 0u;
    if ((tick != ctrl->next_tick) || (ctrl->latched == 0u) ||
        (tick >= stsp_stage_end(h, stage))) {
        return stsp_qspline_step_cold(ctrl, tick, x, u);
    }
    if (stsp_qspline_law(h, stage, tick - h->stage_start[stage], x, ctrl->v, y,
                         ctrl->limited, NULL) != 0u) {
        status = stsp_limit(h, x, y, &mask);
    }
    stsp_copy(u, y, stsp_nu(h));
    ctrl->sat_mask = mask;
    ctrl->next_tick = tick + 1u;
    return status;
}

/* stsp_params.c's tick of a fixed-point spline table with spline columns (stsp_params.h,
 * format 2; blocks of stsp_qspline.h): per input i the accumulator starts from the bias plus
 * sum_p g_p d_q[p], g_p the gain of block (s, i, p) at tick `tick` (stsp_qspline_narrow on
 * the stage's span basis), and the law of stsp_qspline_law goes on over the entries: one
 * rounding of the whole sum, the per-tick law over [x_q; d_q] bit for bit. The blocks'
 * place comes from the stage layout as it reads now (stsp_qspline_col_start); a layout that
 * no longer fits cols[n_cols] (a table changed after init) leaves the columns out, a scale
 * outside 1..30 gives a wrong gain (its shift taken modulo 64 by stsp_qspline_biased): a wrong
 * command, no access outside the arrays, no undefined shift. Writes
 * the unclamped y (stsp_params.c clamps). Time: nu P gains of 4 multiply-adds more than the
 * plain tick, and the stage search of stsp_qspline_col_start (n_stages at most). */
static void stsp_qspline_param_law(stsp_ctrl_t *ctrl, uint32_t s, uint32_t tick,
                                   const stsp_scalar_t *x, const stsp_scalar_t *v,
                                   const stsp_scalar_t *cols, uint32_t n_cols,
                                   const stsp_scalar_t *d, uint32_t n_params, uint32_t kept,
                                   stsp_scalar_t *y)
{
    const stsp_header_t *h = &ctrl->checked;
    const stsp_qspline_t *sp = &h->sp;
    const uint32_t nu = stsp_nu(h);
    const uint32_t tau = tick - h->stage_start[s];
    const uint32_t k_raw = sp->span_log2[s];
    const uint32_t k = (k_raw <= STSP_QSPLINE_MAX_SPAN_LOG2) ? k_raw : 0u;
    stsp_uacc_t acc0[STSP_MAX_NU];
    uint32_t p[4];
    uint32_t width;
    const uint32_t sigma = stsp_qspline_basis(k, tau, p);
    const uint64_t first = stsp_qspline_col_start(sp, h->stage_start, s, nu * n_params, &width);
    const uint64_t words = (uint64_t)nu * (uint64_t)n_params * (uint64_t)width;
    uint32_t use = 0u;
    uint32_t i;
    (void)kept; /* no span cache in fixed point: every tick evaluates its entries */
    if ((k == k_raw) && ((sigma + 4u) < width) && (first <= (uint64_t)n_cols) &&
        (words <= ((uint64_t)n_cols - first))) {
        use = 1u;
    }
    for (i = 0u; i < nu; ++i) {
        stsp_uacc_t acc = stsp_q_start();
        if (use != 0u) {
            const stsp_scalar_t *block = &cols[(uint32_t)first + (i * n_params * width)];
            uint32_t q;
            for (q = 0u; q < n_params; ++q) {
                const uint32_t sh = (uint32_t)(int32_t)block[0];
                acc = stsp_q_mac(acc, stsp_qspline_narrow(&block[1u + sigma], p, (3u * k) + sh),
                                 d[q]);
                block = &block[width];
            }
        }
        acc0[i] = acc;
    }
    (void)stsp_qspline_law(h, s, tau, x, v, y, 0u, acc0);
}
#endif

#ifndef STSP_ARITH_FIXED_POINT

/* Stage s of a spline table, once knot_start, row_start and coef_start are known to be
 * nondecreasing within their arrays: fewer than 2^24 ticks, S + 3 coefficients for each of its
 * entries (no product is formed: it could wrap), its knots (stsp_knots_ok). */
static stsp_status_t stsp_check_spline_stage(const stsp_header_t *h, uint32_t s)
{
    const stsp_spline_t *p = &h->sp;
    const uint32_t nu = h->nu;
    const uint32_t ticks = h->stage_start[s + 1u] - h->stage_start[s];
    const uint32_t k0 = p->knot_start[s];
    const uint32_t n_knots = p->knot_start[s + 1u] - k0;
    const uint32_t n_coef = p->coef_start[s + 1u] - p->coef_start[s];
    const uint32_t entries = (uint32_t)p->row_start[(s + 1u) * nu] - p->row_start[s * nu];
    const uint32_t stride = n_knots - 4u; /* S + 3 */
    if ((ticks >= 16777216u) || ((n_coef % stride) != 0u) || ((n_coef / stride) != entries) ||
        (stsp_knots_ok(&p->knot[k0], n_knots, ticks) == 0)) {
        return STSP_ERR_BAD_DIMS;
    }
    return STSP_OK;
}

/* A spline table's layout (stsp_spline_t): its arrays present; the three index arrays from 0
 * to their lengths and nondecreasing, at least 8 knots per stage (all checked before any
 * other element is read through them); every operand index below nx + 1 + n_latch; each stage
 * as stsp_check_spline_stage says. */
static stsp_status_t stsp_spline_check_dims(const stsp_header_t *h)
{
    const stsp_spline_t *p = &h->sp;
    const uint32_t ns = h->n_stages;
    const uint32_t rows = ns * (uint32_t)h->nu;
    const uint32_t nz = (uint32_t)h->nx + 1u + h->n_latch;
    uint32_t i;
    if ((p->knot_start == NULL) || (p->knot == NULL) || (p->row_start == NULL) ||
        (p->col == NULL) || (p->coef_start == NULL) || (p->coef == NULL)) {
        return STSP_ERR_NULL;
    }
    if ((p->knot_start[0] != 0u) || (p->knot_start[ns] != p->n_knots) ||
        (p->row_start[0] != 0u) || (p->row_start[rows] != p->n_entries) ||
        (p->coef_start[0] != 0u) || (p->coef_start[ns] != p->n_coef)) {
        return STSP_ERR_BAD_DIMS;
    }
    for (i = 0u; i < ns; ++i) {
        const uint32_t k0 = p->knot_start[i];
        const uint32_t k1 = p->knot_start[i + 1u];
        if ((k1 < k0) || ((k1 - k0) < 8u) || (p->coef_start[i + 1u] < p->coef_start[i])) {
            return STSP_ERR_BAD_DIMS;
        }
    }
    for (i = 0u; i < rows; ++i) {
        if (p->row_start[i + 1u] < p->row_start[i]) {
            return STSP_ERR_BAD_DIMS;
        }
    }
    for (i = 0u; i < p->n_entries; ++i) {
        if (p->col[i] >= nz) {
            return STSP_ERR_BAD_DIMS;
        }
    }
    /* Within a row the operands increase: the gains of x first (the ordinary tick's loop),
     * then k0 and L (folded into one spline per input at a span change). */
    for (i = 0u; i < rows; ++i) {
        uint32_t e;
        for (e = (uint32_t)p->row_start[i] + 1u; e < p->row_start[i + 1u]; ++e) {
            if (p->col[e] <= p->col[e - 1u]) {
                return STSP_ERR_BAD_DIMS;
            }
        }
    }
    for (i = 0u; i < ns; ++i) {
        const stsp_status_t st = stsp_check_spline_stage(h, i);
        if (st != STSP_OK) {
            return st;
        }
    }
    return STSP_OK;
}
/* Cold path, spline table: the span of `tick` in `stage`, into p. The search starts at the
 * span of the last step when the tick stays in its stage (a later tick, or the same again:
 * never before that span), else at the stage's first span. */
static void stsp_spline_locate(const stsp_ctrl_t *c, uint32_t tick, uint16_t stage,
                               stsp_span_t *p)
{
    const uint32_t from = ((c->latched != 0u) && (stage == c->stage)) ? c->span.span : 0u;
    stsp_spline_span(&c->checked, stage, from, tick, stsp_stage_end(&c->checked, stage), p);
}

/* The first tick of the next span, success: that span (stsp_step_next_span checked that
 * there is one in the stage) and its fold, into the instance. */
static void stsp_spline_next_span(stsp_ctrl_t *c, uint32_t tick, const stsp_f32_t *knot,
                                  stsp_f32_t inv, const stsp_f32_t *coef,
                                  const stsp_f32_t *fold)
{
    stsp_span_t *p = &c->span;
    const uint32_t sigma = p->span + 1u;
    p->span = sigma;
    p->knot = knot;
    p->inv = inv;
    p->coef = coef;
    p->next = stsp_span_end(knot, sigma, p->n_spans, tick, p->first,
                            stsp_stage_end(&c->checked, c->stage));
    stsp_spline_copy_fold(&c->checked, p->fold, fold);
}

/* Cold path, spline table: the state and a fresh latch must be finite, as the command does
 * not show it (an input need not use every x[j] or v[c]): STSP_ERR_NONFINITE_STATE, else
 * STSP_ERR_NONFINITE_OUTPUT for a latch that overflowed, else STSP_OK. */
static stsp_status_t stsp_spline_inputs(const stsp_header_t *h, const stsp_f32_t *x,
                                        const stsp_f32_t *v_new, uint32_t relatch)
{
    if (stsp_all_finite(x, stsp_nx(h)) == 0) {
        return STSP_ERR_NONFINITE_STATE;
    }
    if ((relatch != 0u) && (stsp_all_finite(v_new, stsp_n_latch(h)) == 0)) {
        return STSP_ERR_NONFINITE_OUTPUT;
    }
    return STSP_OK;
}

/* The spline law out of line, for the ticks other than the ordinary one (the first of a span,
 * the cold path): one more copy of it in flash instead of two. */
static STSP_NOINLINE uint32_t stsp_spline_law_other(const stsp_header_t *h, const stsp_span_t *p,
                                                    const stsp_f32_t *knot, stsp_f32_t inv,
                                                    const stsp_f32_t *coef,
                                                    const stsp_f32_t *fold, uint32_t tick,
                                                    const stsp_f32_t *x, stsp_f32_t *y,
                                                    uint32_t limited)
{
    return stsp_spline_law(h, p, knot, inv, coef, fold, tick, x, y, limited);
}

/* Every tick of a spline table but its ordinary one, as stsp_step_cold: the same plan and
 * commit, with the span located and recorded, and the state and a fresh latch checked for
 * finiteness (stsp_spline_inputs). stage_end stays 0: every tick of a spline table leaves
 * stsp_step's ordinary path for stsp_spline_step, which compares with the span's end. */
static STSP_NOINLINE stsp_status_t stsp_step_cold_spline(stsp_ctrl_t *ctrl, uint32_t tick,
                                                         const stsp_f32_t *x, stsp_f32_t *u)
{
    const stsp_header_t *h = &ctrl->checked;
    stsp_f32_t v_new[STSP_MAX_LATCH];
    stsp_f32_t y[STSP_MAX_NU];
    stsp_plan_t plan = {0u, 0u};
    stsp_span_t span; /* written by stsp_spline_locate before any use */
    stsp_status_t status;
    uint16_t mask = 0u;
    stsp_zero(v_new, STSP_MAX_LATCH);
    status = stsp_plan_tick(ctrl, tick, x, v_new, &plan);
    if (status >= STSP_OK) {
        const stsp_status_t st = stsp_spline_inputs(h, x, v_new, plan.relatch);
        if (st != STSP_OK) {
            status = st;
        } else {
            stsp_spline_locate(ctrl, tick, plan.stage, &span);
            stsp_spline_fold(h, &span, span.coef, v_new, span.fold);
            if (stsp_spline_law_other(h, &span, span.knot, span.inv, span.coef, span.fold, tick,
                                      x, y, ctrl->limited) != 0u) {
                const stsp_status_t lim = stsp_limit(h, x, y, &mask);
                if (lim != STSP_OK) {
                    status = lim;
                }
            }
        }
    }
    if (status < STSP_OK) {
        stsp_hold(ctrl, u);
        return status;
    }
    stsp_copy(u, y, stsp_nu(h));
    ctrl->sat_mask = mask;
    stsp_commit_tick(ctrl, tick, &plan, v_new);
    ctrl->stage_end = 0u;
    stsp_spline_commit(h, &ctrl->span, &span);
    return status;
}

/* What a spline table's tick does once its command is in y and out says whether it needs a
 * look (stsp_spline_law): as the per-tick ordinary tick, a NaN/Inf command or state is an
 * error that depends on x, read before u is written; otherwise the command is written and
 * clamped in place if need be. Returns 1 when u holds a command (the step succeeded so far),
 * with *st its status; 0 on an error (*st), u then the safe command. */
static STSP_ALWAYS_INLINE uint32_t stsp_spline_finish(stsp_ctrl_t *ctrl, uint32_t tick,
                                                      const stsp_f32_t *x, stsp_f32_t *u,
                                                      const stsp_f32_t *y, uint32_t out,
                                                      stsp_status_t *st)
{
    const stsp_header_t *h = &ctrl->checked;
    if ((out != 0u) &&
        ((stsp_command_finite(h, y) == 0) || (stsp_all_finite(x, stsp_nx(h)) == 0))) {
        *st = stsp_step_nonfinite(ctrl, x, u);
        return 0u;
    }
    stsp_copy_command(u, y, stsp_nu(h));
    if (out != 0u) {
        *st = stsp_step_fixup(ctrl, tick, u);
    } else {
        ctrl->next_tick = tick + 1u;
        *st = STSP_OK;
    }
    return 1u;
}

/* A spline table's tick other than the ordinary one: the expected tick that starts the next
 * span of the stage is that span's tick (its knots and coefficients one further: within the
 * stage's arrays, as there is a next span; the fold of the kept v computed for it and
 * recorded on success); anything else the cold path. Out of line, so that the ordinary tick
 * keeps its registers. */
static STSP_NOINLINE stsp_status_t stsp_step_next_span(stsp_ctrl_t *ctrl, uint32_t tick,
                                                       const stsp_f32_t *x, stsp_f32_t *u)
{
    const stsp_header_t *h = &ctrl->checked;
    const stsp_span_t *p = &ctrl->span;
    stsp_f32_t fold[4u * STSP_MAX_NU];
    stsp_f32_t y[STSP_MAX_NU];
    const stsp_f32_t *knot;
    const stsp_f32_t *coef;
    stsp_f32_t inv;
    stsp_status_t st = STSP_OK;
    uint32_t out;
    if ((tick != ctrl->next_tick) || (tick != p->next) || ((p->span + 1u) >= p->n_spans)) {
        return stsp_step_cold_spline(ctrl, tick, x, u);
    }
    knot = &p->knot[1];
    inv = stsp_span_inv(knot);
    /* The coefficients move only when the stage has entries (otherwise the pointer is the
     * stage's first coefficient, which may be one past the array). */
    coef = (p->row_end[stsp_nu(h) - 1u] > 0u) ? &p->coef[1] : p->coef;
    stsp_spline_fold(h, p, coef, ctrl->v, fold);
    out = stsp_spline_law_other(h, p, knot, inv, coef, fold, tick, x, y, ctrl->limited);
    if (stsp_spline_finish(ctrl, tick, x, u, y, out, &st) != 0u) {
        stsp_spline_next_span(ctrl, tick, knot, inv, coef, fold);
    }
    return st;
}

/* A spline table's every tick (its stage_end stays 0, so each leaves stsp_step's ordinary
 * path). The ordinary one is here: the expected tick inside the span of the last step
 * (span.next is 0 until the first latch, and never beyond the stage or n_ticks). Anything
 * else takes stsp_step_next_span. */
static stsp_status_t stsp_spline_step(stsp_ctrl_t *ctrl, uint32_t tick, const stsp_f32_t *x,
                               stsp_f32_t *u)
{
    const stsp_span_t *p = &ctrl->span;
    stsp_f32_t y[STSP_MAX_NU];
    stsp_status_t st = STSP_OK;
    uint32_t out;
    if ((tick != ctrl->next_tick) || (tick >= p->next)) {
        return stsp_step_next_span(ctrl, tick, x, u);
    }
    out = stsp_spline_law(&ctrl->checked, p, p->knot, p->inv, p->coef, p->fold, tick, x, y,
                          ctrl->limited);
    (void)stsp_spline_finish(ctrl, tick, x, u, y, out, &st);
    return st;
}

#endif /* STSP_ARITH_FIXED_POINT */

#ifndef STSP_ARITH_FIXED_POINT
/* The spline part of stsp_table_crc32()'s serialization: counts, then the six arrays, index
 * arrays as u32 each, knots and coefficients as binary32. */
static uint32_t stsp_spline_crc(uint32_t crc, const stsp_spline_t *sp, uint32_t ns, uint32_t nu)
{
    const uint32_t rows = (ns * nu) + 1u;
    uint32_t c = crc;
    uint32_t i;
    c = stsp_crc32_u32(c, sp->n_knots);
    c = stsp_crc32_u32(c, sp->n_entries);
    c = stsp_crc32_u32(c, sp->n_coef);
    c = stsp_crc32_u32s(c, sp->knot_start, ns + 1u);
    c = stsp_crc32_f32s(c, sp->knot, sp->n_knots);
    for (i = 0u; i < rows; ++i) {
        c = stsp_crc32_u32(c, (uint32_t)sp->row_start[i]);
    }
    for (i = 0u; i < sp->n_entries; ++i) {
        c = stsp_crc32_u32(c, (uint32_t)sp->col[i]);
    }
    c = stsp_crc32_u32s(c, sp->coef_start, ns + 1u);
    return stsp_crc32_f32s(c, sp->coef, sp->n_coef);
}
#endif

#ifndef STSP_ARITH_FIXED_POINT
/* acc less input i's gains of x times their states, in stored order (stsp_spline_law's
 * order), the span p's coefficients of its first entry at coef. */
static stsp_f32_t stsp_spline_x_terms(const stsp_header_t *h, const stsp_span_t *p,
                                      const stsp_f32_t *coef, const stsp_f32_t *n,
                                      const stsp_f32_t *x, uint32_t i, stsp_f32_t acc)
{
    const uint32_t nx = stsp_nx(h);
    stsp_f32_t out = acc;
    uint32_t e;
    for (e = (i > 0u) ? p->row_end[i - 1u] : 0u; e < p->k_end[i]; ++e) {
        const uint32_t col = p->col[e];
        out = stsp_mls(out, stsp_spline_gain(&coef[e * p->stride], n),
                       x[(col < nx) ? col : (nx - 1u)]);
    }
    return out;
}

/* The span record of `tick` in stage s for stsp_params.c's tick (format 2) into p: the span
 * as the cold path finds it from span `from` (stsp_spline_span: bounded by S and by the
 * validated lengths), and per input the fold of stsp_spline_fold with v continued with the
 * columns' terms, f[r] = f[r] - (c_p[r] d[p]) for p = 0 .. P-1 (stsp_params.h's order). The
 * columns of stage s start at nu P (knot_start[s] - 4 s); a layout that no longer fits cols
 * (a table changed after init) leaves them out: a wrong command, no access outside the
 * arrays. */
static void stsp_spline_param_span(const stsp_header_t *h, uint32_t s, uint32_t from,
                                   uint32_t tick, const stsp_f32_t *v, const stsp_f32_t *cols,
                                   uint32_t n_cols, const stsp_f32_t *d, uint32_t n_params,
                                   stsp_span_t *p)
{
    const uint32_t nu = stsp_nu(h);
    const uint32_t ks = h->sp.knot_start[s];
    const uint32_t per_stage = nu * n_params;
    uint32_t off = 0u;
    uint32_t use_cols = 0u;
    uint32_t i;
    stsp_spline_span(h, s, from, tick, stsp_stage_end(h, (uint16_t)s), p);
    stsp_spline_fold(h, p, p->coef, v, p->fold);
    if ((ks >= (4u * s)) && ((ks - (4u * s)) <= (n_cols / per_stage))) {
        off = per_stage * (ks - (4u * s));
        if ((per_stage * p->stride) <= (n_cols - off)) {
            use_cols = 1u;
        }
    }
    for (i = 0u; (use_cols != 0u) && (i < nu); ++i) {
        stsp_f32_t *f = &p->fold[4u * i];
        uint32_t q;
        for (q = 0u; q < n_params; ++q) {
            const stsp_f32_t *cs = &cols[off + ((((i * n_params) + q) * p->stride) + p->span)];
            uint32_t r;
            for (r = 0u; r < 4u; ++r) {
                f[r] = stsp_mls(f[r], cs[r], d[q]);
            }
        }
    }
}

/* 1 when the span record p (its next nonzero: recorded since the last parameter change,
 * init or reset) is of the stage whose first tick is `first`, and starts at or before tau
 * (U[sigma + 3] <= tau, the third of the knots it keeps from U[sigma + 1]): a search from its
 * span then finds the span of a search from 0. */
static uint32_t stsp_span_before(const stsp_span_t *p, uint32_t first, stsp_f32_t tau)
{
    return ((p->next != 0u) && (p->first == first) && (p->knot[2] <= tau)) ? 1u : 0u;
}

/* stsp_params.c's tick of a spline table with spline columns (stsp_params.h, format 2): the
 * span record of `tick` in stage s (stsp_spline_param_span), its basis, and per input the
 * folded spline's value less the gains of x (stsp_spline_law's order). With `kept` (v is
 * ctrl->v, d the parameters in use: stsp_params.c clears the record, next = 0, on new
 * parameters; ctrl->v changes only with the stage, or after init and reset, which clear it)
 * ctrl->span is the span cache, as the spline tick's ordinary path keeps it:
 * used as it is for a tick inside its span of stage s (the same record, so the same bits as a
 * fresh one), else searched again from its span when it lies in stage s at or before the tick
 * (a later tick), from the stage's first span otherwise (another stage, a tick before it, no
 * record), and recorded. Without it the record is a fresh one on the stack, searched from the
 * first span (a fresh latch, not yet committed). */
static void stsp_spline_param_law(stsp_ctrl_t *ctrl, uint32_t s, uint32_t tick,
                                  const stsp_f32_t *x, const stsp_f32_t *v,
                                  const stsp_f32_t *cols, uint32_t n_cols, const stsp_f32_t *d,
                                  uint32_t n_params, uint32_t kept, stsp_f32_t *y)
{
    const stsp_header_t *h = &ctrl->checked;
    const uint32_t nu = stsp_nu(h);
    const uint32_t first = h->stage_start[s];
    const uint32_t in_stage = tick - first;
    const stsp_f32_t tau = (stsp_f32_t)in_stage; /* exact: < 2^24 on a valid table */
    stsp_span_t fresh;
    const stsp_span_t *p = &ctrl->span;
    stsp_f32_t n[4];
    uint32_t i;
    if (kept == 0u) {
        stsp_spline_param_span(h, s, 0u, tick, v, cols, n_cols, d, n_params, &fresh);
        p = &fresh;
    } else if ((stsp_span_before(p, first, tau) == 0u) || (tick >= p->next)) {
        const uint32_t from = (stsp_span_before(p, first, tau) != 0u) ? p->span : 0u;
        stsp_spline_param_span(h, s, from, tick, v, cols, n_cols, d, n_params, &ctrl->span);
    } else {
        /* inside the recorded span */
    }
    stsp_spline_basis(p->knot, p->inv, tau, n);
    for (i = 0u; i < nu; ++i) {
        y[i] = stsp_spline_x_terms(h, p, p->coef, n, x, i, stsp_spline_gain(&p->fold[4u * i], n));
    }
}
#endif

const stsp_spline_ops_t stsp_spline_ops = {
    STSP_SCALAR_KIND, stsp_spline_check_dims,
#ifdef STSP_ARITH_FIXED_POINT
    stsp_spline_check_values,
#else
    NULL, /* float32: init's value checks cover the coefficients (stsp_table.c) */
#endif
    stsp_spline_crc, stsp_spline_step,
#ifdef STSP_ARITH_FIXED_POINT
    stsp_qspline_param_law
#else
    stsp_spline_param_law
#endif
};
