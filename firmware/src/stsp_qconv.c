/* Fixed-point variants only: conversions between float32 values and the table's Q formats,
 * for applications on an FPU target (stsp_step() itself needs no floating point). The
 * contract is on the prototypes in stospline/stsp_controller.h. */
#include "stsp_internal.h"

#include <string.h>

#ifdef STSP_ARITH_FIXED_POINT

/* 2^e as a binary32, exact for |e| <= STSP_Q_EXP_MAX + STSP_Q_FRAC_BITS = 91 (stsp_init()
 * checked the exponents). Built from its bits: no libm. e is clamped to the normal range
 * [-126, 127] first, so that exponents changed in memory after init give a wrong but finite
 * scale (never a NaN, whose conversion to an integer would be undefined). */
static stsp_f32_t stsp_pow2f(int32_t e)
{
    const int32_t normal = (e > 127) ? 127 : ((e < -126) ? -126 : e);
    const uint32_t biased = (uint32_t)normal + 127u; /* in [1, 254]: a normal number */
    const uint32_t bits = biased << 23;
    stsp_f32_t value;
    (void)memcpy(&value, &bits, sizeof value);
    return value;
}

/* floor(s + 1/2) saturated to [-2^F, 2^F - 1]; *clamped set when it saturated. s is finite.
 * 2^F is exact in binary32; 2^F + 1/2 rounds to 2^F for Q31, which is still the right
 * threshold there (every binary32 at or above 2^24 is an integer). */
static stsp_scalar_t stsp_q_from_f32(stsp_f32_t s, uint32_t *clamped)
{
    const stsp_f32_t one = stsp_pow2f(STSP_Q_FRAC_BITS);
#if defined(STSP_ARITH_Q15)
    const stsp_scalar_t q_min = (stsp_scalar_t)INT16_MIN; /* -2^F */
    const stsp_scalar_t q_max = (stsp_scalar_t)INT16_MAX; /* 2^F - 1 */
#else
    const stsp_scalar_t q_min = (stsp_scalar_t)INT32_MIN;
    const stsp_scalar_t q_max = (stsp_scalar_t)INT32_MAX;
#endif
    int32_t q;
    if (s >= (one - 0.5f)) {
        *clamped = 1u;
        return q_max;
    }
    if (s < (-one - 0.5f)) {
        *clamped = 1u;
        return q_min;
    }
    if ((s < 8388608.0f) && (s > -8388608.0f)) {
        /* |s| < 2^23: s + 1/2 is exact; truncation then a step down for negatives is floor. */
        const stsp_f32_t r = s + 0.5f;
        q = (int32_t)r;
        if ((stsp_f32_t)q > r) {
            q -= 1;
        }
    } else {
        q = (int32_t)s; /* already an integer, within [-2^31, 2^31) */
    }
    return (stsp_scalar_t)q;
}

stsp_status_t stsp_state_to_q(const stsp_ctrl_t *ctrl, const stsp_f32_t *x, stsp_scalar_t *x_q)
{
    const stsp_status_t st = stsp_check_ready(ctrl);
    const stsp_header_t *t;
    uint32_t j;
    uint32_t clamped = 0u;
    if ((x == NULL) || (x_q == NULL)) {
        return STSP_ERR_NULL;
    }
    if (st != STSP_OK) {
        return st;
    }
    t = &ctrl->checked; /* the dimensions and exponents init validated */
    for (j = 0u; j < t->nx; ++j) {
        /* NaN fails both compares; +-Inf exceeds FLT_MAX in magnitude. */
        if (!((x[j] <= 3.40282347e+38f) && (x[j] >= -3.40282347e+38f))) {
            uint32_t k;
            for (k = 0u; k < t->nx; ++k) {
                x_q[k] = (stsp_scalar_t)0;
            }
            return STSP_ERR_NONFINITE_STATE;
        }
    }
    for (j = 0u; j < t->nx; ++j) {
        /* x 2^(F - x_exp) is exact unless it overflows to +-Inf (then it saturates) or
         * underflows below 2^-126 (then it rounds to 0 either way). */
        const stsp_f32_t s = x[j] * stsp_pow2f((int32_t)STSP_Q_FRAC_BITS - (int32_t)t->x_exp[j]);
        x_q[j] = stsp_q_from_f32(s, &clamped);
    }
    return (clamped != 0u) ? STSP_WARN_STATE_CLAMPED : STSP_OK;
}

stsp_status_t stsp_command_to_f32(const stsp_ctrl_t *ctrl, const stsp_scalar_t *u_q,
                                  stsp_f32_t *u)
{
    const stsp_status_t st = stsp_check_ready(ctrl);
    const stsp_header_t *t;
    uint32_t i;
    if ((u_q == NULL) || (u == NULL)) {
        return STSP_ERR_NULL;
    }
    if (st != STSP_OK) {
        return st;
    }
    t = &ctrl->checked; /* the dimensions and exponents init validated */
    for (i = 0u; i < t->nu; ++i) {
        u[i] = (stsp_f32_t)u_q[i] * stsp_pow2f((int32_t)t->u_exp[i] - (int32_t)STSP_Q_FRAC_BITS);
    }
    return STSP_OK;
}

#else
/* ISO C requires a translation unit to declare something. */
typedef int stsp_qconv_unused_t;
#endif
