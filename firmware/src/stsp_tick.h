/* The checks on a command that both ticks make, the per-tick one (stsp_controller.c) and the
 * spline one (stsp_spline.c): the alarm that sends a command to the cold path, the limit and
 * finiteness checks and the clamp, and the ordinary ticks' fixups. Static, inlined into each
 * tick. Private: not installed. */
#ifndef STSP_TICK_H
#define STSP_TICK_H

#include "stsp_internal.h"

/* Clamps u[i] to [u_min[i], u_max[i]] (bits of *mask); STSP_WARN_SATURATED if any was, else
 * STSP_OK. Inlined into each caller: a call would keep the cold paths' y in memory. */
static STSP_ALWAYS_INLINE stsp_status_t stsp_clamp(const stsp_header_t *h, stsp_scalar_t *u,
                                                   uint16_t *mask)
{
    const uint32_t nu = stsp_nu(h);
    uint32_t i;
    uint32_t m = 0u;
    for (i = 0u; i < nu; ++i) {
        if (u[i] > h->u_max[i]) {
            u[i] = h->u_max[i];
            m |= (uint32_t)1u << i;
        } else if (u[i] < h->u_min[i]) {
            u[i] = h->u_min[i];
            m |= (uint32_t)1u << i;
        } else {
            /* within the limits */
        }
    }
    *mask = (uint16_t)m;
    return (m != 0u) ? STSP_WARN_SATURATED : STSP_OK;
}

#ifndef STSP_CLAMP_NO_FIXUP
/* An ordinary tick whose finite command (already in u) is out of range, or a false alarm
 * (stsp_controller.c, stsp_spline.c's float32 ticks; the Q spline ticks, which clamp their
 * command before writing u, define STSP_CLAMP_NO_FIXUP). */
static STSP_NOINLINE stsp_status_t stsp_step_fixup(stsp_ctrl_t *ctrl, uint32_t tick,
                                                   stsp_scalar_t *u)
{
    uint16_t mask = 0u;
    const stsp_status_t st = stsp_clamp(&ctrl->checked, u, &mask);
    ctrl->sat_mask = mask;
    ctrl->next_tick = tick + 1u;
    return st;
}
#endif

#ifndef STSP_ARITH_FIXED_POINT
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

/* 1 when sum is not finite: sum - sum is +0 for a finite sum, NaN for NaN and +-Inf. */
static STSP_ALWAYS_INLINE uint32_t stsp_total_alarm(stsp_f32_t sum)
{
    uint32_t out = 0u;
    if (!((sum - sum) == 0.0f)) {
        out = 1u;
    }
    return out;
}

/* Without limits, the cold-path alarm is whether the sum of the u[i] is not finite (any NaN
 * or Inf makes it NaN or Inf; a finite sum that overflows is a false alarm that stsp_limit()
 * clears). The generic float32 law takes the same sum as its rows end (stsp_controller.c). */
static STSP_ALWAYS_INLINE uint32_t stsp_unlimited_alarm(const stsp_header_t *h,
                                                        const stsp_f32_t *y)
{
    const uint32_t nu = stsp_nu(h);
    stsp_f32_t sum = -0.0f; /* -0 + a = a for every a: the compiler drops this add */
    uint32_t i;
    STSP_UNROLL
    for (i = 0u; i < nu; ++i) {
        sum += y[i];
    }
    return stsp_total_alarm(sum);
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

#else
/* Cold path, part 3, fixed point: some y[i] is outside [u_min[i], u_max[i]]; clamp it (the
 * law's u_q is always a valid integer: there is no non-finite case). */
static stsp_status_t stsp_limit(const stsp_header_t *h, const stsp_scalar_t *x,
                                stsp_scalar_t *y, uint16_t *mask)
{
    (void)x;
    return stsp_clamp(h, y, mask);
}

/* Without limits there is nothing to check: u_q is always a valid integer. */
static STSP_ALWAYS_INLINE uint32_t stsp_unlimited_alarm(const stsp_header_t *h,
                                                        const stsp_scalar_t *y)
{
    (void)h;
    (void)y;
    return 0u;
}

#endif

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

#endif /* STSP_TICK_H */
