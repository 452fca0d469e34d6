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
 */
#ifndef STSP_CONTROLLER_H
#define STSP_CONTROLLER_H

#include <stddef.h>
#include <stdint.h>

#include "stospline/stsp_bandqp.h"

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

/** Table magic, "STSP" as a little-endian u32. */
#define STSP_TABLE_MAGIC 0x53545350u
/** Table format understood by this firmware (2: actuator limits u_min/u_max; 3: optional
 * band dual QP re-solved at the t0 latch; 4: the safe command u_hold; 5: optional spline
 * gains, stsp_table_t.spline). */
#define STSP_FORMAT_VERSION 5u
/** Arithmetic variant tag stored in the table (scalar_kind): float32, Q15 or Q31 tables. */
#define STSP_SCALAR_FLOAT32 1u
#define STSP_SCALAR_Q15 2u
#define STSP_SCALAR_Q31 3u
#if defined(STSP_ARITH_Q15)
#define STSP_SCALAR_KIND STSP_SCALAR_Q15
#elif defined(STSP_ARITH_Q31)
#define STSP_SCALAR_KIND STSP_SCALAR_Q31
#else
#define STSP_SCALAR_KIND STSP_SCALAR_FLOAT32
#endif
/** Fixed point: stsp_init() refuses scale exponents (x_exp, u_exp, v_exp) outside +-this. */
#define STSP_Q_EXP_MAX 60

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
                                         outside the Q range and was saturated to its end */
    STSP_WARN_BAND_FALLBACK = 5,    /**< the band dual QP found no optimal active set for this
                                         x0 (W not positive definite in double precision), its
                                         data times x0 overflowed, or a multiplier is beyond
                                         FLT_MAX: latched the design's affine map
                                         Lambda x + lambda0 instead */
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
    STSP_ERR_TABLE_CHANGED = -13    /**< stsp_verify(): the table header (magic, version, kind,
                                         a dimension, an array address, the band dual's or
                                         the spline's header) is not the one stsp_init()
                                         validated */
} stsp_status_t;

#ifndef STSP_ARITH_FIXED_POINT
/**
 * Spline gains (format 5, float32 builds only): each stage's gains as cubic B-splines of the
 * tick, instead of one row per tick. Arrays concatenated over the stages s = 0..n_stages-1:
 *   knot[knot_start[s] .. knot_start[s+1]): stage s's clamped knot vector, S_s + 7 knots for
 *     S_s >= 1 spans: [0, 0, 0, 0, b_1, ..., b_{S_s-1}, T, T, T, T] in ticks from the stage's
 *     first, T = stage_start[s+1] - stage_start[s] < 2^24, 0 < b_1 < ... < b_{S_s-1} < T
 *     integers;
 *   col[row_start[s*nu + i] .. row_start[s*nu + i + 1]): the stored (nonzero) entries of stage
 *     s, input i, each the index of its operand in z = [x, 1, v]: j < nx is K[i][j], j == nx
 *     k0[i], j = nx + 1 + c is L[i][c]; an entry not stored is exactly 0;
 *   coef[coef_start[s] .. coef_start[s+1]): the stage's S_s + 3 B-spline coefficients of each
 *     entry, entry after entry in col order.
 * stsp_init() checks: the six arrays not NULL (else STSP_ERR_NULL); knot_start[0] == 0,
 * row_start[0] == 0, coef_start[0] == 0, all three nondecreasing and ending at n_knots,
 * n_entries and n_coef; every stage's knots as above; col[e] < nx + 1 + n_latch, and
 * strictly increasing within each (stage, input) row (so its gains of x come first);
 * coef_start[s+1] - coef_start[s] == (entries of stage s) x (S_s + 3) (else
 * STSP_ERR_BAD_DIMS); every coefficient finite (STSP_ERR_BAD_VALUES).
 */
typedef struct {
    uint32_t n_knots;             /**< length of knot */
    uint32_t n_entries;           /**< length of col */
    uint32_t n_coef;              /**< length of coef */
    const uint32_t *knot_start;   /**< [n_stages + 1] */
    const stsp_f32_t *knot;       /**< [n_knots] */
    const uint16_t *row_start;    /**< [n_stages * nu + 1] */
    const uint8_t *col;           /**< [n_entries] */
    const uint32_t *coef_start;   /**< [n_stages + 1] */
    const stsp_f32_t *coef;       /**< [n_coef] */
} stsp_spline_t;
#endif

#ifdef STSP_ARITH_FIXED_POINT
/**
 * Fixed-point spline gains (Q15/Q31 builds; issue 13's compressed format, host
 * stospline.table.qspline): each stage's gains as uniform cubic B-splines of the tick, with
 * integer coefficients in the per-tick format's scaling (negated, stsp_table_t). Stage s of
 * T_s ticks has spans of D = 2^k ticks (k = span_log2[s] <= 9), S = ceil(T_s / D) spans and
 * S + 3 coefficients per stored entry. Arrays concatenated over the stages s = 0..n_stages-1:
 *   span_log2[s]: k of stage s;
 *   col[row_start[s*nu + i] .. row_start[s*nu + i + 1]): the stored (nonzero) entries of stage
 *     s, input i, each the index of its operand in z = [x, 1, v]: j < nx is K[i][j], j == nx
 *     k0[i], j = nx + 1 + c is L[i][c]; an entry not stored is exactly 0;
 *   shift[e]: entry e's scale s_e, in [1, 30];
 *   coef[coef_start[s] .. coef_start[s+1]): the stage's S + 3 coefficients of each entry,
 *     entry after entry in col order.
 * At tick tau of the stage, sigma = tau >> k, d = tau & (D - 1), P0 = (D - d)^3,
 * P1 = 4 D^3 - 3 d^2 (2 D - d), P3 = d^3, P2 = 6 D^3 - P0 - P1 - P3, and entry e's gain is
 *     g = floor((c[sigma] P0 + c[sigma+1] P1 + c[sigma+2] P2 + c[sigma+3] P3) / 2^(3k + s_e)
 *               + 1/2)
 * exactly (one rounding; the sum in 64-bit integers), the per-tick table's stored gain.
 * stsp_init() checks: the six arrays not NULL (else STSP_ERR_NULL); row_start[0] == 0,
 * coef_start[0] == 0, both nondecreasing and ending at n_entries and n_coef; span_log2[s] <= 9;
 * shift[e] in [1, 30]; col[e] < nx + 1 + n_latch and strictly increasing within each (stage,
 * input) row; coef_start[s+1] - coef_start[s] == (entries of stage s) x (S_s + 3) (else
 * STSP_ERR_BAD_DIMS); and, at every tick of the plan, every input's row of gains as evaluated
 * with |k0| + sum|K| + sum|L| <= 2^F - 1, the per-tick format's row bound
 * (STSP_ERR_BAD_VALUES): the law then cannot overflow (stsp_step).
 */
typedef struct {
    uint32_t n_entries;          /**< length of col and shift */
    uint32_t n_coef;             /**< length of coef */
    const uint8_t *span_log2;    /**< [n_stages] */
    const uint16_t *row_start;   /**< [n_stages * nu + 1] */
    const uint8_t *col;          /**< [n_entries] */
    const uint8_t *shift;        /**< [n_entries] */
    const uint32_t *coef_start;  /**< [n_stages + 1] */
    const stsp_scalar_t *coef;   /**< [n_coef] */
} stsp_qspline_t;
/** The spline gains of the build's arithmetic (stsp_table_t.spline). */
typedef stsp_qspline_t stsp_spline_gains_t;
#else
typedef stsp_spline_t stsp_spline_gains_t;
#endif

/**
 * Generated gain tables plus the header that stsp_init() verifies.
 * Layouts (row-major): K[tick][i*nx + j], k0[tick][i], L[tick][i*n_latch + c],
 * Lambda[stage][c*nx + j], lambda0[stage][c], u_min[i], u_max[i], u_hold[i]; multiplier
 * columns beyond a stage's stage_n_latch are zero. u_min[i] = -FLT_MAX and u_max[i] = FLT_MAX
 * mean unlimited. u_hold is the safe command every refused step writes (a hover thrust, a
 * brake): within [u_min, u_max].
 *
 * Fixed point (scalar_kind Q15/Q31, F = STSP_Q_FRAC_BITS): the entries are integers in
 * [-2^F, 2^F - 1] that carry the scales, and the law's gains are stored negated:
 *     K[t][i][j] = -K_ij(t) 2^(x_exp[j] - u_exp[i]) 2^F,  k0[t][i] = -k0_i(t) 2^(F - u_exp[i]),
 *     L[t][i][c] = -L_ic(t) 2^(v_exp[c] - u_exp[i]) 2^F,
 *     Lambda[s][c][j] = Lambda_cj 2^(x_exp[j] - v_exp[c]) 2^F,
 *     lambda0[s][c] = lambda0_c 2^(F - v_exp[c])
 * (rounded half up), so that x[j] = x_q[j] 2^(x_exp[j] - F), v[c] = v_q[c] 2^(v_exp[c] - F),
 * u[i] = u_q[i] 2^(u_exp[i] - F). u_min/u_max/u_hold are in u_q units; -2^F and 2^F - 1 mean
 * unlimited.
 *
 * A spline table (spline != NULL) has K, k0 and L NULL: its gains are the splines'.
 */
typedef struct {
    uint32_t magic;          /**< STSP_TABLE_MAGIC */
    uint16_t format_version; /**< STSP_FORMAT_VERSION */
    uint16_t scalar_kind;    /**< STSP_SCALAR_KIND of the build (float32, Q15 or Q31) */
    uint16_t nx;             /**< states */
    uint16_t nu;             /**< inputs */
    uint16_t n_latch;        /**< latched multipliers per stage (padded width) */
    uint16_t n_stages;
    uint32_t n_ticks;        /**< ticks in the whole plan */
    uint32_t tick_hz;        /**< controller rate */
    const uint32_t *stage_start; /**< [n_stages + 1]: first tick of each stage, then n_ticks */
    const uint16_t *stage_n_latch; /**< [n_stages]: multipliers latched at each stage start
                                        (0: keep the v latched before) */
    const stsp_scalar_t *K;
    const stsp_scalar_t *k0;
    const stsp_scalar_t *L;
    const stsp_scalar_t *Lambda;
    const stsp_scalar_t *lambda0;
    const stsp_scalar_t *u_min;  /**< [nu]: lower actuator limits */
    const stsp_scalar_t *u_max;  /**< [nu]: upper actuator limits */
    const stsp_scalar_t *u_hold; /**< [nu]: the safe command of a refused step, in the limits */
#ifdef STSP_ARITH_FIXED_POINT
    const int8_t *x_exp;         /**< [nx]: state scale exponents */
    const int8_t *u_exp;         /**< [nu]: command scale exponents */
    const int8_t *v_exp;         /**< [n_latch]: latched multiplier scale exponents (may be NULL
                                      when n_latch == 0) */
#endif
    const stsp_bandqp_t *band_qp; /**< NULL, or the band dual of a joint design: the stage-0
                                      latch then solves it for the measured x0 (v[c] =
                                      (float)lam[c], c < q) instead of Lambda x + lambda0;
                                      requires q == stage_n_latch[0] and stage_n_latch[s] == 0 for
                                      s > 0 (one latch, at t0). float32 only: a fixed-point
                                      build refuses a table with one (STSP_ERR_BAD_DIMS) */
    const stsp_spline_gains_t *spline; /**< NULL (gains per tick: K, k0, L), or the spline
                                      gains (K, k0, L then NULL): stsp_spline_t in a float32
                                      build, stsp_qspline_t in a Q15/Q31 build. With band_qp
                                      too (float32 only), the band dual is the one re-solved
                                      for the spline's gains (W non-symmetric, a P-matrix:
                                      stsp_bandqp.h); the same stage-0 latch and checks */
    uint32_t crc32;              /**< CRC-32 of dims and arrays, see stsp_table_crc32() */
    uint8_t problem_sha256[32];  /**< hash of the problem file the tables came from */
} stsp_table_t;

/**
 * Private to the controller: the table header as stsp_init() validated it. stsp_step(),
 * stsp_reset() and the conversions use only this copy, never the header again: every loop
 * bound and index comes from here, so a header changed after init (or a band dual's header)
 * cannot move an access outside the arrays init checked. stsp_verify() compares the header
 * with it before it reads any array.
 */
typedef struct {
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

/**
 * One controller instance; caller-owned (stack, static or a struct of the application).
 * Read-only for the caller: `sat_mask`, `stage`, `next_tick`, `latched`; the rest is private.
 */
typedef struct {
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
 * Defined by the spline tables' code (firmware/src/stsp_spline.c, in every arithmetic: the
 * float32 or the fixed-point spline tick; value STSP_FORMAT_VERSION),
 * which a program links only when something refers to it strongly: a generated spline table
 * does (`<name>_spline_code`, a pointer to this). The controller refers to that code only
 * weakly (GCC or clang, ELF), so that programs with per-tick tables do not carry it; without
 * it stsp_init() refuses a spline table with STSP_ERR_BAD_DIMS. A hand-made spline table must
 * refer to it too (or link with -Wl,--undefined=stsp_spline_code).
 */
extern const uint32_t stsp_spline_code;

/**
 * CRC-32 (IEEE 802.3 polynomial, reflected, as zlib) of the table's canonical serialization:
 * nx, nu, n_latch, n_stages, n_ticks, tick_hz as little-endian u32; stage_start and stage_n_latch
 * as little-endian u32 each; then K, k0, L, Lambda, lambda0, u_min, u_max, u_hold as little-endian
 * binary32 bit patterns (L, Lambda, lambda0 only when n_latch > 0; K, k0, L not for a spline
 * table). Fixed point: scalar_kind
 * as a u32 after tick_hz, the same arrays as little-endian int16 (Q15) or int32 (Q31), then
 * x_exp, u_exp and v_exp (when n_latch > 0) one byte each. Then, for a spline table, n_knots,
 * n_entries and n_coef as u32, knot_start as u32 each, knot as binary32 bit patterns,
 * row_start, col and coef_start as u32 each, coef as binary32 bit patterns (all little-endian);
 * fixed point, after the exponents: n_entries and n_coef as u32, span_log2, row_start, col,
 * shift and coef_start as u32 each, coef as little-endian int16 (Q15) or int32 (Q31).
 * Then, when band_qp is not NULL,
 * its q and nx as u32 and Nt, mt, W, lo, hi as little-endian binary64 bit patterns. Last,
 * the 32 bytes of problem_sha256. Independent of the
 * target's byte order. The table's dimensions and pointers must already be valid (stsp_init()
 * checks them first): the arrays are read as long as the header says.
 */
uint32_t stsp_table_crc32(const stsp_table_t *table);

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
