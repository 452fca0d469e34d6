/* Fixed-point (Q15/Q31) spline gains: the evaluation of issue 13's compressed format in the
 * fixed-point builds (host: stospline/table/qspline.py, whose evaluate_q it reproduces bit for
 * bit). Private: not installed. stsp_init() does not take such a table yet: this is the
 * per-tick evaluation the controller will call, tested on its own (tests/c/test_qspline.c,
 * tests/python/table/test_qspline_c.py).
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

#ifdef STSP_ARITH_FIXED_POINT

#define STSP_QSPLINE_MAX_SPAN_LOG2 9u
#define STSP_QSPLINE_MAX_SHIFT 30u

/* The arrays of stospline.table.qspline.QSplineGains, concatenated over the stages:
 *   span_log2[s]: k of stage s;
 *   col[row_start[s*nu + i] .. row_start[s*nu + i + 1]): stage s, input i's stored entries,
 *     each the index of its operand in z = [x, 1, v] (increasing);
 *   shift[e]: entry e's s_e, in [1, STSP_QSPLINE_MAX_SHIFT];
 *   coef[coef_start[s] .. coef_start[s+1]): (S + 3) integers per entry, entry after entry. */
typedef struct {
    uint32_t n_entries;          /* length of col and shift */
    uint32_t n_coef;             /* length of coef */
    const uint8_t *span_log2;    /* [n_stages] */
    const uint16_t *row_start;   /* [n_stages * nu + 1] */
    const uint8_t *col;          /* [n_entries] */
    const uint8_t *shift;        /* [n_entries] */
    const uint32_t *coef_start;  /* [n_stages + 1] */
    const stsp_scalar_t *coef;   /* [n_coef] */
} stsp_qspline_t;

/* sigma of tick tau in a stage of spans 2^k, and P[0..3] (k <= 9). */
uint32_t stsp_qspline_basis(uint32_t k, uint32_t tau, uint32_t *p);

/* One gain from its four coefficients of the span c[0..3] and P[0..3], sh = 3k + s_e in
 * [1, 57]: the exact rounded value (at most 3 2^31 in magnitude). It fits stsp_scalar_t when
 * the table's rows sum to at most 2^F - 1 in magnitude, as every valid table's do (the host
 * checks it; stsp_init() will, once it takes these tables). */
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

#endif /* STSP_ARITH_FIXED_POINT */
#endif /* STSP_QSPLINE_H */
