/* The cold paths' tick plan, shared by stsp_controller.c (per-tick tables) and stsp_spline.c
 * (spline tables): range and order checks, the stage search, the latch into scratch, and the
 * commit of a successful step. Static and inlined into each cold path. Define STSP_PLAN_BAND
 * (0 or 1) before including it. Private: not installed. */
#ifndef STSP_PLAN_H
#define STSP_PLAN_H

#if (STSP_PLAN_BAND != 0) && !defined(STSP_ARITH_FIXED_POINT)
/* The stage-0 latch of a band table: v = the band dual's multipliers for the measured x,
 * rounded to binary32, zero beyond q. Returns 1 on success; 0 if the solver failed (v_new
 * untouched): x not finite (the affine fallback then propagates the NaN/Inf, and the step
 * fails with STSP_ERR_NONFINITE_STATE as for any table), Nt x + mt overflowed, no active set
 * met the optimality conditions (W not positive definite in double precision), or a
 * multiplier lies outside the binary32 range. The solver (stsp_bandqp_solve_f32, with its
 * ~0.8 KB of stack, used on this tick only) is the table's (stsp_bandqp_t.solve_f32), which
 * init checked (stsp_internal.h). */
static STSP_NOINLINE int stsp_band_latch(const stsp_header_t *h, const stsp_f32_t *x,
                                         stsp_f32_t *v_new)
{
    stsp_f32_t v[STSP_BANDQP_MAX];
    const uint32_t q = h->band.q;
    uint32_t i;
    /* The validated copy of the band dual's header, not the table's: q and nx as init checked. */
    if (h->band.solve_f32(&h->band, x, v) != STSP_BANDQP_OK) {
        return 0;
    }
    for (i = 0u; i < stsp_n_latch(h); ++i) {
        v_new[i] = (i < q) ? v[i] : 0.0f;
    }
    return 1;
}
#endif

/* Stage containing `tick`, searching forward from `from` (ticks only move forward; at most
 * n_stages steps, whatever stage_start holds now). */
static uint16_t stsp_stage_of(const stsp_header_t *h, uint16_t from, uint32_t tick)
{
    uint32_t s = from;
    while (((s + 1u) < h->n_stages) && (h->stage_start[s + 1u] <= tick)) {
        ++s;
    }
    return (uint16_t)s;
}

/* What a tick other than the ordinary one does: decided before anything is written. */
typedef struct {
    uint16_t stage;   /* stage of the tick */
    uint16_t relatch; /* nonzero: v_new holds a fresh latch for `stage` */
} stsp_plan_t;

/* Cold path, part 1: range and order checks, stage search, and the latch v_new = Lambda x +
 * lambda0 (or a copy of the v kept) into the caller's scratch: the instance changes only on
 * success, in stsp_commit(). Returns a negative error, or the tick warning (or STSP_OK).
 * Inlined into both cold paths (as a call it costs each cold tick some 20 instructions). The
 * band dual's latch only where STSP_PLAN_BAND is 1 (both cold paths: stsp_controller.c and,
 * for a spline band table, stsp_spline.c; each gets its own copy of stsp_band_latch). */
static STSP_ALWAYS_INLINE stsp_status_t stsp_plan(const stsp_ctrl_t *c, uint32_t tick,
                                                  const stsp_scalar_t *x, stsp_scalar_t *v_new,
                                                  stsp_plan_t *plan)
{
    const stsp_header_t *h = &c->checked;
    const uint32_t nx = stsp_nx(h);
    const uint32_t n_latch = stsp_n_latch(h);
    stsp_status_t status = STSP_OK;
    uint32_t i;
    uint32_t n_stage;
    uint16_t stage;

    if (tick >= h->n_ticks) {
        return STSP_ERR_TICK_RANGE;
    }
    if (c->next_tick > 0u) {
        if ((tick + 1u) < c->next_tick) {
            return STSP_ERR_TICK_ORDER;
        }
        if ((tick + 1u) == c->next_tick) {
            status = STSP_WARN_TICK_REPEATED;
        }
    }
    if (tick > c->next_tick) {
        status = STSP_WARN_TICK_SKIPPED;
    }
    stage = stsp_stage_of(h, c->stage, tick);
    /* A stage with stage_n_latch > 0 latches a fresh v at its first tick; one with
     * stage_n_latch == 0 keeps the v latched earlier (joint multipliers are latched once, at
     * stage 0). Only columns below n_latch are ever touched, whatever stage_n_latch holds. */
    n_stage = h->stage_n_latch[stage];
    plan->stage = stage;
    plan->relatch = 0u;
    if ((c->latched == 0u) || ((stage != c->stage) && (n_stage > 0u))) {
        plan->relatch = 1u;
    }
#if (STSP_PLAN_BAND != 0) && !defined(STSP_ARITH_FIXED_POINT)
    if ((plan->relatch != 0u) && (stage == 0u) && (h->band_qp != NULL)) {
        if (stsp_band_latch(h, x, v_new) != 0) {
            return status;
        }
        status = STSP_WARN_BAND_FALLBACK; /* the affine map below, from the design's x0 */
    }
#endif
    if (plan->relatch != 0u) {
        for (i = 0u; i < n_latch; ++i) {
            stsp_scalar_t acc = (stsp_scalar_t)0;
            if (i < n_stage) {
                const uint32_t row = ((uint32_t)stage * n_latch) + i;
                acc = stsp_latch_row(&h->Lambda[row * nx], h->lambda0[row], x, nx);
            }
            v_new[i] = acc;
        }
    } else {
        for (i = 0u; i < n_latch; ++i) {
            v_new[i] = c->v[i];
        }
    }
    return status;
}

/* The first tick after stage s, capped at the validated n_ticks even if stage_start changed
 * since init: the law never indexes a tick beyond the table. */
static uint32_t stsp_stage_end(const stsp_header_t *h, uint16_t s)
{
    const uint32_t end = h->stage_start[(uint32_t)s + 1u];
    return (end < h->n_ticks) ? end : h->n_ticks;
}

/* Cold path, part 2: the step succeeded; record the stage, the latch and the tick. */
static STSP_ALWAYS_INLINE void stsp_commit(stsp_ctrl_t *c, uint32_t tick,
                                           const stsp_plan_t *plan, const stsp_scalar_t *v_new)
{
    const stsp_header_t *h = &c->checked;
    if (plan->relatch != 0u) {
        uint32_t i;
        for (i = 0u; i < stsp_n_latch(h); ++i) {
            c->v[i] = v_new[i];
        }
        c->latched = 1u;
    }
    c->stage = plan->stage;
    c->stage_end = stsp_stage_end(h, plan->stage);
    if ((tick + 1u) > c->next_tick) {
        c->next_tick = tick + 1u;
    }
}

#endif /* STSP_PLAN_H */
