/* Latched time-varying affine controller: see stospline/stsp_controller.h for the contract
 * and docs/guide/firmware.md for the response to every fault and the MISRA deviations.
 *
 * Hot path. An ordinary tick (the expected tick, inside the stage already latched) runs
 * straight through stsp_step(): two compares select it, the law is evaluated from the tick's
 * rows of K, k0, L (in the float32 build with run-time dimensions the rows the instance keeps
 * for next_tick, stsp_ctrl_t.rows, in a tail-called stsp_step_ordinary) and the latched v,
 * and one check says whether the command needs the cold path. With limits, that check is a compare pair per input against [u_min, u_max], false
 * for NaN and for +-Inf (the limits are finite); without, it is whether the sum of the inputs
 * is finite. Either also serves as the finiteness check of the state: a NaN or infinite x[j]
 * reaches every input (each input sums K[i][j] x[j] over all j, and 0 * Inf is NaN), as does
 * a non-finite latch (each input sums L[i][c] v[c] over all columns). So x itself is read for
 * finiteness only on the cold path, to tell a bad state from an overflow. Everything else
 * (tick range, order, repeats, skips, stage changes, latching, clamping, errors) is on cold
 * paths in functions of their own.
 *
 * A spline table (float32) keeps stage_end at 0, so each of its ticks leaves that path for
 * stsp_spline_ops.step (stsp_spline.c): its ordinary tick is again two compares (the expected
 * tick, inside the recorded span), the spline law (stsp_law_spline.h) and the same checks, except that the
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
 * stsp_law_q.h (one, by STSP_ARITH_FIXED_POINT); stsp_spline.c a spline table's ticks and
 * layout checks (linked only with a spline table, through its ops), on the spline law of stsp_law_spline.h;
 * stsp_plan.h the cold paths' plan and commit;
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
/* The cold path's plan and commit, with the band dual's latch (stsp_spline.c has its own copy,
 * without). */
#define STSP_PLAN_BAND 1
#include "stsp_plan.h"

#include <float.h>
#include <string.h>

/* float32 with run-time dimensions: the instance keeps the rows of tick next_tick
 * (stsp_ctrl_t.rows), and the ordinary tick is a function of its own (stsp_step_ordinary). */
#if !defined(STSP_ARITH_FIXED_POINT) && !defined(STSP_FIXED_NX)
#define STSP_ROW_CACHE 1
#else
#define STSP_ROW_CACHE 0
#endif

#if STSP_ROW_CACHE
/* The rows of tick 0 into the instance, from the validated copy: where init and reset leave
 * next_tick (stage_end 0: the first tick takes the cold path, which sets them again). */
static void stsp_rows_first(stsp_ctrl_t *ctrl)
{
    ctrl->rows.K = ctrl->checked.K;
    ctrl->rows.k0 = ctrl->checked.k0;
    ctrl->rows.L = ctrl->checked.L;
}
#endif

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
#if STSP_ROW_CACHE
    stsp_rows_first(ctrl);
#endif
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
#if STSP_ROW_CACHE
    stsp_rows_first(ctrl);
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
#if STSP_ROW_CACHE
    stsp_rows_t next = ctrl->rows;
#endif
    stsp_zero(v_new, STSP_MAX_LATCH);
    status = stsp_plan(ctrl, tick, x, v_new, &plan);
    if (status >= STSP_OK) {
#if STSP_ROW_CACHE
        const uint32_t alarm = stsp_law(h, tick, x, v_new, y, ctrl->limited, &next);
#else
        const uint32_t alarm = stsp_law(h, tick, x, v_new, y, ctrl->limited);
#endif
        if (alarm != 0u) {
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
#if STSP_ROW_CACHE
    /* A successful cold tick leaves next_tick == tick + 1 (stsp_plan refuses tick + 1 <
     * next_tick, stsp_commit raises next_tick to tick + 1): the law's next rows are its rows. */
    ctrl->rows = next;
#endif
    return status;
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


/* The ordinary tick of a per-tick table (tick == next_tick < stage_end): the law, the
 * classification of a non-finite command (before u is written: x and u may overlap), the
 * command, and the tick. Inlined into stsp_step(), except in the float32 build with run-time
 * dimensions (STSP_ROW_CACHE): there the law runs on the rows the instance keeps for
 * next_tick, which move on to the next tick's only when the step succeeds (a non-finite
 * command leaves the instance unchanged), and the function is tail-called (stsp_step() then
 * needs no frame). */
#if STSP_ROW_CACHE
#define STSP_ORDINARY_TICK STSP_NOINLINE
#else
#define STSP_ORDINARY_TICK STSP_ALWAYS_INLINE
#endif
static STSP_ORDINARY_TICK stsp_status_t stsp_step_ordinary(stsp_ctrl_t *ctrl, uint32_t now,
                                                           const stsp_scalar_t *x,
                                                           stsp_scalar_t *u)
{
    stsp_scalar_t y[STSP_MAX_NU];
    uint32_t out;
    uint32_t tick;
#if STSP_ROW_CACHE
    stsp_rows_t rows = ctrl->rows;
    (void)now;
    out = stsp_law_kept(&ctrl->checked, &rows, x, ctrl->v, y, ctrl->limited);
    tick = ctrl->next_tick; /* == now, read after the law: one register fewer across it */
#else
    tick = now;
    out = stsp_law(&ctrl->checked, tick, x, ctrl->v, y, ctrl->limited);
#endif
#ifndef STSP_ARITH_FIXED_POINT
    /* A NaN/Inf command: which error it is depends on x, read before u is written. */
    if ((out != 0u) && (stsp_command_finite(&ctrl->checked, y) == 0)) {
        return stsp_step_nonfinite(ctrl, x, u);
    }
#endif
#if STSP_ROW_CACHE
    ctrl->rows = rows;
#endif
    stsp_copy_command(u, y, stsp_nu(&ctrl->checked));
    if (out != 0u) {
        return stsp_step_fixup(ctrl, tick, u);
    }
    ctrl->next_tick = tick + 1u;
    return STSP_OK;
}

#if !STSP_ROW_CACHE
/* A spline table's tick (stsp_spline.c, through the table's ops, which init checked), from
 * stsp_step(). A call, not a tail call: stsp_step() then has a call and saves lr in its
 * prologue, and its ordinary tick returns with one pop {..., pc} instead of pop and bx lr (one
 * instruction less on the Cortex-M4F ordinary tick of the STSP_FIXED_* and Q15/Q31 builds). */
static STSP_ALWAYS_INLINE stsp_status_t stsp_step_spline(stsp_ctrl_t *ctrl, uint32_t tick,
                                                         const stsp_scalar_t *x,
                                                         stsp_scalar_t *u)
{
    const stsp_status_t status = ctrl->checked.sp.ops->step(ctrl, tick, x, u);
    STSP_NO_TAIL_CALL();
    return status;
}
#endif

#if STSP_ROW_CACHE
/* Every tick but the ordinary one of a per-tick table: a spline table's (stsp_spline.c, through
 * the table's ops, which init checked), or the cold path. Out of line, so that stsp_step()
 * tail-calls everything and needs no frame. */
static STSP_NOINLINE stsp_status_t stsp_step_other(stsp_ctrl_t *ctrl, uint32_t tick,
                                                   const stsp_f32_t *x, stsp_f32_t *u)
{
    if (ctrl->checked.spline != NULL) {
        return ctrl->checked.sp.ops->step(ctrl, tick, x, u);
    }
    return stsp_step_cold(ctrl, tick, x, u);
}
#endif

stsp_status_t stsp_step(stsp_ctrl_t *ctrl, uint32_t tick, const stsp_scalar_t *x,
                        stsp_scalar_t *u)
{
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
     * of a spline table (stage_end 0) its own, stsp_spline_ops.step. */
    if ((tick != ctrl->next_tick) || (tick >= ctrl->stage_end)) {
#if STSP_ROW_CACHE
        return stsp_step_other(ctrl, tick, x, u);
#else
        if (ctrl->checked.spline != NULL) {
            return stsp_step_spline(ctrl, tick, x, u);
        }
        return stsp_step_cold(ctrl, tick, x, u);
#endif
    }
    return stsp_step_ordinary(ctrl, tick, x, u);
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
