/* Clamping to the actuator limits, shared by the law's limit check and the cold paths of
 * stsp_controller.c (which includes it through the law header). Private: not installed. */
#ifndef STSP_CLAMP_H
#define STSP_CLAMP_H

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

#endif /* STSP_CLAMP_H */
