/* The law of a spline table (stsp_spline_t, float32 only), included once by stsp_spline.c
 * after stsp_law.h: the stage layout and span search of the cold path, and the law at a span
 * (static, inlined into the spline ordinary tick and the cold path). Private: not installed. */
#ifndef STSP_LAW_SPLINE_H
#define STSP_LAW_SPLINE_H

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

#endif /* STSP_LAW_SPLINE_H */
