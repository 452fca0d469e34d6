/**
 * @file stsp_types.h
 * @brief Scalar types, the arithmetic of the build, the STSP_MAX_* limits and the status codes.
 *
 * Included by every other stospline header. One arithmetic per translation unit: the
 * arithmetic macros below select stsp_scalar_t and the suffix of every public symbol
 * (STSP_NAME: stsp_init is stsp_init_f32, stsp_init_q15 or stsp_init_q31), so that
 * controllers of several arithmetics link into one program, each used from translation units
 * built for it.
 */
#ifndef STSP_TYPES_H
#define STSP_TYPES_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/** Scalar type of the float32 variant: IEEE-754 binary32. */
typedef float stsp_f32_t;
/** 16-bit fractional data type in 1.15 format: value = q / 2^15, in [-1, 1 - 2^-15]. */
typedef int16_t stsp_q15_t;
/** 32-bit fractional data type in 1.31 format: value = q / 2^31, in [-1, 1 - 2^-31]. */
typedef int32_t stsp_q31_t;

/*
 * Arithmetic variant, chosen at configure time (CMake: -DSTSP_ARITH=float32|q15|q31), by
 * defining STSP_ARITH_Q15 or STSP_ARITH_Q31 (or neither, or STSP_ARITH_FLOAT32: float32) for
 * the library and every file that includes this header. stsp_scalar_t is the type of the
 * state x, the command u, the latched v and every table entry; the fixed-point variants and
 * their scaling are described in docs/guide/firmware.md ("Fixed-point variants") and on
 * stsp_step(). */
#if defined(STSP_ARITH_Q15) && defined(STSP_ARITH_Q31)
#error "define at most one of STSP_ARITH_Q15, STSP_ARITH_Q31"
#endif
/* STSP_ARITH_FLOAT32 (optional; the CMake package and stospline.pc define it for a float32
 * library) states float32 explicitly, so that code built against that library cannot add a
 * fixed-point definition unnoticed. */
#if defined(STSP_ARITH_FLOAT32) && (defined(STSP_ARITH_Q15) || defined(STSP_ARITH_Q31))
#error "STSP_ARITH_FLOAT32 (a float32 library) with STSP_ARITH_Q15/Q31: one arithmetic per build"
#endif
#if defined(STSP_ARITH_Q15)
typedef stsp_q15_t stsp_scalar_t;
#define STSP_ARITH_FIXED_POINT 1
#define STSP_Q_FRAC_BITS 15 /**< F: x = x_q 2^(x_exp - F), u = u_q 2^(u_exp - F) */
#elif defined(STSP_ARITH_Q31)
typedef stsp_q31_t stsp_scalar_t;
#define STSP_ARITH_FIXED_POINT 1
#define STSP_Q_FRAC_BITS 31
#else
typedef stsp_f32_t stsp_scalar_t;
#endif

/* The symbol of `base` in this arithmetic: base_f32, base_q15 or base_q31. Every external
 * symbol of the controller (the API in stsp_controller.h, stsp_table.h and stsp_spline.h, and the
 * private ones between its sources) is named through it, so that the controllers of several
 * arithmetics link into one program. The band solver (stsp_bandqp.h) is float32 code with
 * names of its own. */
#if defined(STSP_ARITH_Q15)
#define STSP_NAME(base) base##_q15
#elif defined(STSP_ARITH_Q31)
#define STSP_NAME(base) base##_q31
#else
#define STSP_NAME(base) base##_f32
#endif

/** Upper bounds checked by stsp_init(); they size stsp_ctrl_t and bound every loop. */
#ifndef STSP_MAX_NX
#define STSP_MAX_NX 32u
#endif
#ifndef STSP_MAX_NU
#define STSP_MAX_NU 16u
#endif
#ifndef STSP_MAX_LATCH
#define STSP_MAX_LATCH 16u
#endif
#ifndef STSP_MAX_STAGES
#define STSP_MAX_STAGES 256u
#endif

#if (STSP_MAX_NU > 16u) || (STSP_MAX_NU < 1u)
#error "STSP_MAX_NU must be 1..16: stsp_ctrl_t.sat_mask has one bit per input"
#endif
#if defined(STSP_FIXED_NX) || defined(STSP_FIXED_NU) || defined(STSP_FIXED_N_LATCH)
#if !defined(STSP_FIXED_NX) || !defined(STSP_FIXED_NU) || !defined(STSP_FIXED_N_LATCH)
#error "define all of STSP_FIXED_NX, STSP_FIXED_NU, STSP_FIXED_N_LATCH, or none"
#endif
#if (STSP_FIXED_NX < 1u) || (STSP_FIXED_NX > STSP_MAX_NX) || (STSP_FIXED_NU < 1u) || \
    (STSP_FIXED_NU > STSP_MAX_NU) || (STSP_FIXED_N_LATCH > STSP_MAX_LATCH)
#error "STSP_FIXED_* dimensions outside the STSP_MAX_* limits"
#endif
#endif

/**
 * Status codes: 0 success, positive = the command is valid (finite, within the limits) but
 * something is worth logging, negative = the command is the table's safe command u_hold
 * (which stsp_init() requires to lie within the limits) and the error says why.
 * When several warnings apply, STSP_WARN_SATURATED wins, then STSP_WARN_BAND_FALLBACK, then
 * the tick warnings (the caller knows which tick it passed, but not what the law did).
 */
typedef enum {
    STSP_OK = 0,
    STSP_WARN_TICK_SKIPPED = 1,     /**< tick > expected; evaluated at the given tick (a stage
                                         entered late latches at that tick) */
    STSP_WARN_TICK_REPEATED = 2,    /**< same tick again; recomputed, no new latch */
    STSP_WARN_SATURATED = 3,        /**< at least one input was clamped to u_min/u_max; which
                                         ones: stsp_ctrl_t.sat_mask */
    STSP_WARN_STATE_CLAMPED = 4,    /**< fixed point, stsp_state_to_q(): a state entry was
                                         outside the Q range and was saturated to its end;
                                         stsp_est_step(): the innovation or the estimate was */
    STSP_WARN_BAND_FALLBACK = 5,    /**< the band dual QP found no optimal active set for this
                                         x0 (W not positive definite in double precision), its
                                         data times x0 overflowed, or a multiplier is beyond
                                         FLT_MAX: latched the design's affine map
                                         Lambda x + lambda0 instead */
    STSP_WARN_NO_MEASUREMENT = 6,   /**< stsp_est_step(): a sampling tick without a reading
                                         (y NULL): the law ran on the prediction */
    STSP_ERR_NULL = -1,             /**< a pointer argument is NULL */
    STSP_ERR_NOT_INITIALIZED = -2,  /**< step/reset before a successful init, or after
                                         stsp_verify() stopped the instance */
    STSP_ERR_BAD_MAGIC = -3,        /**< the table header's magic is wrong */
    STSP_ERR_BAD_VERSION = -4,      /**< table format or scalar variant not supported */
    STSP_ERR_BAD_DIMS = -5,         /**< dimensions zero, above the STSP_MAX_* limits, not the
                                         STSP_FIXED_* ones or the expected ones, the stage
                                         index arrays inconsistent, or a spline table's
                                         layout or knots invalid (stsp_spline_t) */
    STSP_ERR_BAD_CRC = -6,          /**< the tables do not match their CRC-32 */
    STSP_ERR_TICK_RANGE = -7,       /**< tick >= n_ticks: the plan is over */
    STSP_ERR_TICK_ORDER = -8,       /**< tick went backwards by more than one repeat */
    STSP_ERR_NONFINITE_STATE = -9,  /**< x holds NaN or +-Inf */
    STSP_ERR_NONFINITE_OUTPUT = -10,/**< the state is finite but u (or the latch) overflowed */
    STSP_ERR_BAD_VALUES = -11,      /**< a table value (a spline coefficient too) is NaN or
                                         +-Inf, u_min > u_max, or
                                         u_hold outside [u_min, u_max]; fixed point: a scale
                                         exponent beyond +-STSP_Q_EXP_MAX, or a row whose
                                         absolute sum exceeds 2^F - 1 (see stsp_step; a
                                         spline table's rows of gains as evaluated, at every
                                         tick) */
    STSP_ERR_BAD_PROBLEM = -12,     /**< stsp_init_problem(): the table's problem_sha256 is not
                                         the expected one (tables from another problem file) */
    STSP_ERR_TABLE_CHANGED = -13,   /**< stsp_verify(): the table header (magic, version, kind,
                                         a dimension, an array address, the band dual's or
                                         the spline's header) is not the one stsp_init()
                                         validated */
    STSP_ERR_NONFINITE_MEASUREMENT = -14, /**< stsp_est_step(): y holds NaN or +-Inf */
    STSP_ERR_PARAM_RANGE = -15      /**< stsp_set_params(): a parameter is NaN, +-Inf or
                                         outside its declared range (the old ones kept) */
} stsp_status_t;

#ifdef __cplusplus
}
#endif

#endif /* STSP_TYPES_H */
