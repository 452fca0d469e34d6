/* The law of a spline table (stsp_spline_t, float32 only), included once by stsp_controller.c
 * after stsp_law.h: the stage layout and span search of the cold path, and the law at a span
 * (static, inlined into the spline ordinary tick and the cold path). Private: not installed. */
#ifndef STSP_LAW_SPLINE_H
#define STSP_LAW_SPLINE_H

/* z = [x, 1, v], the operands the entries' col index. An index read after init is bounded in
 * the cheaper way for the build: in an STSP_FIXED_* build z is padded with zeros to a power of
 * two and the index masked (one instruction per entry, and a few constant stores per tick);
 * in the generic build (the padding would be a loop) the index is clamped to z's last entry. */
#ifdef STSP_FIXED_NX
#define STSP_NZ (STSP_FIXED_NX + 1u + STSP_FIXED_N_LATCH)
#define STSP_Z_LEN                                                                         \
    ((STSP_NZ <= 8u) ? 8u                                                                  \
                     : ((STSP_NZ <= 16u) ? 16u                                             \
                                         : ((STSP_NZ <= 32u) ? 32u                         \
                                                             : ((STSP_NZ <= 64u) ? 64u     \
                                                                                 : 256u))))

static inline uint32_t stsp_z_index(uint32_t col, uint32_t last)
{
    (void)last;
    return col & (STSP_Z_LEN - 1u);
}
#else
#define STSP_Z_LEN (STSP_MAX_NX + 1u + STSP_MAX_LATCH)

static inline uint32_t stsp_z_index(uint32_t col, uint32_t last)
{
    return (col < last) ? col : last;
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
        if ((end < e1) || (end > sp->n_entries)) {
            fits = 0u;
        } else {
            e1 = end;
        }
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
            p->row_end[i] = 0u;
        }
    }
    p->stride = n_spans + 3u;
    p->first = h->stage_start[s];
    return n_spans;
}

/* Cold path: record span p in the instance's dst, row_end only for the table's inputs (the
 * rest stays zero, as init left it). */
static void stsp_spline_commit(const stsp_header_t *h, stsp_span_t *dst, const stsp_span_t *p)
{
    uint32_t i;
    dst->knot = p->knot;
    dst->coef = p->coef;
    dst->col = p->col;
    dst->first = p->first;
    dst->next = p->next;
    dst->stride = p->stride;
    dst->span = p->span;
    dst->n_spans = p->n_spans;
    for (i = 0u; i < stsp_nu(h); ++i) {
        dst->row_end[i] = p->row_end[i];
    }
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
static STSP_ALWAYS_INLINE void stsp_spline_basis(const stsp_f32_t *k, stsp_f32_t tau,
                                                 stsp_f32_t *n)
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
    /* round 1 (N[0] = 1) */
    temp = 1.0f / (right1 + left1);
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

/* acc - g z for one entry whose four coefficients of the span are c[0..3]: g = ((n[0] c[0] +
 * n[1] c[1]) + n[2] c[2]) + n[3] c[3], every product and sum rounded (not fused), then the
 * product g z rounded and subtracted. On a single-precision VFP one VLDM of c and VMUL, three
 * VMLA, VMLS (chained: the bits of the C below, as for stsp_mls), in one asm statement so
 * that the four coefficients land in consecutive registers (s12-s15, with g in s11: all
 * caller-saved, declared clobbered). */
static STSP_ALWAYS_INLINE stsp_f32_t
/* cppcheck-suppress misra-c2012-2.7 ; deviation D5: the parameters are asm operands */
stsp_spline_entry(stsp_f32_t acc, const stsp_f32_t *c, const stsp_f32_t *n, stsp_f32_t z)
{
#if STSP_VFP_MAC
    stsp_f32_t r = acc;
    __asm__ volatile("vldmia %[c], {s12-s15}\n\t"
                     "vmul.f32 s11, %[n0], s12\n\t"
                     "vmla.f32 s11, %[n1], s13\n\t"
                     "vmla.f32 s11, %[n2], s14\n\t"
                     "vmla.f32 s11, %[n3], s15\n\t"
                     "vmls.f32 %[r], s11, %[z]"
                     : [r] "+t"(r)
                     : [c] "r"(c), [n0] "t"(n[0]), [n1] "t"(n[1]), [n2] "t"(n[2]),
                       [n3] "t"(n[3]), [z] "t"(z), "m"(c[0]), "m"(c[1]), "m"(c[2]), "m"(c[3])
                     : "s11", "s12", "s13", "s14", "s15");
    return r;
#else
    stsp_f32_t g = n[0] * c[0];
    g = stsp_mla(g, n[1], c[1]);
    g = stsp_mla(g, n[2], c[2]);
    g = stsp_mla(g, n[3], c[3]);
    return stsp_mls(acc, g, z);
#endif
}

/* The spline law at `tick` in p's stage, in the span whose knots start at knot (U[sigma + 1])
 * and whose first entry's coefficients at coef, with multipliers v, into y (x and u may
 * overlap: y is never the caller's u): the basis once, then per input i, over its entries in
 * stored order, acc = acc - g z[col] from acc = +0 (stsp_spline_entry). Returns nonzero when
 * the step needs the cold path: as stsp_law_alarm(), and also when the state is not finite
 * (an input need not use every x[j], so the command does not reveal it: the state's sum joins
 * the command's in the check; it also overflows for some huge finite states, a false alarm
 * the cold path clears). A col changed since init is bounded by stsp_z_index(): a wrong
 * command, no access outside z. */
static STSP_ALWAYS_INLINE uint32_t stsp_spline_law(const stsp_header_t *h, const stsp_span_t *p,
                                                   const stsp_f32_t *knot,
                                                   const stsp_f32_t *coef, uint32_t tick,
                                                   const stsp_f32_t *x, const stsp_f32_t *v,
                                                   stsp_f32_t *y, uint32_t limited)
{
    const uint32_t nx = stsp_nx(h);
    const uint32_t nu = stsp_nu(h);
    const uint32_t n_latch = stsp_n_latch(h);
    const uint32_t last = nx + n_latch;
    const uint32_t stride = p->stride;
    const uint32_t in_stage = tick - p->first; /* tau, exact: < 2^24 on a valid table */
    const uint8_t *col = p->col;
    stsp_f32_t z[STSP_Z_LEN];
    const stsp_f32_t *zp;
    stsp_f32_t n[4];
    stsp_f32_t total = -0.0f; /* of x, then of y: -0 + a = a, the compiler drops this add */
    uint32_t off = 0u;        /* an offset, not a pointer: it ends beyond the coefficients */
    uint32_t e = 0u;
    uint32_t i;
    uint32_t out = 0u;
    STSP_UNROLL
    for (i = 0u; i < nx; ++i) {
        z[i] = x[i];
        total += x[i];
    }
    z[nx] = 1.0f;
    STSP_UNROLL
    for (i = 0u; i < n_latch; ++i) {
        z[nx + 1u + i] = v[i];
    }
#ifdef STSP_FIXED_NX
    STSP_UNROLL
    for (i = last + 1u; i < STSP_Z_LEN; ++i) {
        z[i] = 0.0f;
    }
#endif
    stsp_spline_basis(knot, (stsp_f32_t)in_stage, n);
    zp = z;
#if STSP_VFP_MAC
    __asm__("" : "+r"(zp));
#endif
    STSP_UNROLL
    for (i = 0u; i < nu; ++i) {
        const uint32_t end = p->row_end[i];
        stsp_f32_t acc = 0.0f;
        for (; e < end; ++e) {
            acc = stsp_spline_entry(acc, &coef[off], n, zp[stsp_z_index(col[e], last)]);
            off += stride;
        }
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
