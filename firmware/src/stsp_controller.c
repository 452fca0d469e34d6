/* Latched time-varying affine controller: see stospline/stsp_controller.h for the contract
 * and docs/guide/firmware.md for the response to every fault and the MISRA deviations.
 *
 * Hot path. An ordinary tick (the expected tick, inside the stage already latched) runs
 * straight through stsp_step(): two compares select it, the law is evaluated from the tick's
 * rows of K, k0, L and the latched v, and one check says whether the command needs the cold
 * path. With limits, that check is a compare pair per input against [u_min, u_max], false
 * for NaN and for +-Inf (the limits are finite); without, it is whether the sum of the inputs
 * is finite. Either also serves as the finiteness check of the state: a NaN or infinite x[j]
 * reaches every input (each input sums K[i][j] x[j] over all j, and 0 * Inf is NaN), as does
 * a non-finite latch (each input sums L[i][c] v[c] over all columns). So x itself is read for
 * finiteness only on the cold path, to tell a bad state from an overflow. Everything else
 * (tick range, order, repeats, skips, stage changes, latching, clamping, errors) is on cold
 * paths in functions of their own.
 *
 * A spline table (float32) keeps stage_end at 0, so each of its ticks leaves that path for
 * stsp_step_spline: its ordinary tick is again two compares (the expected tick, inside the
 * recorded span), the spline law (stsp_law_spline.h) and the same checks, except that the
 * state is checked too (a sparse row need not use every x[j]); the first tick of the next
 * span is also evaluated without the cold path; everything else goes to stsp_step_cold_spline
 * (the per-tick cold path's plan and commit, plus the span search).
 *
 * After init every function works from the instance's copy of the validated header
 * (stsp_header_t: dimensions, array addresses, the band dual's header), never from the table
 * header, so a header changed later cannot move an access outside the arrays init checked;
 * stsp_verify() compares the two. x and u may overlap: each path computes the command into a
 * local array and writes u last, after every read of x.
 *
 * The sources, one job each: this file is the tick/latch state machine (init, reset, verify,
 * step); stsp_table.c validates and serialises the table (CRC-32); stsp_law.h is the law,
 * inlined into stsp_step(), on the row primitives and latch row of stsp_law_f32.h or
 * stsp_law_q.h (one, by STSP_ARITH_FIXED_POINT); stsp_law_spline.h the spline law (float32);
 * stsp_clamp.h the actuator clamp; stsp_internal.h the compiler and VFP helpers, the
 * dimensions the law uses and the fixed-point accumulator; stsp_crc32.c, stsp_qconv.c (Q
 * state/command conversions) and stsp_bandqp.c (the band dual) as named. Everything else here
 * (ticks, stages, latching order, statuses) is the same code in every arithmetic. */
#include "stsp_internal.h"
/* The law (stsp_law.h) on the row primitives of the configured arithmetic, inlined into
 * stsp_step(). */
#ifdef STSP_ARITH_FIXED_POINT
#include "stsp_law_q.h"
#else
#include "stsp_law_f32.h"
#endif
#include "stsp_law.h"
#ifndef STSP_ARITH_FIXED_POINT
#include "stsp_law_spline.h"
#endif

#include <float.h>
#include <string.h>

/* A refused init: the instance all zeros (not ready), as before it was given a table. */
static stsp_status_t stsp_refuse(stsp_ctrl_t *ctrl, stsp_status_t status)
{
    (void)memset(ctrl, 0, sizeof *ctrl);
    return status;
}

stsp_status_t stsp_init(stsp_ctrl_t *ctrl, const stsp_table_t *table)
{
    stsp_status_t st;
    if (ctrl == NULL) {
        return STSP_ERR_NULL;
    }
    (void)memset(ctrl, 0, sizeof *ctrl);
    if (table == NULL) {
        return STSP_ERR_NULL;
    }
    if (table->magic != STSP_TABLE_MAGIC) {
        return STSP_ERR_BAD_MAGIC;
    }
    if ((table->format_version != STSP_FORMAT_VERSION) ||
        (table->scalar_kind != STSP_SCALAR_KIND)) {
        return STSP_ERR_BAD_VERSION;
    }
    /* From here on only the copy's dimensions and addresses are used. */
    stsp_copy_header(&ctrl->checked, table);
    st = stsp_check_table(&ctrl->checked, table);
    if (st != STSP_OK) {
        return stsp_refuse(ctrl, st);
    }
    ctrl->table = table;
    stsp_copy(ctrl->hold, table->u_hold, ctrl->checked.nu);
    ctrl->limited = stsp_has_limits(&ctrl->checked);
    ctrl->ready = STSP_CTRL_READY;
    return STSP_OK;
}

stsp_status_t stsp_init_expect(stsp_ctrl_t *ctrl, const stsp_table_t *table, uint32_t nx,
                               uint32_t nu)
{
    stsp_status_t st = stsp_init(ctrl, table);
    if ((st == STSP_OK) && ((ctrl->checked.nx != nx) || (ctrl->checked.nu != nu))) {
        st = stsp_refuse(ctrl, STSP_ERR_BAD_DIMS);
    }
    return st;
}

stsp_status_t stsp_init_problem(stsp_ctrl_t *ctrl, const stsp_table_t *table, uint32_t nx,
                                uint32_t nu, const uint8_t *problem_sha256)
{
    stsp_status_t st;
    if (problem_sha256 == NULL) {
        if (ctrl != NULL) {
            (void)memset(ctrl, 0, sizeof *ctrl);
        }
        return STSP_ERR_NULL;
    }
    st = stsp_init_expect(ctrl, table, nx, nu);
    if ((st == STSP_OK) &&
        (memcmp(table->problem_sha256, problem_sha256, sizeof table->problem_sha256) != 0)) {
        st = stsp_refuse(ctrl, STSP_ERR_BAD_PROBLEM);
    }
    return st;
}

stsp_status_t stsp_reset(stsp_ctrl_t *ctrl)
{
    const stsp_status_t st = stsp_check_ready(ctrl);
    if (st != STSP_OK) {
        return st;
    }
    ctrl->next_tick = 0u;
    ctrl->stage_end = 0u;
    ctrl->stage = 0u;
    ctrl->latched = 0u;
    ctrl->sat_mask = 0u;
    stsp_zero(ctrl->v, STSP_MAX_LATCH);
#ifndef STSP_ARITH_FIXED_POINT
    (void)memset(&ctrl->span, 0, sizeof ctrl->span);
#endif
    return STSP_OK;
}

stsp_status_t stsp_verify(stsp_ctrl_t *ctrl)
{
    const stsp_status_t st = stsp_check_ready(ctrl);
    if (st != STSP_OK) {
        return st;
    }
    /* The header first: the CRC below reads the arrays only as the copy describes them. */
    if (stsp_header_changed(&ctrl->checked, ctrl->table) != 0) {
        ctrl->ready = STSP_CTRL_STOPPED;
        return STSP_ERR_TABLE_CHANGED;
    }
    if (stsp_crc_of(&ctrl->checked, ctrl->table) != ctrl->table->crc32) {
        ctrl->ready = STSP_CTRL_STOPPED;
        return STSP_ERR_BAD_CRC;
    }
    return STSP_OK;
}

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

#ifndef STSP_ARITH_FIXED_POINT
/* The stage-0 latch of a band table: v = the band dual's multipliers for the measured x,
 * rounded to binary32, zero beyond q. Returns 1 on success; 0 if the solver failed (v_new
 * untouched): x not finite (the affine fallback then propagates the NaN/Inf, and the step
 * fails with STSP_ERR_NONFINITE_STATE as for any table), Nt x + mt overflowed, no active set
 * met the optimality conditions (W not positive definite in double precision), or a
 * multiplier lies outside the binary32 range. The solver (stsp_bandqp_solve_f32, with its
 * ~0.8 KB of stack, used on this tick only) is linked only into programs with a band table:
 * init refuses a band table without it (stsp_internal.h). */
static STSP_NOINLINE int stsp_band_latch(const stsp_header_t *h, const stsp_f32_t *x,
                                         stsp_f32_t *v_new)
{
    stsp_f32_t v[STSP_BANDQP_MAX];
    const uint32_t q = h->band.q;
    uint32_t i;
    /* The validated copy of the band dual's header, not the table's: q and nx as init checked. */
    if (stsp_bandqp_solve_f32(&h->band, x, v) != STSP_BANDQP_OK) {
        return 0;
    }
    for (i = 0u; i < stsp_n_latch(h); ++i) {
        v_new[i] = (i < q) ? v[i] : 0.0f;
    }
    return 1;
}
#endif

/* What a tick other than the ordinary one does: decided before anything is written. */
typedef struct {
    uint16_t stage;   /* stage of the tick */
    uint16_t relatch; /* nonzero: v_new holds a fresh latch for `stage` */
} stsp_plan_t;

/* Cold path, part 1: range and order checks, stage search, and the latch v_new = Lambda x +
 * lambda0 (or a copy of the v kept) into the caller's scratch: the instance changes only on
 * success, in stsp_commit(). Returns a negative error, or the tick warning (or STSP_OK).
 * Inlined into both cold paths (as a call it costs each cold tick some 20 instructions). */
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
#ifndef STSP_ARITH_FIXED_POINT
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

#ifndef STSP_ARITH_FIXED_POINT
/* Cold path, spline table: the span of `tick` in `stage`, into p. The search starts at the
 * span of the last step when the tick stays in its stage (a later tick, or the same again:
 * never before that span), else at the stage's first span. */
static void stsp_spline_locate(const stsp_ctrl_t *c, uint32_t tick, uint16_t stage,
                               stsp_span_t *p)
{
    const uint32_t from = ((c->latched != 0u) && (stage == c->stage)) ? c->span.span : 0u;
    stsp_spline_span(&c->checked, stage, from, tick, stsp_stage_end(&c->checked, stage), p);
}

/* Ordinary tick of a spline table, success: the span it evaluated, the one after the
 * recorded one (stsp_step_spline checked that there is one in the stage), into the instance. */
static STSP_NOINLINE void stsp_spline_next_span(stsp_ctrl_t *c, uint32_t tick,
                                                const stsp_f32_t *knot, const stsp_f32_t *coef)
{
    stsp_span_t *p = &c->span;
    const uint32_t sigma = p->span + 1u;
    p->span = sigma;
    p->knot = knot;
    p->coef = coef;
    p->next = stsp_span_end(knot, sigma, p->n_spans, tick, p->first,
                            stsp_stage_end(&c->checked, c->stage));
}

/* Cold path, spline table: the state and a fresh latch must be finite, as the command does
 * not show it (an input need not use every x[j] or v[c]): STSP_ERR_NONFINITE_STATE, else
 * STSP_ERR_NONFINITE_OUTPUT for a latch that overflowed, else STSP_OK. */
static stsp_status_t stsp_spline_inputs(const stsp_header_t *h, const stsp_f32_t *x,
                                        const stsp_f32_t *v_new, uint32_t relatch)
{
    if (stsp_all_finite(x, stsp_nx(h)) == 0) {
        return STSP_ERR_NONFINITE_STATE;
    }
    if ((relatch != 0u) && (stsp_all_finite(v_new, stsp_n_latch(h)) == 0)) {
        return STSP_ERR_NONFINITE_OUTPUT;
    }
    return STSP_OK;
}
#endif

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

/* Every tick but the ordinary one: range, order, repeat, skip, stage change, latch. The
 * command is computed into y and written to u last, after every read of x. */
static STSP_NOINLINE stsp_status_t stsp_step_cold(stsp_ctrl_t *ctrl, uint32_t tick,
                                                  const stsp_scalar_t *x, stsp_scalar_t *u)
{
    const stsp_header_t *h = &ctrl->checked;
    stsp_scalar_t v_new[STSP_MAX_LATCH];
    stsp_scalar_t y[STSP_MAX_NU];
    stsp_plan_t plan = {0u, 0u};
    stsp_status_t status;
    uint16_t mask = 0u;
    stsp_zero(v_new, STSP_MAX_LATCH);
    status = stsp_plan(ctrl, tick, x, v_new, &plan);
    if (status >= STSP_OK) {
        if (stsp_law(h, tick, x, v_new, y, ctrl->limited) != 0u) {
            const stsp_status_t st = stsp_limit(h, x, y, &mask);
            if (st != STSP_OK) {
                status = st; /* an error, or STSP_WARN_SATURATED over a tick warning */
            }
        }
    }
    if (status < STSP_OK) {
        stsp_hold(ctrl, u);
        return status;
    }
    stsp_copy(u, y, stsp_nu(h));
    ctrl->sat_mask = mask;
    stsp_commit(ctrl, tick, &plan, v_new);
    return status;
}

#ifndef STSP_ARITH_FIXED_POINT
/* The spline law out of line, for the ticks other than the ordinary one (the first of a span,
 * the cold path): one more copy of it in flash instead of two. */
static STSP_NOINLINE uint32_t stsp_spline_law_other(const stsp_header_t *h, const stsp_span_t *p,
                                                    const stsp_f32_t *knot,
                                                    const stsp_f32_t *coef, uint32_t tick,
                                                    const stsp_f32_t *x, const stsp_f32_t *v,
                                                    stsp_f32_t *y, uint32_t limited)
{
    return stsp_spline_law(h, p, knot, coef, tick, x, v, y, limited);
}

/* Every tick of a spline table but its ordinary one, as stsp_step_cold: the same plan and
 * commit, with the span located and recorded, and the state and a fresh latch checked for
 * finiteness (stsp_spline_inputs). stage_end stays 0: every tick of a spline table leaves
 * stsp_step's ordinary path for stsp_step_spline, which compares with the span's end. */
static STSP_NOINLINE stsp_status_t stsp_step_cold_spline(stsp_ctrl_t *ctrl, uint32_t tick,
                                                         const stsp_f32_t *x, stsp_f32_t *u)
{
    const stsp_header_t *h = &ctrl->checked;
    stsp_f32_t v_new[STSP_MAX_LATCH];
    stsp_f32_t y[STSP_MAX_NU];
    stsp_plan_t plan = {0u, 0u};
    stsp_span_t span; /* written by stsp_spline_locate before any use */
    stsp_status_t status;
    uint16_t mask = 0u;
    stsp_zero(v_new, STSP_MAX_LATCH);
    status = stsp_plan(ctrl, tick, x, v_new, &plan);
    if (status >= STSP_OK) {
        const stsp_status_t st = stsp_spline_inputs(h, x, v_new, plan.relatch);
        if (st != STSP_OK) {
            status = st;
        } else {
            stsp_spline_locate(ctrl, tick, plan.stage, &span);
            if (stsp_spline_law_other(h, &span, span.knot, span.coef, tick, x, v_new, y,
                                      ctrl->limited) != 0u) {
                const stsp_status_t lim = stsp_limit(h, x, y, &mask);
                if (lim != STSP_OK) {
                    status = lim;
                }
            }
        }
    }
    if (status < STSP_OK) {
        stsp_hold(ctrl, u);
        return status;
    }
    stsp_copy(u, y, stsp_nu(h));
    ctrl->sat_mask = mask;
    stsp_commit(ctrl, tick, &plan, v_new);
    ctrl->stage_end = 0u;
    stsp_spline_commit(h, &ctrl->span, &span);
    return status;
}
#endif

/* An ordinary tick whose finite command (already in u) is out of range, or a false alarm. */
static STSP_NOINLINE stsp_status_t stsp_step_fixup(stsp_ctrl_t *ctrl, uint32_t tick,
                                                   stsp_scalar_t *u)
{
    uint16_t mask = 0u;
    const stsp_status_t st = stsp_clamp(&ctrl->checked, u, &mask);
    ctrl->sat_mask = mask;
    ctrl->next_tick = tick + 1u;
    return st;
}

/* Not ready: u is not written, as nu is unknown; except for an instance stsp_verify() stopped,
 * which knows its validated nu and the safe command init copied. */
static STSP_NOINLINE stsp_status_t stsp_step_refused(const stsp_ctrl_t *ctrl, stsp_scalar_t *u)
{
    if (ctrl->ready == STSP_CTRL_STOPPED) {
        stsp_hold(ctrl, u);
    }
    return STSP_ERR_NOT_INITIALIZED;
}

/* x is NULL: the safe command. Out of line, as the refused paths: inline, the copy costs the
 * Cortex-M0+ Q31 ordinary tick some 70 instructions of register pressure (and 1 elsewhere). */
static STSP_NOINLINE stsp_status_t stsp_step_null_state(const stsp_ctrl_t *ctrl,
                                                        stsp_scalar_t *u)
{
    stsp_hold(ctrl, u);
    return STSP_ERR_NULL;
}

#ifndef STSP_ARITH_FIXED_POINT
/* A spline table's tick inside the span whose knots start at knot and whose first entry's
 * coefficients at coef: the recorded span (advance 0), or the next one (advance 1: recorded on
 * success). As the per-tick ordinary tick, a NaN/Inf command or state is an error that depends
 * on x, read before u is written; otherwise the command is clamped in place if need be.
 * Inlined into both callers with advance a constant. */
static STSP_ALWAYS_INLINE stsp_status_t stsp_spline_tick(stsp_ctrl_t *ctrl,
                                                         const stsp_f32_t *knot,
                                                         const stsp_f32_t *coef,
                                                         uint32_t advance, uint32_t tick,
                                                         const stsp_f32_t *x, stsp_f32_t *u)
{
    const stsp_header_t *h = &ctrl->checked;
    stsp_f32_t y[STSP_MAX_NU];
    const uint32_t out =
        (advance != 0u)
            ? stsp_spline_law_other(h, &ctrl->span, knot, coef, tick, x, ctrl->v, y,
                                    ctrl->limited)
            : stsp_spline_law(h, &ctrl->span, knot, coef, tick, x, ctrl->v, y, ctrl->limited);
    if ((out != 0u) &&
        ((stsp_command_finite(h, y) == 0) || (stsp_all_finite(x, stsp_nx(h)) == 0))) {
        return stsp_step_nonfinite(ctrl, x, u);
    }
    stsp_copy(u, y, stsp_nu(h));
    if (advance != 0u) {
        stsp_spline_next_span(ctrl, tick, knot, coef);
    }
    if (out != 0u) {
        return stsp_step_fixup(ctrl, tick, u);
    }
    ctrl->next_tick = tick + 1u;
    return STSP_OK;
}

/* A spline table's tick other than the ordinary one: the expected tick that starts the next
 * span of the stage is that span's tick (its knots and coefficients one further: within the
 * stage's arrays, as there is a next span); anything else the cold path. Out of line, so that
 * the ordinary tick keeps its registers. */
static STSP_NOINLINE stsp_status_t stsp_step_next_span(stsp_ctrl_t *ctrl, uint32_t tick,
                                                       const stsp_f32_t *x, stsp_f32_t *u)
{
    const stsp_span_t *p = &ctrl->span;
    const uint32_t nu = stsp_nu(&ctrl->checked);
    if ((tick != ctrl->next_tick) || (tick != p->next) || ((p->span + 1u) >= p->n_spans)) {
        return stsp_step_cold_spline(ctrl, tick, x, u);
    }
    /* The coefficients move only when the stage has entries (otherwise the pointer is the
     * stage's first coefficient, which may be one past the array). */
    return stsp_spline_tick(ctrl, &p->knot[1],
                            (p->row_end[nu - 1u] > 0u) ? &p->coef[1] : p->coef, 1u, tick, x, u);
}

/* A spline table's every tick (its stage_end stays 0, so each leaves stsp_step's ordinary
 * path). The ordinary one is here: the expected tick inside the span of the last step
 * (span.next is 0 until the first latch, and never beyond the stage or n_ticks). Anything
 * else takes stsp_step_next_span. */
static STSP_NOINLINE stsp_status_t stsp_step_spline(stsp_ctrl_t *ctrl, uint32_t tick,
                                                    const stsp_f32_t *x, stsp_f32_t *u)
{
    if ((tick != ctrl->next_tick) || (tick >= ctrl->span.next)) {
        return stsp_step_next_span(ctrl, tick, x, u);
    }
    return stsp_spline_tick(ctrl, ctrl->span.knot, ctrl->span.coef, 0u, tick, x, u);
}

/* Every tick that leaves stsp_step's ordinary path: a spline table's, or the cold path. Its
 * own function, so that the per-tick cold path does not pay for the spline tick's frame. */
static STSP_NOINLINE stsp_status_t stsp_step_other(stsp_ctrl_t *ctrl, uint32_t tick,
                                                   const stsp_f32_t *x, stsp_f32_t *u)
{
    if (ctrl->checked.spline != NULL) {
        return stsp_step_spline(ctrl, tick, x, u);
    }
    return stsp_step_cold(ctrl, tick, x, u);
}
#endif

stsp_status_t stsp_step(stsp_ctrl_t *ctrl, uint32_t tick, const stsp_scalar_t *x,
                        stsp_scalar_t *u)
{
    stsp_scalar_t y[STSP_MAX_NU];
    uint32_t out;
    if ((u == NULL) || (ctrl == NULL)) {
        return STSP_ERR_NULL;
    }
    if (ctrl->ready != STSP_CTRL_READY) {
        return stsp_step_refused(ctrl, u);
    }
    if (x == NULL) {
        return stsp_step_null_state(ctrl, u);
    }
    /* Ordinary tick: the expected one, inside the latched stage (stage_end is 0 until the
     * first latch, and never above n_ticks). Anything else takes the cold path; every tick
     * of a spline table (stage_end 0) its own, stsp_step_spline. */
    if ((tick != ctrl->next_tick) || (tick >= ctrl->stage_end)) {
#ifndef STSP_ARITH_FIXED_POINT
        return stsp_step_other(ctrl, tick, x, u);
#else
        return stsp_step_cold(ctrl, tick, x, u);
#endif
    }
    out = stsp_law(&ctrl->checked, tick, x, ctrl->v, y, ctrl->limited);
#ifndef STSP_ARITH_FIXED_POINT
    /* A NaN/Inf command: which error it is depends on x, read before u is written. */
    if ((out != 0u) && (stsp_command_finite(&ctrl->checked, y) == 0)) {
        return stsp_step_nonfinite(ctrl, x, u);
    }
#endif
    stsp_copy(u, y, stsp_nu(&ctrl->checked));
    if (out != 0u) {
        return stsp_step_fixup(ctrl, tick, u);
    }
    ctrl->next_tick = tick + 1u;
    return STSP_OK;
}

#ifdef STSP_HOST_MESSAGES
const char *stsp_status_str(stsp_status_t status)
{
    const char *text;
    switch (status) {
    case STSP_OK: text = "ok"; break;
    case STSP_WARN_TICK_SKIPPED: text = "tick skipped: evaluated at the given tick"; break;
    case STSP_WARN_TICK_REPEATED: text = "tick repeated: recomputed without a new latch"; break;
    case STSP_WARN_SATURATED: text = "command clamped to the actuator limits"; break;
    case STSP_WARN_STATE_CLAMPED: text = "state outside the fixed-point range, saturated"; break;
    case STSP_WARN_BAND_FALLBACK: text = "band QP failed: latched the design's affine map"; break;
    case STSP_ERR_NULL: text = "null pointer argument"; break;
    case STSP_ERR_NOT_INITIALIZED: text = "controller not initialized"; break;
    case STSP_ERR_BAD_MAGIC: text = "table magic mismatch"; break;
    case STSP_ERR_BAD_VERSION: text = "table format or scalar variant not supported"; break;
    case STSP_ERR_BAD_DIMS: text = "table dimensions invalid"; break;
    case STSP_ERR_BAD_CRC: text = "table CRC mismatch"; break;
    case STSP_ERR_TICK_RANGE: text = "tick beyond the end of the table"; break;
    case STSP_ERR_TICK_ORDER: text = "tick went backwards"; break;
    case STSP_ERR_NONFINITE_STATE: text = "state not finite"; break;
    case STSP_ERR_NONFINITE_OUTPUT: text = "command overflowed"; break;
    case STSP_ERR_BAD_PROBLEM: text = "table made from another problem file"; break;
    case STSP_ERR_BAD_VALUES: text = "table values not finite or limits invalid"; break;
    case STSP_ERR_TABLE_CHANGED: text = "table header changed since init"; break;
    default: text = "unknown status"; break;
    }
    return text;
}
#endif
