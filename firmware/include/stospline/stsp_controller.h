/**
 * @file stsp_controller.h
 * @brief Latched time-varying affine controller evaluated from const gain tables.
 *
 * The whole flashable API. Does not use malloc, recursion or VLAs; every loop is bounded by
 * the table's dimensions, which stsp_init() checks against the STSP_MAX_* limits below. No
 * static or global mutable data: every function is re-entrant, and any number of instances
 * may run at once (one instance must not be stepped from two contexts at the same time).
 *
 * Law, at tick j of stage s (time t0 + j / tick_hz):
 *
 *     at the stage's first tick, if stage_n_latch[s] > 0:
 *                                 v = Lambda[s] x + lambda0[s]          (latch)
 *       or, at stage 0 of a table with band_qp (band constraints lo <= E{C2 x(t_k)} <= hi):
 *                                 v = argmax of the band dual at x      (stsp_bandqp.h)
 *     every tick:                 u = sat(-K[j] x - k0[j] - L[j] v)
 *
 * where sat() clamps input i to [u_min[i], u_max[i]] (STSP_WARN_SATURATED says it did). A
 * spline table (stsp_spline_t in float32 builds, stsp_qspline_t in Q15/Q31 builds) has the
 * same law with K[j], k0[j], L[j] the stage's cubic B-splines evaluated at tick j (the order
 * below).
 * Stage-wise designs latch at every constrained stage; joint designs latch once, at stage 0
 * (stage_n_latch[s] = 0 afterwards keeps v). Entries of v beyond stage_n_latch[s] are set to zero.
 * The caller holds u until the next tick (zero-order hold).
 *
 * Evaluation order (fixed: the QEMU replay test checks the Cortex-M builds against the host
 * build bit for bit): for each input i,
 *     u[i] = ((((-(K[i][0] x[0])) - k0[i]) - K[i][1] x[1]) - ... - K[i][nx-1] x[nx-1])
 *            - L[i][0] v[0] - ... - L[i][n_latch-1] v[n_latch-1]
 * over all n_latch columns (zero padded, so every tick costs the same), binary32 throughout,
 * no fused multiply-add (compile with -ffp-contract=off). This is -(k0 + K x + L v) summed
 * left to right, exactly (IEEE rounding is sign-symmetric), up to the sign of a zero result.
 * On a single-precision VFP (Cortex-M4F) each step is one VNMLA.F32 (the first two terms) or
 * VMLS.F32: chained, not fused (the product is rounded, then the difference), so the same
 * operations in the same order; define STSP_NO_VFP_MAC for separate VMUL and VSUB.
 *
 * Spline gains (stsp_table_t.spline) are evaluated as stsp_spline.h describes.
 *
 * Buffers: stsp_ctrl_t holds STSP_MAX_LATCH scalars for v, STSP_MAX_NU for the copy of
 * u_hold, 24 bytes of state, the validated copy of the table header (stsp_header_t) and, in
 * float32 builds, a spline table's current span (stsp_span_t); on 32-bit targets 692 bytes
 * with the default STSP_MAX_LATCH = STSP_MAX_NU = 16 (float32), 188 (Q15), 252 (Q31)
 * (arm-none-eabi-gcc -mcpu=cortex-m4, sizeof(stsp_ctrl_t)).
 * stsp_step() uses STSP_MAX_LATCH + STSP_MAX_NU scalars of stack (a spline table: also
 * z = [x, 1, v], STSP_MAX_NX + 1 + STSP_MAX_LATCH scalars), plus, on the stage-0 latch of a
 * band table only, the band solver's work area and multipliers (sizeof(stsp_bandqp_work_t) +
 * STSP_BANDQP_MAX doubles, about 0.8 KB with STSP_BANDQP_MAX = 8; docs/guide/firmware.md). The
 * tables stay where the caller put them (const, normally flash) and are never copied; their
 * header (dimensions, array addresses) is: after stsp_init() every call works from the
 * instance's copy, so a header changed later cannot move an access outside the arrays init
 * checked (stsp_verify() reports the change).
 *
 * Compile-time dimensions (optional): define STSP_FIXED_NX, STSP_FIXED_NU and
 * STSP_FIXED_N_LATCH (all three, for the library and every file that includes this header)
 * to build a controller for one table shape. The loops then have constant bounds and the
 * compiler unrolls them (the Cortex-M4F figures in docs/guide/firmware.md); stsp_init() refuses a
 * table of any other shape with STSP_ERR_BAD_DIMS. The arithmetic is the same operation for
 * operation, so both builds give bit-identical commands.
 *
 * Headers, by job: stsp_types.h (scalar types, the arithmetic, limits, status codes),
 * stsp_table.h (table formats, CRC-32), stsp_spline.h (spline evaluation), stsp_bandqp.h (the
 * band dual), this file (the controller API); stsp_private.h is the controller's private
 * layout, not API.
 */
#ifndef STSP_CONTROLLER_H
#define STSP_CONTROLLER_H

#include "stospline/stsp_types.h"
#include "stospline/stsp_table.h"
#include "stospline/stsp_spline.h"
#include "stospline/stsp_private.h"

#ifdef __cplusplus
extern "C" {
#endif

/* The API's symbols carry the arithmetic (STSP_NAME, stsp_types.h): stsp_init is stsp_init_f32,
 * stsp_init_q15 or stsp_init_q31, and so on. */
#define stsp_init STSP_NAME(stsp_init)
#define stsp_init_expect STSP_NAME(stsp_init_expect)
#define stsp_init_problem STSP_NAME(stsp_init_problem)
#define stsp_reset STSP_NAME(stsp_reset)
#define stsp_verify STSP_NAME(stsp_verify)
#define stsp_step STSP_NAME(stsp_step)
#define stsp_state_to_q STSP_NAME(stsp_state_to_q)
#define stsp_command_to_f32 STSP_NAME(stsp_command_to_f32)
#define stsp_status_str STSP_NAME(stsp_status_str)

/**
 * One controller instance; caller-owned (stack, static or a struct of the application).
 * Read-only for the caller: `sat_mask`, `stage`, `next_tick`, `latched`; the rest is private.
 */
typedef struct stsp_ctrl {
    const stsp_table_t *table;
    uint32_t ready;          /**< a magic value after a successful init (private) */
    uint32_t next_tick;      /**< tick expected at the next step */
    uint32_t stage_end;      /**< first tick after `stage` once latched, else 0; always 0
                                  for a spline table (private) */
    uint16_t stage;          /**< stage of the last successful step */
    uint16_t latched;        /**< nonzero once v holds a latch for `stage` */
    uint16_t sat_mask;       /**< after STSP_WARN_SATURATED: bit i set if u[i] was clamped
                                  (not updated by other statuses) */
    uint16_t limited;        /**< nonzero if the table has a finite limit (private) */
    stsp_scalar_t v[STSP_MAX_LATCH];
    stsp_header_t checked;   /**< the validated table header (private) */
    stsp_scalar_t hold[STSP_MAX_NU]; /**< the table's u_hold, copied at init (private): a
                                          refused step writes it even if the table changed;
                                          after the fields the ordinary tick reads, so their
                                          offsets are unchanged */
#ifndef STSP_ARITH_FIXED_POINT
    stsp_span_t span;        /**< a spline table's current span (private) */
#endif
#if !defined(STSP_ARITH_FIXED_POINT) && !defined(STSP_FIXED_NX)
    stsp_rows_t rows;        /**< the rows of tick next_tick (private; generic float32) */
#endif
} stsp_ctrl_t;

/**
 * Bind a table to an instance after verifying its header, dimensions, CRC and values; the
 * instance keeps a copy of the validated header (stsp_header_t) and works from it from then on.
 * Precondition (as for stsp_table_crc32()): each array is as long as the header says.
 * On any error the instance is left not ready (every step returns STSP_ERR_NOT_INITIALIZED).
 * Cost: one pass over every table entry for the CRC and one for the finiteness check.
 */
stsp_status_t stsp_init(stsp_ctrl_t *ctrl, const stsp_table_t *table);

/**
 * stsp_init(), and STSP_ERR_BAD_DIMS (instance not ready) unless the table has exactly nx
 * states and nu inputs: the lengths of the caller's x and u buffers. Refuses a table flashed
 * for another plant before it can index past those buffers.
 */
stsp_status_t stsp_init_expect(stsp_ctrl_t *ctrl, const stsp_table_t *table, uint32_t nx,
                               uint32_t nu);

/**
 * stsp_init_expect(), and STSP_ERR_BAD_PROBLEM (instance not ready) unless the table was made
 * from the problem file with SHA-256 `problem_sha256` (32 bytes; the generated header's
 * <NAME>_PROBLEM_SHA256 initializer): refuses tables flashed from another version of the
 * problem. The CRC-32 covers the stored hash, so a corrupted hash is STSP_ERR_BAD_CRC.
 */
stsp_status_t stsp_init_problem(stsp_ctrl_t *ctrl, const stsp_table_t *table, uint32_t nx,
                                uint32_t nu, const uint8_t *problem_sha256);

/** Restart the plan at tick 0 (the next step latches stage 0 again). */
stsp_status_t stsp_reset(stsp_ctrl_t *ctrl);

/**
 * Check that the bound table is still the one stsp_init() validated (e.g. from a background
 * task, to detect flash or RAM that changed after init). First the header: magic, version and
 * scalar kind, every dimension and array address, and the band dual's header, against the
 * instance's copy: a difference is STSP_ERR_TABLE_CHANGED, and no array is read through the
 * changed header. Then the CRC-32, recomputed over the arrays init validated (and tick_hz,
 * problem_sha256 and the crc32 field of the header): a difference is STSP_ERR_BAD_CRC. Either
 * error stops the instance: every later stsp_step() returns STSP_ERR_NOT_INITIALIZED with u
 * the safe command u_hold as init copied it (written to the validated u[nu]), reset and verify return
 * STSP_ERR_NOT_INITIALIZED, until a new init.
 */
stsp_status_t stsp_verify(stsp_ctrl_t *ctrl);

/**
 * Compute the command for tick `tick` from the measured state x[nx]; writes u[nu].
 * On a negative status u is the table's safe command u_hold (copied at init) and the instance
 * is unchanged; otherwise u is finite and u_min[i] <= u[i] <= u_max[i]. Exceptions: with
 * u == NULL nothing is written, and before a successful init (STSP_ERR_NOT_INITIALIZED) u is
 * not written because nu is unknown (after stsp_verify() stopped the instance it is u_hold).
 * nx and nu are the dimensions init validated, whatever the table header says later.
 * x and u may be the same buffer or overlap: every read of x happens before the first write
 * of u, so the status and the command are those of separate buffers (the overlapping entries
 * of x then hold the command). u must not overlap the instance or the table.
 * See docs/guide/firmware.md for every status's response.
 */
stsp_status_t stsp_step(stsp_ctrl_t *ctrl, uint32_t tick, const stsp_scalar_t *x,
                        stsp_scalar_t *u);

#ifdef STSP_ARITH_FIXED_POINT
/*
 * Fixed point, per tick (integers only, no floating point; F = STSP_Q_FRAC_BITS): for each
 * input i, with the accumulator stsp_acc (int32 for Q15, int64 for Q31),
 *     acc  = 2^(2F) + 2^(F-1) + k0[i] 2^F + sum_j K[i][j] x_q[j] + sum_c L[i][c] v_q[c]
 *     u_q[i] = (acc >> F) - 2^F   = floor((sum + 2^(F-1)) / 2^F): rounded half up
 * and the latch v_q[c] the same way from lambda0 and Lambda. No overflow, no saturation of u_q
 * or v_q: stsp_init() accepts a table only if every row has |k0| + sum|K| + sum|L| <= 2^F - 1
 * (and |lambda0| + sum|Lambda| <= 2^F - 1), so with |x_q|, |v_q| <= 2^F the sum stays within
 * +-(2^F - 1) 2^F, acc within [0, 2^(2F+1)) (Q15: < 2^31, Q31: < 2^63), and u_q, v_q within
 * +-(2^F - 1). Then u_q is clamped to [u_min, u_max] (STSP_WARN_SATURATED, sat_mask). Every
 * x_q is a valid state: the representable range is the table's (x_exp); a state beyond it must
 * be saturated when it is converted, which stsp_state_to_q() does and reports.
 */

/**
 * Convert a float32 state to the table's Q format (for FPU targets; stsp_step() itself needs
 * no floating point): x_q[j] = sat(floor(x[j] 2^(F - x_exp[j]) + 1/2)), saturated to
 * [-2^F, 2^F - 1]. Returns STSP_OK, STSP_WARN_STATE_CLAMPED if some x[j] was outside the Q
 * range (those x_q[j] are -2^F or 2^F - 1, the others converted), STSP_ERR_NONFINITE_STATE if
 * some x[j] is NaN or +-Inf (x_q all zeros), STSP_ERR_NULL, STSP_ERR_NOT_INITIALIZED (x_q not
 * written).
 */
stsp_status_t stsp_state_to_q(const stsp_ctrl_t *ctrl, const stsp_f32_t *x, stsp_scalar_t *x_q);

/**
 * Convert a Q command to float32: u[i] = u_q[i] 2^(u_exp[i] - F) (exact for Q15; Q31 rounds
 * to nearest binary32). Returns STSP_OK, STSP_ERR_NULL or STSP_ERR_NOT_INITIALIZED.
 */
stsp_status_t stsp_command_to_f32(const stsp_ctrl_t *ctrl, const stsp_scalar_t *u_q,
                                  stsp_f32_t *u);
#endif

#ifdef STSP_HOST_MESSAGES
/** Human-readable text of a status (host builds only). */
const char *stsp_status_str(stsp_status_t status);
#endif

#ifdef __cplusplus
}
#endif

#endif /* STSP_CONTROLLER_H */
