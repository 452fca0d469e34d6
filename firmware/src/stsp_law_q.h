/* The fixed-point (Q15/Q31) law and its limit check, included once by stsp_controller.c
 * (static, inlined into stsp_step). Private: not installed. */
#ifndef STSP_LAW_Q_H
#define STSP_LAW_Q_H

#include "stsp_clamp.h"

/* Cold path, part 3, fixed point: some y[i] is outside [u_min[i], u_max[i]]; clamp it (the
 * law's u_q is always a valid integer: there is no non-finite case). */
static stsp_status_t stsp_limit(const stsp_header_t *h, const stsp_scalar_t *x,
                                stsp_scalar_t *y, uint16_t *mask)
{
    (void)x;
    return stsp_clamp(h, y, mask);
}

/* The law at `tick` with multipliers v, fixed point (Q15: 32-bit accumulator, Q31: 64-bit),
 * into y (never the caller's u: x and u may overlap):
 *     u_q[i] = floor((k0[i] 2^F + sum_j K[i][j] x_q[j] + sum_c L[i][c] v_q[c]) / 2^F + 1/2)
 * (the table stores -K, -k0, -L: one multiply-accumulate per term). Scaling: every term of
 * row i is in units of 2^(u_exp[i] - 2F) (the gains carry x_exp, v_exp and u_exp), so the
 * only shift is the final one by F. Overflow: none; the sum is exact (integer, any order
 * gives the same bits) and bounded by (2^F - 1) 2^F, the accumulator by 2^(2F+1) (see
 * stsp_uacc_t); u_q is within +-(2^F - 1) without saturation. Returns nonzero when some u_q[i]
 * lies outside [u_min[i], u_max[i]] (only checked when the table is limited). */
static STSP_ALWAYS_INLINE uint32_t stsp_law(const stsp_header_t *h, uint32_t tick,
                                            const stsp_scalar_t *x, const stsp_scalar_t *v,
                                            stsp_scalar_t *y, uint32_t limited)
{
    const uint32_t nx = stsp_nx(h);
    const uint32_t nu = stsp_nu(h);
    const uint32_t nl = stsp_nl(h);
    const stsp_scalar_t *K = &h->K[tick * (nu * nx)];
    const stsp_scalar_t *k0 = &h->k0[tick * nu];
    /* L may be NULL when nl == 0: no pointer arithmetic on it then. */
    const stsp_scalar_t *L = (nl > 0u) ? &h->L[tick * (nu * nl)] : h->L;
    uint32_t i;
    uint32_t out = 0u;
    STSP_UNROLL
    for (i = 0u; i < nu; ++i) {
        stsp_uacc_t acc = stsp_q_start();
        uint32_t j;
        STSP_UNROLL
        for (j = 0u; j < nx; ++j) {
            acc = stsp_q_mac(acc, K[j], x[j]);
        }
        K = &K[nx];
        if (nl > 0u) {
            STSP_UNROLL
            for (j = 0u; j < nl; ++j) {
                acc = stsp_q_mac(acc, L[j], v[j]);
            }
            L = &L[nl];
        }
        y[i] = stsp_q_round(acc, k0[i]);
    }
    if (limited != 0u) {
        STSP_UNROLL
        for (i = 0u; i < nu; ++i) {
            if ((y[i] < h->u_min[i]) || (y[i] > h->u_max[i])) {
                out = 1u;
            }
        }
    }
    return out;
}

#endif /* STSP_LAW_Q_H */
