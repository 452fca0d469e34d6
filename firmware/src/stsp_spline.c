/* Spline tables (stsp_spline_t, float32 builds): their every tick (stsp_spline_step, which
 * stsp_step() calls for a spline table) and their layout checks at init
 * (stsp_spline_check_dims). Its own translation unit so that a program without a spline table
 * does not link it: the controller refers to both functions weakly (stsp_internal.h), and a
 * generated spline table refers strongly to stsp_spline_code, defined here. The law itself is
 * stsp_law_spline.h. */
#include "stsp_internal.h"

#ifndef STSP_ARITH_FIXED_POINT
#include "stsp_law_f32.h"
/* Of stsp_law.h only the alarm (stsp_law_alarm): not the per-tick law's out-of-line rows. */
#define STSP_LAW_ALARM_ONLY 1
#include "stsp_law.h"
#include "stsp_law_spline.h"
#define STSP_PLAN_BAND 1
#include "stsp_plan.h"
#endif

/* The symbol a generated spline table refers to (also in fixed-point builds, which refuse
 * spline tables: a table generated for float32 then still links, and init says why). */
const uint32_t stsp_spline_code = STSP_FORMAT_VERSION;

#ifndef STSP_ARITH_FIXED_POINT

/* 1 when the knots k[0..len) are stage s's clamped knot vector for `ticks` ticks (< 2^24, so
 * every integer up to it is a binary32): four 0, then strictly increasing integers in (0,
 * ticks), then four times `ticks`. NaN fails every comparison. */
static int stsp_knots_ok(const stsp_f32_t *k, uint32_t len, uint32_t ticks)
{
    const stsp_f32_t end = (stsp_f32_t)ticks;
    uint32_t i;
    for (i = 0u; i < 4u; ++i) {
        if (!(k[i] == 0.0f) || !(k[len - 4u + i] == end)) {
            return 0;
        }
    }
    for (i = 4u; i < (len - 4u); ++i) {
        /* 0 < k[i] < ticks < 2^24 here, so the conversion is defined. */
        if (!(k[i] > k[i - 1u]) || !(k[i] < end) ||
            ((stsp_f32_t)(uint32_t)k[i] != k[i])) {
            return 0;
        }
    }
    return 1;
}

/* Stage s of a spline table, once knot_start, row_start and coef_start are known to be
 * nondecreasing within their arrays: fewer than 2^24 ticks, S + 3 coefficients for each of its
 * entries (no product is formed: it could wrap), its knots (stsp_knots_ok). */
static stsp_status_t stsp_check_spline_stage(const stsp_header_t *h, uint32_t s)
{
    const stsp_spline_t *p = &h->sp;
    const uint32_t nu = h->nu;
    const uint32_t ticks = h->stage_start[s + 1u] - h->stage_start[s];
    const uint32_t k0 = p->knot_start[s];
    const uint32_t n_knots = p->knot_start[s + 1u] - k0;
    const uint32_t n_coef = p->coef_start[s + 1u] - p->coef_start[s];
    const uint32_t entries = (uint32_t)p->row_start[(s + 1u) * nu] - p->row_start[s * nu];
    const uint32_t stride = n_knots - 4u; /* S + 3 */
    if ((ticks >= 16777216u) || ((n_coef % stride) != 0u) || ((n_coef / stride) != entries) ||
        (stsp_knots_ok(&p->knot[k0], n_knots, ticks) == 0)) {
        return STSP_ERR_BAD_DIMS;
    }
    return STSP_OK;
}

/* A spline table's layout (stsp_spline_t): its arrays present; the three index arrays from 0
 * to their lengths and nondecreasing, at least 8 knots per stage (all checked before any
 * other element is read through them); every operand index below nx + 1 + n_latch; each stage
 * as stsp_check_spline_stage says. */
stsp_status_t stsp_spline_check_dims(const stsp_header_t *h)
{
    const stsp_spline_t *p = &h->sp;
    const uint32_t ns = h->n_stages;
    const uint32_t rows = ns * (uint32_t)h->nu;
    const uint32_t nz = (uint32_t)h->nx + 1u + h->n_latch;
    uint32_t i;
    if ((p->knot_start == NULL) || (p->knot == NULL) || (p->row_start == NULL) ||
        (p->col == NULL) || (p->coef_start == NULL) || (p->coef == NULL)) {
        return STSP_ERR_NULL;
    }
    if ((p->knot_start[0] != 0u) || (p->knot_start[ns] != p->n_knots) ||
        (p->row_start[0] != 0u) || (p->row_start[rows] != p->n_entries) ||
        (p->coef_start[0] != 0u) || (p->coef_start[ns] != p->n_coef)) {
        return STSP_ERR_BAD_DIMS;
    }
    for (i = 0u; i < ns; ++i) {
        const uint32_t k0 = p->knot_start[i];
        const uint32_t k1 = p->knot_start[i + 1u];
        if ((k1 < k0) || ((k1 - k0) < 8u) || (p->coef_start[i + 1u] < p->coef_start[i])) {
            return STSP_ERR_BAD_DIMS;
        }
    }
    for (i = 0u; i < rows; ++i) {
        if (p->row_start[i + 1u] < p->row_start[i]) {
            return STSP_ERR_BAD_DIMS;
        }
    }
    for (i = 0u; i < p->n_entries; ++i) {
        if (p->col[i] >= nz) {
            return STSP_ERR_BAD_DIMS;
        }
    }
    /* Within a row the operands increase: the gains of x first (the ordinary tick's loop),
     * then k0 and L (folded into one spline per input at a span change). */
    for (i = 0u; i < rows; ++i) {
        uint32_t e;
        for (e = (uint32_t)p->row_start[i] + 1u; e < p->row_start[i + 1u]; ++e) {
            if (p->col[e] <= p->col[e - 1u]) {
                return STSP_ERR_BAD_DIMS;
            }
        }
    }
    for (i = 0u; i < ns; ++i) {
        const stsp_status_t st = stsp_check_spline_stage(h, i);
        if (st != STSP_OK) {
            return st;
        }
    }
    return STSP_OK;
}
/* Cold path, spline table: the span of `tick` in `stage`, into p. The search starts at the
 * span of the last step when the tick stays in its stage (a later tick, or the same again:
 * never before that span), else at the stage's first span. */
static void stsp_spline_locate(const stsp_ctrl_t *c, uint32_t tick, uint16_t stage,
                               stsp_span_t *p)
{
    const uint32_t from = ((c->latched != 0u) && (stage == c->stage)) ? c->span.span : 0u;
    stsp_spline_span(&c->checked, stage, from, tick, stsp_stage_end(&c->checked, stage), p);
}

/* The first tick of the next span, success: that span (stsp_step_next_span checked that
 * there is one in the stage) and its fold, into the instance. */
static void stsp_spline_next_span(stsp_ctrl_t *c, uint32_t tick, const stsp_f32_t *knot,
                                  stsp_f32_t inv, const stsp_f32_t *coef,
                                  const stsp_f32_t *fold)
{
    stsp_span_t *p = &c->span;
    const uint32_t sigma = p->span + 1u;
    p->span = sigma;
    p->knot = knot;
    p->inv = inv;
    p->coef = coef;
    p->next = stsp_span_end(knot, sigma, p->n_spans, tick, p->first,
                            stsp_stage_end(&c->checked, c->stage));
    stsp_spline_copy_fold(&c->checked, p->fold, fold);
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

/* The spline law out of line, for the ticks other than the ordinary one (the first of a span,
 * the cold path): one more copy of it in flash instead of two. */
static STSP_NOINLINE uint32_t stsp_spline_law_other(const stsp_header_t *h, const stsp_span_t *p,
                                                    const stsp_f32_t *knot, stsp_f32_t inv,
                                                    const stsp_f32_t *coef,
                                                    const stsp_f32_t *fold, uint32_t tick,
                                                    const stsp_f32_t *x, stsp_f32_t *y,
                                                    uint32_t limited)
{
    return stsp_spline_law(h, p, knot, inv, coef, fold, tick, x, y, limited);
}

/* Every tick of a spline table but its ordinary one, as stsp_step_cold: the same plan and
 * commit, with the span located and recorded, and the state and a fresh latch checked for
 * finiteness (stsp_spline_inputs). stage_end stays 0: every tick of a spline table leaves
 * stsp_step's ordinary path for stsp_spline_step, which compares with the span's end. */
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
            stsp_spline_fold(h, &span, span.coef, v_new, span.fold);
            if (stsp_spline_law_other(h, &span, span.knot, span.inv, span.coef, span.fold, tick,
                                      x, y, ctrl->limited) != 0u) {
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

/* What a spline table's tick does once its command is in y and out says whether it needs a
 * look (stsp_spline_law): as the per-tick ordinary tick, a NaN/Inf command or state is an
 * error that depends on x, read before u is written; otherwise the command is written and
 * clamped in place if need be. Returns 1 when u holds a command (the step succeeded so far),
 * with *st its status; 0 on an error (*st), u then the safe command. */
static STSP_ALWAYS_INLINE uint32_t stsp_spline_finish(stsp_ctrl_t *ctrl, uint32_t tick,
                                                      const stsp_f32_t *x, stsp_f32_t *u,
                                                      const stsp_f32_t *y, uint32_t out,
                                                      stsp_status_t *st)
{
    const stsp_header_t *h = &ctrl->checked;
    if ((out != 0u) &&
        ((stsp_command_finite(h, y) == 0) || (stsp_all_finite(x, stsp_nx(h)) == 0))) {
        *st = stsp_step_nonfinite(ctrl, x, u);
        return 0u;
    }
    stsp_copy_command(u, y, stsp_nu(h));
    if (out != 0u) {
        *st = stsp_step_fixup(ctrl, tick, u);
    } else {
        ctrl->next_tick = tick + 1u;
        *st = STSP_OK;
    }
    return 1u;
}

/* A spline table's tick other than the ordinary one: the expected tick that starts the next
 * span of the stage is that span's tick (its knots and coefficients one further: within the
 * stage's arrays, as there is a next span; the fold of the kept v computed for it and
 * recorded on success); anything else the cold path. Out of line, so that the ordinary tick
 * keeps its registers. */
static STSP_NOINLINE stsp_status_t stsp_step_next_span(stsp_ctrl_t *ctrl, uint32_t tick,
                                                       const stsp_f32_t *x, stsp_f32_t *u)
{
    const stsp_header_t *h = &ctrl->checked;
    const stsp_span_t *p = &ctrl->span;
    stsp_f32_t fold[4u * STSP_MAX_NU];
    stsp_f32_t y[STSP_MAX_NU];
    const stsp_f32_t *knot;
    const stsp_f32_t *coef;
    stsp_f32_t inv;
    stsp_status_t st = STSP_OK;
    uint32_t out;
    if ((tick != ctrl->next_tick) || (tick != p->next) || ((p->span + 1u) >= p->n_spans)) {
        return stsp_step_cold_spline(ctrl, tick, x, u);
    }
    knot = &p->knot[1];
    inv = stsp_span_inv(knot);
    /* The coefficients move only when the stage has entries (otherwise the pointer is the
     * stage's first coefficient, which may be one past the array). */
    coef = (p->row_end[stsp_nu(h) - 1u] > 0u) ? &p->coef[1] : p->coef;
    stsp_spline_fold(h, p, coef, ctrl->v, fold);
    out = stsp_spline_law_other(h, p, knot, inv, coef, fold, tick, x, y, ctrl->limited);
    if (stsp_spline_finish(ctrl, tick, x, u, y, out, &st) != 0u) {
        stsp_spline_next_span(ctrl, tick, knot, inv, coef, fold);
    }
    return st;
}

/* A spline table's every tick (its stage_end stays 0, so each leaves stsp_step's ordinary
 * path). The ordinary one is here: the expected tick inside the span of the last step
 * (span.next is 0 until the first latch, and never beyond the stage or n_ticks). Anything
 * else takes stsp_step_next_span. */
stsp_status_t stsp_spline_step(stsp_ctrl_t *ctrl, uint32_t tick, const stsp_f32_t *x,
                               stsp_f32_t *u)
{
    const stsp_span_t *p = &ctrl->span;
    stsp_f32_t y[STSP_MAX_NU];
    stsp_status_t st = STSP_OK;
    uint32_t out;
    if ((tick != ctrl->next_tick) || (tick >= p->next)) {
        return stsp_step_next_span(ctrl, tick, x, u);
    }
    out = stsp_spline_law(&ctrl->checked, p, p->knot, p->inv, p->coef, p->fold, tick, x, y,
                          ctrl->limited);
    (void)stsp_spline_finish(ctrl, tick, x, u, y, out, &st);
    return st;
}

#endif /* STSP_ARITH_FIXED_POINT */
