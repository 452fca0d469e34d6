/* The fixed-point (Q15/Q31) arithmetic of the law (stsp_law.h) and its limit check, included
 * once by stsp_controller.c (static, inlined into stsp_step). Private: not installed. */
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

/* The fixed-point (Q15: 32-bit accumulator, Q31: 64-bit) row of the law (stsp_law.h):
 *     u_q[i] = floor((k0[i] 2^F + sum_j K[i][j] x_q[j] + sum_c L[i][c] v_q[c]) / 2^F + 1/2)
 * (the table stores -K, -k0, -L: one multiply-accumulate per term). Scaling: every term of
 * row i is in units of 2^(u_exp[i] - 2F) (the gains carry x_exp, v_exp and u_exp), so the
 * only shift is the final one by F. Overflow: none; the sum is exact (integer, any order
 * gives the same bits) and bounded by (2^F - 1) 2^F, the accumulator by 2^(2F+1) (see
 * stsp_uacc_t); u_q is within +-(2^F - 1) without saturation. */
typedef stsp_uacc_t stsp_row_acc_t;
/* Aliases, as in stsp_law_f32.h (inline wrappers change GCC's schedule of the law): the row
 * starts from the accumulator's bias, and k0 is added after the shift. */
#define stsp_row_first(a, b, k0) stsp_q_mac(stsp_q_start(), (a), (b))
#define stsp_row_mac stsp_q_mac
#define stsp_row_end stsp_q_round

/* Without limits there is nothing to check: u_q is always a valid integer. */
static STSP_ALWAYS_INLINE uint32_t stsp_unlimited_alarm(const stsp_header_t *h,
                                                        const stsp_scalar_t *y)
{
    (void)h;
    (void)y;
    return 0u;
}

/* One latched multiplier: v_q = round half up of lambda0 + sum_j Lambda x_q / 2^F, exact in
 * stsp_uacc_t and within +-(2^F - 1) (the row bound of stsp_check_values). */
static STSP_ALWAYS_INLINE stsp_scalar_t stsp_latch_row(const stsp_scalar_t *lam,
                                                       stsp_scalar_t lambda0,
                                                       const stsp_scalar_t *x, uint32_t nx)
{
    stsp_uacc_t sum = stsp_q_start();
    uint32_t j;
    for (j = 0u; j < nx; ++j) {
        sum = stsp_q_mac(sum, lam[j], x[j]);
    }
    return stsp_q_round(sum, lambda0);
}

#endif /* STSP_LAW_Q_H */
