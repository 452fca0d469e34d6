/* The float32 law, its limit and finiteness checks, included once by stsp_controller.c
 * (static, inlined into stsp_step). Private: not installed. */
#ifndef STSP_LAW_F32_H
#define STSP_LAW_F32_H

#include "stsp_clamp.h"

/* The error of a non-finite command: the state was not finite, or it was and the law (or the
 * latch) overflowed. Reads x: called before u is written (x and u may overlap). */
static stsp_status_t stsp_nonfinite_status(const stsp_header_t *h, const stsp_f32_t *x)
{
    return (stsp_all_finite(x, stsp_nx(h)) == 0) ? STSP_ERR_NONFINITE_STATE
                                                 : STSP_ERR_NONFINITE_OUTPUT;
}

/* Cold path, part 3: some y[i] may be outside [u_min[i], u_max[i]] or not finite. If any is
 * NaN/Inf, returns the error that says why. Otherwise clamps y (bits of *mask) and returns
 * STSP_WARN_SATURATED, or STSP_OK if nothing needed clamping (a false alarm of the fast
 * check). Inlined into both cold paths, so that y can stay in registers. */
static STSP_ALWAYS_INLINE stsp_status_t stsp_limit(const stsp_header_t *h, const stsp_f32_t *x,
                                                   stsp_f32_t *y, uint16_t *mask)
{
    if (stsp_all_finite(y, stsp_nu(h)) == 0) {
        return stsp_nonfinite_status(h, x);
    }
    return stsp_clamp(h, y, mask);
}

/* The float32 row of the law (stsp_law.h), in the documented order:
 *     u[i] = (((-(K[i][0] x[0]) - k0[i]) - K[i][1] x[1]) - ... ) - L[i][0] v[0] - ...
 * which is -(k0[i] + K[i][0] x[0] + ... + L[i][c] v[c] ...) exactly (IEEE rounding is
 * symmetric; a+b = b+a), up to the sign of an exactly zero result; starting from -(K x)
 * folds the final negation away, and each step is one stsp_nmla()/stsp_mls() (one VNMLA or
 * VMLS on the M4F, same bits). */
typedef stsp_f32_t stsp_row_acc_t;
/* Aliases, not wrappers: GCC schedules the law through inline wrappers differently (one
 * more load on the M4F ordinary tick), so the law calls the VFP helpers by these names
 * directly, and the end of a row is the accumulator itself (k0 was folded in first). */
#define stsp_row_first stsp_nmla
#define stsp_row_mac stsp_mls
#define stsp_row_end(acc, k0) (acc)

/* Without limits, the cold-path alarm is whether the sum of the u[i] is not finite (any NaN
 * or Inf makes it NaN or Inf; a finite sum that overflows is a false alarm that stsp_limit()
 * clears). */
static STSP_ALWAYS_INLINE uint32_t stsp_unlimited_alarm(const stsp_header_t *h,
                                                        const stsp_f32_t *y)
{
    const uint32_t nu = stsp_nu(h);
    stsp_f32_t sum = -0.0f; /* -0 + a = a for every a: the compiler drops this add */
    uint32_t i;
    uint32_t out = 0u;
    STSP_UNROLL
    for (i = 0u; i < nu; ++i) {
        sum += y[i];
    }
    /* sum - sum is +0 for a finite sum, NaN for NaN and +-Inf. */
    if (!((sum - sum) == 0.0f)) {
        out = 1u;
    }
    return out;
}

/* One latched multiplier: lambda0 + sum_j Lambda[j] x[j], in that order. */
static STSP_ALWAYS_INLINE stsp_f32_t stsp_latch_row(const stsp_f32_t *lam, stsp_f32_t lambda0,
                                                    const stsp_f32_t *x, uint32_t nx)
{
    stsp_f32_t acc = lambda0;
    uint32_t j;
    for (j = 0u; j < nx; ++j) {
        acc += lam[j] * x[j];
    }
    return acc;
}

/* 1 when every y[0..nu) is finite: the ordinary tick's test, inlined so that y can stay in
 * registers. */
static STSP_ALWAYS_INLINE int stsp_command_finite(const stsp_header_t *h, const stsp_f32_t *y)
{
    const uint32_t nu = stsp_nu(h);
    uint32_t i;
    int finite = 1;
    STSP_UNROLL
    for (i = 0u; i < nu; ++i) {
        if (stsp_isfinite_f32(y[i]) == 0) {
            finite = 0;
        }
    }
    return finite;
}

/* An ordinary tick whose command is not finite: the error, u the safe command (x not yet
 * overwritten). */
static STSP_NOINLINE stsp_status_t stsp_step_nonfinite(const stsp_ctrl_t *ctrl,
                                                       const stsp_f32_t *x, stsp_f32_t *u)
{
    const stsp_status_t st = stsp_nonfinite_status(&ctrl->checked, x);
    stsp_hold(ctrl, u);
    return st;
}

#endif /* STSP_LAW_F32_H */
