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

/**
 * Defined by the spline tables' code (firmware/src/stsp_spline.c, in every arithmetic: the
 * float32 or the fixed-point spline tick; value STSP_FORMAT_VERSION),
 * which a program links only when something refers to it strongly: a generated spline table
 * does (`<name>_spline_code`, a pointer to this). The controller refers to that code only
 * weakly (GCC or clang, ELF), so that programs with per-tick tables do not carry it; without
 * it stsp_init() refuses a spline table with STSP_ERR_BAD_DIMS. A hand-made spline table must
 * refer to it too (or link with -Wl,--undefined=stsp_spline_code).
 */
extern const uint32_t stsp_spline_code;

#ifdef __cplusplus
}
#endif

#endif /* STSP_SPLINE_H */
