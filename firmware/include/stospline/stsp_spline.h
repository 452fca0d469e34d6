/**
 * @file stsp_spline.h
 * @brief Evaluation of spline gains (stsp_table_t.spline): the order every build follows, and
 *        the code a spline table links.
 *
 * Spline tables (stsp_spline_t), binary32, every operation rounded, no fused multiply-add: at
 * tick j of stage s, tau = (float)(j - stage_start[s]) (exact) and U the stage's knots, the span
 * sigma with U[sigma+3] <= tau < U[sigma+4] and i = sigma + 3 give the basis (The NURBS Book,
 * A2.2): left[k] = tau - U[i+1-k], right[k] = U[i+k] - tau (k = 1..3), N[0] = 1, and for
 * k = 1..3: saved = 0; for r = 0..k-1: temp = N[r] / (right[r+1] + left[k-r]),
 * N[r] = saved + right[r+1] temp, saved = left[k-r] temp; then N[k] = saved. Each stored entry
 * (coefficients c) has the gain g = ((N[0] c[sigma] + N[1] c[sigma+1]) + N[2] c[sigma+2]) +
 * N[3] c[sigma+3], and for each input i
 *     u[i] = (((+0 - g_1 z[col_1]) - g_2 z[col_2]) - ...)   over the entries of (s, i) in order,
 * with z = [x, 1, v]; then the limit and finiteness checks and the clamp of the per-tick law.
 * On the M4F each step is one VMLA.F32 or VMLS.F32 (chained, as above).
 *
 * Fixed-point spline tables (stsp_qspline_t, Q15/Q31), integers only: at tick j of stage s,
 * tau = j - stage_start[s], k = span_log2[s], sigma = tau >> k, d = tau & (2^k - 1), the basis
 * numerators P0..P3 of stsp_qspline_t, and each stored entry e of (s, i) the gain
 * g_e = floor((c[sigma] P0 + c[sigma+1] P1 + c[sigma+2] P2 + c[sigma+3] P3) / 2^(3k + s_e)
 * + 1/2), exact; then for each input i, over its entries in order, with z = [x_q, 0, v_q]:
 *     acc = 2^(2F) + 2^(F-1) + sum_e g_e z[col_e],   u_q[i] = (acc >> F) - 2^F + g_k0
 * (g_k0 the gain of col nx, k0[i], 0 if not stored): the per-tick fixed-point law (see
 * stsp_step) with the gains as evaluated, bit for bit (every sum exact: any order gives the
 * same bits). Then the clamp. Every tick goes through the cold path's plan and commit (range,
 * order, stage, latch); its cost is the stage's entries times one 4-term evaluation, the same
 * at every tick of a stage.
 */
#ifndef STSP_SPLINE_H
#define STSP_SPLINE_H

#include "stospline/stsp_table.h"

#ifdef __cplusplus
extern "C" {
#endif

struct stsp_ctrl;   /* stsp_ctrl_t, stsp_controller.h */
struct stsp_header; /* stsp_header_t, stsp_private.h (not API) */

/**
 * The code of a spline table in the build's arithmetic (firmware/src/stsp_spline.c): its layout
 * and value checks for stsp_init(), its part of the CRC-32, and its every tick. A spline table
 * points to stsp_spline_ops (stsp_spline_t.ops, stsp_qspline_t.ops; the generated C does), and
 * the controller reaches that code only through the pointer: a program links it only with a
 * spline table. stsp_init() refuses a spline table whose ops is NULL or of another arithmetic
 * (STSP_ERR_BAD_DIMS). Private members: only the controller calls them.
 */
struct stsp_spline_ops_s {
    uint32_t scalar_kind; /**< STSP_SCALAR_KIND of the code */
    /** init: the layout of the validated header copy's spline */
    stsp_status_t (*check_dims)(const struct stsp_header *h);
    /** init, after the CRC: the gains as evaluated (fixed point; NULL: nothing to check) */
    stsp_status_t (*check_values)(const struct stsp_header *h);
    /** stsp_table_crc32(): the spline part of the serialization */
    uint32_t (*crc)(uint32_t crc, const stsp_spline_gains_t *sp, uint32_t n_stages, uint32_t nu);
    /** stsp_step() of a spline table, after its argument and ready checks */
    stsp_status_t (*step)(struct stsp_ctrl *ctrl, uint32_t tick, const stsp_scalar_t *x,
                          stsp_scalar_t *u);
    /** stsp_param_step() of a spline table with spline columns (stsp_params.h, format 2):
     *  the unclamped command y[nu] at `tick` of stage s of ctrl's table from x, the latch v
     *  and d[n_params], the columns cols[n_cols] (float32 B-spline columns, or Q15/Q31 blocks of scale
     *  and coefficients).
     *  kept nonzero: v holds ctrl->v and d the parameters in use, so ctrl->span may serve as
     *  the span cache (read, and rewritten on a span change); 0 (a fresh latch): not touched.
     *  Fixed point keeps no span cache and ignores kept */
    void (*param_law)(struct stsp_ctrl *ctrl, uint32_t s, uint32_t tick,
                      const stsp_scalar_t *x, const stsp_scalar_t *v, const stsp_scalar_t *cols,
                      uint32_t n_cols, const stsp_scalar_t *d, uint32_t n_params,
                      uint32_t kept, stsp_scalar_t *y);
};

/** The spline code of the build's arithmetic (stsp_spline_ops_f32, _q15 or _q31). */
#define stsp_spline_ops STSP_NAME(stsp_spline_ops)
extern const stsp_spline_ops_t stsp_spline_ops;

#ifdef __cplusplus
}
#endif

#endif /* STSP_SPLINE_H */
