/* The law, one definition for every arithmetic, included once by stsp_controller.c after the
 * arithmetic's row primitives (stsp_law_f32.h or stsp_law_q.h: stsp_row_first, stsp_row_mac,
 * stsp_row_end, stsp_unlimited_alarm). Static, inlined into stsp_step. Private: not installed. */
#ifndef STSP_LAW_H
#define STSP_LAW_H

/* Whether a command y needs the cold path: with limits, some y[i] outside [u_min[i],
 * u_max[i]] (false for NaN, and for one of +-Inf since the limits are finite); without,
 * stsp_unlimited_alarm(). Shared by the per-tick and the spline law. */
static STSP_ALWAYS_INLINE uint32_t stsp_law_alarm(const stsp_header_t *h, const stsp_scalar_t *y,
                                                  uint32_t limited)
{
    const uint32_t nu = stsp_nu(h);
    uint32_t out = 0u;
    if (limited != 0u) {
        const stsp_scalar_t *lo = h->u_min;
        const stsp_scalar_t *hi = h->u_max;
        uint32_t i;
        STSP_UNROLL
        for (i = 0u; i < nu; ++i) {
            if (!((y[i] >= lo[i]) && (y[i] <= hi[i]))) {
                out = 1u;
            }
        }
    } else {
        out = stsp_unlimited_alarm(h, y);
    }
    return out;
}

#ifndef STSP_LAW_ALARM_ONLY
#if defined(STSP_FIXED_NX) || defined(STSP_ARITH_FIXED_POINT)
/* The law at `tick` with multipliers v, into y (never the caller's u: x and u may overlap):
 * per input i, the row K[i][0] x[0] (with k0[i], as the arithmetic folds it in), the rest of
 * K[i] x, then L[i] v over all n_latch columns (zero padded, so every tick costs the same).
 * Returns stsp_law_alarm(). Inlined into callers whose y is a local array, so that in an
 * STSP_FIXED_* build x, v and y stay in registers. */
static STSP_ALWAYS_INLINE uint32_t stsp_law(const stsp_header_t *h, uint32_t tick,
                                            const stsp_scalar_t *x, const stsp_scalar_t *v,
                                            stsp_scalar_t *y, uint32_t limited)
{
    const uint32_t nx = stsp_nx(h);
    const uint32_t nu = stsp_nu(h);
    const uint32_t n_latch = stsp_n_latch(h);
    const stsp_scalar_t *K = &h->K[tick * (nu * nx)];
    const stsp_scalar_t *k0 = &h->k0[tick * nu];
    /* L may be NULL when n_latch == 0: no pointer arithmetic on it then. */
    const stsp_scalar_t *L = (n_latch > 0u) ? &h->L[tick * (nu * n_latch)] : h->L;
    uint32_t i;
    STSP_UNROLL
    for (i = 0u; i < nu; ++i) {
        stsp_row_acc_t acc = stsp_row_first(K[0], x[0], k0[i]);
        uint32_t j;
        STSP_UNROLL
        for (j = 1u; j < nx; ++j) {
            acc = stsp_row_mac(acc, K[j], x[j]);
        }
        K = &K[nx];
        if (n_latch > 0u) {
            STSP_UNROLL
            for (j = 0u; j < n_latch; ++j) {
                acc = stsp_row_mac(acc, L[j], v[j]);
            }
            L = &L[n_latch];
        }
        y[i] = stsp_row_end(acc, k0[i]);
    }
    return stsp_law_alarm(h, y, limited);
}
#else
/* float32, generic dimensions. The rows of `tick` (< n_ticks, which the cold path checked
 * first), from the validated copy h. */
static inline void stsp_rows_at(const stsp_header_t *h, uint32_t tick, stsp_rows_t *r)
{
    const uint32_t nu = stsp_nu(h);
    const uint32_t n_latch = stsp_n_latch(h);
    r->K = &h->K[tick * (nu * stsp_nx(h))];
    r->k0 = &h->k0[tick * nu];
    /* L may be NULL when n_latch == 0: no pointer arithmetic on it then. */
    r->L = (n_latch > 0u) ? &h->L[tick * (nu * n_latch)] : h->L;
}

/* The law on the rows r (those of one tick) with multipliers v, into y: two rows at a time,
 * each x[j] (v[c]) loaded once for both (stsp_law_pairs: on the M4F VLDM of four columns and
 * VMLS), an odd last row alone. Each row is still its own chain in the documented order: acc
 * = -k0[i], then acc = stsp_mls(acc, K[i][j], x[j]) for j = 0 .. nx - 1 and stsp_mls(acc,
 * L[i][c], v[c]) for c = 0 .. n_latch - 1. Its first step, -k0[i] - K[i][0] x[0], is the
 * documented (-(K[i][0] x[0])) - k0[i]: both are (-k0[i]) + (-(K[i][0] x[0])), and binary32
 * addition is commutative, signs of zero included (as for VNMLA, stsp_nmla). Writes y[0 ..
 * nu) (never the caller's u: x and u may overlap) and moves r past the tick's rows (to the
 * next tick's: nu nx, nu and nu n_latch entries on; L stays when n_latch == 0); returns the
 * inputs' sum in order, -0 + y[0] + y[1] + ... (stsp_unlimited_alarm's). Inlined into the
 * ordinary tick and the cold path's stsp_law_rows on a single-precision VFP (one asm
 * statement); elsewhere (soft float, the host) once, out of line: inlined twice, its C loops
 * cost the Cortex-M0+ some 650 B of flash. */
#if STSP_VFP_MAC
#define STSP_LAW_ON_ROWS STSP_ALWAYS_INLINE
#else
#define STSP_LAW_ON_ROWS STSP_NOINLINE
#endif
static STSP_LAW_ON_ROWS stsp_f32_t stsp_law_on_rows(const stsp_header_t *h, stsp_rows_t *r,
                                                    const stsp_f32_t *x, const stsp_f32_t *v,
                                                    stsp_f32_t *y)
{
    const uint32_t nx = stsp_nx(h);
    const uint32_t nu = stsp_nu(h);
    const uint32_t n_latch = stsp_n_latch(h);
    const stsp_f32_t *K = r->K;
    const stsp_f32_t *k0 = r->k0;
    const stsp_f32_t *L = r->L;
    stsp_f32_t total = -0.0f; /* -0 + a = a for every a */
    stsp_f32_t *yp = y;
    stsp_law_pairs(x, v, nx, n_latch, nu, &k0, &yp, &K, &L, &total);
    r->K = K;
    r->k0 = k0;
    r->L = L;
    return total;
}

/* The law of an ordinary tick on the rows the instance keeps (*rows: those of the tick),
 * moving them on to the next tick's; as stsp_law() otherwise. */
static STSP_ALWAYS_INLINE uint32_t stsp_law_kept(const stsp_header_t *h, stsp_rows_t *rows,
                                                 const stsp_f32_t *x, const stsp_f32_t *v,
                                                 stsp_f32_t *y, uint32_t limited)
{
    const stsp_f32_t total = stsp_law_on_rows(h, rows, x, v, y);
    return (limited != 0u) ? stsp_law_alarm(h, y, limited) : stsp_total_alarm(total);
}

/* The law at `tick` (< n_ticks) on the cold path (stsp_step_cold): the rows from the tick's
 * index in the validated copy h; *next then holds the rows of tick + 1 (stsp_law_on_rows).
 * Out of line; the ordinary tick (stsp_step_ordinary) runs stsp_law_kept() on the rows the
 * instance keeps. */
static STSP_NOINLINE stsp_f32_t stsp_law_rows(const stsp_header_t *h, uint32_t tick,
                                              const stsp_f32_t *x, const stsp_f32_t *v,
                                              stsp_f32_t *y, stsp_rows_t *next)
{
    stsp_rows_t r;
    stsp_f32_t total;
    stsp_rows_at(h, tick, &r);
    total = stsp_law_on_rows(h, &r, x, v, y);
    *next = r;
    return total;
}

/* The law at `tick` with multipliers v, into y (never the caller's u: x and u may overlap),
 * and the rows of tick + 1 into *next. Returns the alarm of stsp_law_alarm(); without limits
 * from the inputs' sum that stsp_law_rows took (same order: the same value). */
static STSP_ALWAYS_INLINE uint32_t stsp_law(const stsp_header_t *h, uint32_t tick,
                                            const stsp_f32_t *x, const stsp_f32_t *v,
                                            stsp_f32_t *y, uint32_t limited, stsp_rows_t *next)
{
    const stsp_f32_t total = stsp_law_rows(h, tick, x, v, y, next);
    return (limited != 0u) ? stsp_law_alarm(h, y, limited) : stsp_total_alarm(total);
}
#endif
#endif /* STSP_LAW_ALARM_ONLY */

#endif /* STSP_LAW_H */
