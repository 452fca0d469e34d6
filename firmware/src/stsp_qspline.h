/* Fixed-point (Q15/Q31) spline gains: the evaluation of the compressed format in the
 * fixed-point builds (host: stospline/table/spline/fixed_point.py, whose evaluate_q it reproduces bit for
 * bit). Private: not installed. The per-tick evaluation, tested on its own
 * (tests/c/test_qspline.c, tests/python/table/test_qspline_c.py); the controller's Q spline
 * tick (stsp_spline.c) uses stsp_qspline_basis and stsp_qspline_narrow below.
 *
 * Per stage s of T_s ticks, spans of D = 2^k ticks (k = span_log2[s] <= 9), S = ceil(T_s / D)
 * spans, S + 3 coefficients per stored entry. At tick tau of the stage, sigma = tau >> k,
 * d = tau & (D - 1):
 *     P0 = (D - d)^3, P1 = 4 D^3 - 3 d^2 (2 D - d), P3 = d^3, P2 = 6 D^3 - P0 - P1 - P3
 * (uint32, exact: each <= 4 D^3 <= 2^29), and the gain of entry e
 *     g = floor((c[sigma] P0 + c[sigma+1] P1 + c[sigma+2] P2 + c[sigma+3] P3) / 2^(3k + s_e)
 *               + 1/2)
 * exactly (the sum in int64: at most 6 D^3 2^31 < 2^61 in magnitude), the stored gain of the
 * per-tick format (negated, scaled: stsp_table_t). No rounding but the last: any order of the
 * sum gives the same bits. */
#ifndef STSP_QSPLINE_H
#define STSP_QSPLINE_H

#include "stsp_internal.h"

/* Named per arithmetic (STSP_NAME), as every external symbol of the controller. */
#define stsp_qspline_basis STSP_NAME(stsp_qspline_basis)
#define stsp_qspline_value STSP_NAME(stsp_qspline_value)
#define stsp_qspline_check STSP_NAME(stsp_qspline_check)
#define stsp_qspline_gains STSP_NAME(stsp_qspline_gains)
#define stsp_qspline_col_start STSP_NAME(stsp_qspline_col_start)
#define stsp_qspline_rows_check STSP_NAME(stsp_qspline_rows_check)

#ifdef STSP_ARITH_FIXED_POINT

#define STSP_QSPLINE_MAX_SPAN_LOG2 9u
#define STSP_QSPLINE_MAX_SHIFT 30u

/* stsp_qspline_t (the arrays of stospline.table.spline.fixed_point.QSplineGains) is public: a Q15/Q31
 * table's spline member (stospline/stsp_controller.h). */

/* sigma of tick tau in a stage of spans 2^k, and P[0..3] (k <= 9). */
uint32_t stsp_qspline_basis(uint32_t k, uint32_t tau, uint32_t *p);

/* The gain biased by 2^(62 - sh): floor(acc / 2^sh + 1/2) + 2^(62 - sh), with acc the exact
 * sum. No signed shift: acc + 2^62 is in (0, 2^63) as |acc| < 2^61 (the unsigned sum wraps to
 * exactly that); floor((a + 2^(sh-1)) / 2^sh) = floor((floor(a / 2^(sh-1)) + 1) / 2) for
 * a >= 0, one variable shift; and 2^62 / 2^sh is an integer (sh <= 57). The shift count is
 * taken modulo 64: the same for sh in [1, 57], and for any other sh (a scale changed after
 * init, which the controller's tick reads unchecked) a wrong value but no undefined shift. */
static inline uint64_t stsp_qspline_biased(const stsp_scalar_t *c, const uint32_t *p,
                                           uint32_t sh)
{
    /* p[r] <= 2^29: an int32, so each product is one 32 x 32 -> 64 multiply */
    const int64_t t0 = (int64_t)c[0] * (int64_t)(int32_t)p[0];
    const int64_t t1 = (int64_t)c[1] * (int64_t)(int32_t)p[1];
    const int64_t t2 = (int64_t)c[2] * (int64_t)(int32_t)p[2];
    const int64_t t3 = (int64_t)c[3] * (int64_t)(int32_t)p[3];
    const int64_t acc = ((t0 + t1) + t2) + t3;
    const uint64_t lifted = (uint64_t)acc + ((uint64_t)1u << 62u);
    const uint32_t down = (sh - 1u) & 63u;
    const uint64_t halves = lifted >> down;
    const uint64_t up = halves + 1u;
    return up >> 1u;
}

/* stsp_qspline_value's low 32 bits, as a stsp_scalar_t: the value itself when it fits (the
 * table's row sums ensure it), from 32-bit arithmetic for the bias. */
static inline stsp_scalar_t stsp_qspline_narrow(const stsp_scalar_t *c, const uint32_t *p,
                                                uint32_t sh)
{
    const uint64_t biased = stsp_qspline_biased(c, p, sh);
    const uint32_t bias_bit = 62u - sh;
    const uint32_t bias = (bias_bit < 32u) ? ((uint32_t)1u << bias_bit) : 0u;
    const uint32_t low = (uint32_t)biased;
    const uint32_t value = low - bias;
    return (stsp_scalar_t)(int32_t)value;
}

/* One gain from its four coefficients of the span c[0..3] and P[0..3], sh = 3k + s_e in
 * [1, 57]: the exact rounded value (at most 3 2^31 in magnitude). It fits stsp_scalar_t when
 * the table's rows sum to at most 2^F - 1 in magnitude, as every valid table's do (the host
 * checks it, and stsp_init() at every tick). */
int64_t stsp_qspline_value(const stsp_scalar_t *c, const uint32_t *p, uint32_t sh);

/* 0 (STSP_OK) when the layout of `sp` for n_stages stages (first ticks stage_start[0..
 * n_stages]), nu inputs and nz = nx + 1 + n_latch operands is the format's: span_log2 <= 9,
 * shifts in [1, 30], the index arrays from 0 to n_entries and n_coef and nondecreasing, the
 * columns below nz and increasing in each row, (S + 3) coefficients per entry of each stage;
 * else STSP_ERR_NULL or STSP_ERR_BAD_DIMS. */
stsp_status_t stsp_qspline_check(const stsp_qspline_t *sp, const uint32_t *stage_start,
                                 uint32_t n_stages, uint32_t nu, uint32_t nz);

/* Every gain of stage s at its tick tau (< its T ticks) into g[i * nz + col] (the row of
 * input i over z = [x, 1, v]); the entries not stored are 0. `sp` passed stsp_qspline_check.
 * Time: the same for every tick of a stage (4 multiply-accumulates per stored entry). */
void stsp_qspline_gains(const stsp_qspline_t *sp, const uint32_t *stage_start, uint32_t s,
                        uint32_t nu, uint32_t nz, uint32_t tau, stsp_scalar_t *g);

/* Spline columns of a parameter table (stsp_params.h, format 2 in a Q15/Q31 build; host
 * stospline/table/spline/qparams.py): per stage s, input i and parameter p, one block of
 * S_s + 4 words, the column's scale s_c (1..30) then its S_s + 3 coefficients, on the gain
 * spline's spans; the column's gain at tick tau is stsp_qspline_narrow(&block[1 + sigma], P,
 * 3k + s_c), as an entry's. Blocks stage after stage, (i, p) row-major within a stage. */

/* The first word of stage s's blocks, per_stage (S + 4) summed over stages 0 .. s-1 with
 * per_stage = nu n_params; *width = S_s + 4. A span_log2 above 9 (a table changed after init)
 * counts as 9: no undefined shift. In uint64: no wrap for s < 2^16, per_stage <= 2^16. */
uint64_t stsp_qspline_col_start(const stsp_qspline_t *sp, const uint32_t *stage_start,
                                uint32_t s, uint32_t per_stage, uint32_t *width);

/* init, for a spline gain table `sp` that passed stsp_qspline_check: at every tick of every
 * stage every input's law row, the gains as evaluated (exact) with |k0| + sum|K| + sum|L| <=
 * 2^F - 1, the per-tick format's row bound, so that the spline law cannot overflow and every
 * gain fits stsp_scalar_t (stsp_init's value check). With spline columns `cols` (a parameter
 * table's, not NULL): also every block's scale in [1, 30], and each row with its columns,
 * sum_e |g_e| + sum_p |g_p| <= 2^F - 1, so that the parametric law cannot overflow either
 * (the caller checked the blocks' length, stsp_qspline_col_start). STSP_OK, else
 * STSP_ERR_BAD_VALUES. One evaluation per entry, column and tick. */
stsp_status_t stsp_qspline_rows_check(const stsp_qspline_t *sp, const uint32_t *stage_start,
                                      uint32_t n_stages, uint32_t nu,
                                      const stsp_scalar_t *cols, uint32_t n_params);

#endif /* STSP_ARITH_FIXED_POINT */
#endif /* STSP_QSPLINE_H */
