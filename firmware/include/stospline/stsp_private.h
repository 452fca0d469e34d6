/**
 * @file stsp_private.h
 * @brief Not API: the layout of the controller's private state.
 *
 * Installed only so that callers can allocate stsp_ctrl_t (stsp_controller.h), which holds these
 * structs by value; the controller alone reads or writes them, and their members change
 * without notice.
 */
#ifndef STSP_PRIVATE_H
#define STSP_PRIVATE_H

#include "stospline/stsp_table.h"

#ifdef __cplusplus
extern "C" {
#endif

/**
 * Private to the controller: the table header as stsp_init() validated it. stsp_step(),
 * stsp_reset() and the conversions use only this copy, never the header again: every loop
 * bound and index comes from here, so a header changed after init (or a band dual's header)
 * cannot move an access outside the arrays init checked. stsp_verify() compares the header
 * with it before it reads any array.
 */
typedef struct stsp_header {
    const stsp_scalar_t *K;
    const stsp_scalar_t *k0;
    const stsp_scalar_t *L;
    const stsp_scalar_t *u_min;
    const stsp_scalar_t *u_max;
    const stsp_scalar_t *Lambda;
    const stsp_scalar_t *lambda0;
    const uint32_t *stage_start;
    const uint16_t *stage_n_latch;
#ifdef STSP_ARITH_FIXED_POINT
    const int8_t *x_exp;
    const int8_t *u_exp;
    const int8_t *v_exp;
#else
    const stsp_bandqp_t *band_qp; /**< the table's pointer (NULL: no band dual) */
    stsp_bandqp_t band;           /**< copy of *band_qp (all zero without one) */
#endif
    uint32_t n_ticks;
    uint16_t nx;
    uint16_t nu;
    uint16_t n_latch;
    uint16_t n_stages;
    const stsp_scalar_t *u_hold; /* last: the ordinary tick's offsets stay as they were */
    const stsp_spline_gains_t *spline; /**< the table's pointer (NULL: gains per tick) */
    stsp_spline_gains_t sp;       /**< copy of *spline (all zero without one) */
    /** sp.ops->step once init accepted a spline table, else NULL: the tick's one load and
        test before the call (stsp_step) */
    stsp_status_t (*spline_step)(struct stsp_ctrl *ctrl, uint32_t tick, const stsp_scalar_t *x,
                                 stsp_scalar_t *u);
} stsp_header_t;

#ifndef STSP_ARITH_FIXED_POINT
/**
 * Private to the controller: where a spline table's last successful step was, set on the cold
 * path (stage change, span change, skip) and read by the ordinary tick. Every pointer and count
 * was bounded by the validated array lengths when it was set.
 */
typedef struct {
    const stsp_f32_t *knot;  /**< U[sigma + 1], the first of the six knots of the span's basis */
    stsp_f32_t inv;          /**< 1 / (U[sigma + 4] - U[sigma + 3]): the basis's first quotient */
    const stsp_f32_t *coef;  /**< coefficient sigma of the stage's first entry (the stage's
                                  first coefficient when it has no entries) */
    const uint8_t *col;      /**< the stage's first entry */
    uint32_t first;          /**< the stage's first tick */
    uint32_t next;           /**< first tick after the span (0: no span yet) */
    uint32_t stride;         /**< coefficients per entry, S + 3 */
    uint32_t span;           /**< sigma */
    uint32_t n_spans;        /**< S */
    uint16_t row_end[STSP_MAX_NU]; /**< input i's entries end at row_end[i] (from col) */
    uint16_t k_end[STSP_MAX_NU];   /**< and its gains of x (col < nx, its first entries) at
                                        k_end[i] */
    uint32_t x_mask[STSP_MAX_NU];  /**< bit j set: input i has a gain of x[j] */
    stsp_f32_t fold[4u * STSP_MAX_NU]; /**< input i's k0[i] + L[i] v as one spline, negated:
                                            the span's four coefficients at fold[4 i] */
} stsp_span_t;
#endif

#if !defined(STSP_ARITH_FIXED_POINT) && !defined(STSP_FIXED_NX)
/**
 * Private to the controller (float32, generic dimensions): where the rows of K, k0 and L of
 * tick `next_tick` start, so that an ordinary tick reads them instead of multiplying its tick
 * index by the row lengths. Derived from the validated header copy (stsp_header_t) at init,
 * reset and every successful cold tick (stage change, latch, skip, repeat), and advanced by
 * one tick's rows (nu nx, nu, nu n_latch entries: where the law's last row ends) by each
 * successful ordinary tick; a refused step leaves them as they were. An ordinary tick
 * (tick == next_tick < stage_end <= n_ticks) is the only reader, so they always point at rows
 * inside the arrays init checked (at most one past the end, never read, after the table's
 * last tick). L is the table's L (NULL allowed) when n_latch == 0.
 */
typedef struct {
    const stsp_f32_t *K;
    const stsp_f32_t *k0;
    const stsp_f32_t *L;
} stsp_rows_t;
#endif

#ifdef __cplusplus
}
#endif

#endif /* STSP_PRIVATE_H */
