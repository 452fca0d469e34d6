/**
 * @file stsp_params.h
 * @brief Runtime parameters: one flashed table, the plan for any parameter vector in a range.
 *
 * For a problem with [[parameters]] (docs/theory/parameters.md) the feed-forward k0 and the
 * latch offsets lambda0 are affine in the parameters theta, and K, L, Lambda do not depend on
 * them. The parameter table (generated as <name>_params.c beside the gain table) holds the
 * nominal values, the declared range and the sensitivity columns; with d = theta - nominal
 * (computed once by stsp_set_params(); in Q format in a Q15/Q31 build, below) the law of
 * stsp_controller.h runs with
 *
 *     k0'[j][i]      = k0[j][i]      + S_k0[j][i][0] d[0] + ... + S_k0[j][i][P-1] d[P-1]
 *     lambda0'[s][c] = lambda0[s][c] + S_lambda0[s][c][0] d[0] + ...
 *
 * When a new theta takes effect (stsp_set_params() between two steps):
 *   k0'      from the next step on (the next tick);
 *   lambda0' at the next latch (the next stage start with stage_n_latch > 0, or tick 0 after
 *            a reset); the multipliers latched before are kept until then.
 * A change at a stage start of a stage-wise design is therefore the design at the new theta
 * from that stage on (each stage re-plans from the measured state). A change inside a stage
 * steers with the new feed-forward and the old multipliers until the next latch: a defined,
 * finite plan that stays within the actuator limits, but not the design at either theta; set
 * the parameters before the stage start they should apply to.
 *
 * Evaluation order of a float32 build (fixed, binary32, no fused multiply-add:
 * -ffp-contract=off):
 *     d[p]   = theta[p] - nominal[p]                              (stsp_set_params)
 *     e      = k0[i];  e = e + (S_k0[i][p] d[p]) for p = 0 .. P-1
 *     u[i]   = -e; u[i] = u[i] - (K[i][j] x[j]) for j = 0 .. nx-1, then
 *              u[i] = u[i] - (L[i][c] v[c]) for c = 0 .. n_latch-1, then the clamp
 *     latch  e = lambda0[c]; e = e + (S_lambda0[c][p] d[p]) for p = 0 .. P-1;
 *            v[c] = e; v[c] = v[c] + (Lambda[c][j] x[j]) for j = 0 .. nx-1
 * each step rounded twice (product, then sum). At theta = nominal (d = 0) the commands are
 * stsp_step()'s bit for bit, up to the sign of a zero (host/stospline/table/params_spec.py is
 * the same arithmetic in numpy, checked bit for bit).
 *
 * Fixed point (Q15/Q31 builds; scalar_kind the build's, host stospline.table.qparams): the
 * parameters are P more states of the fixed-point law (stsp_table.h). nominal, lower and upper
 * are binary64; per parameter d_q[p] = floor((theta[p] - nominal[p]) 2^(F - d_exp[p]) + 1/2),
 * computed once by stsp_set_params() in binary64 (theta[p] converted exactly, one rounded
 * subtraction, the rest exact), and the columns are stored negated and pre-scaled:
 *     S_k0[j][i][p]      = rhu(-S_k0_ip(j) 2^(d_exp[p] - u_exp[i] + F))
 *     S_lambda0[s][c][p] = rhu(S_lambda0_cp 2^(d_exp[p] - v_exp[c] + F))
 * (the table's stored, negated integers below) so that, exactly in the accumulator of
 * stsp_step (any order, one rounding),
 *     u_q[i] = k0[i] + floor((sum_j K x_q + sum_p S_k0 d_q + sum_c L v_q) / 2^F + 1/2)
 *     v_q[c] = lambda0[c] + floor((sum_j Lambda x_q + sum_p S_lambda0 d_q) / 2^F + 1/2).
 * stsp_param_init() checks every law row |k0| + sum|K| + sum|S_k0| + sum|L| and latch row
 * |lambda0| + sum|Lambda| + sum|S_lambda0| <= 2^F - 1, and |d_q| <= 2^F - 1 at both ends of
 * every range: nothing overflows and no u_q or v_q leaves the Q range for any theta in the
 * box and any state. The gain table is the one quantized with the columns (its scales cover
 * the box: stospline.table.parametric_c.generate_parametric_qc), and the commands are
 * bit for bit qformat.law_q of that table over [x_q; d_q].
 *
 * Spline gain tables (float32, format 2, host stospline.table.spline.params): the columns
 * are cubic B-splines on the gain spline's knots, S_s + 3 coefficients per stage, input and
 * parameter (S_k0, format 2). At tick j of stage s, in span sigma with the basis N of
 * stsp_spline.h, per input i the fold of the feed-forward with the latch (stsp_spline.h:
 * f[r] = ((+0 - c_k0[r]) - c_L1[r] v_1) - ... over the row's entries after its gains of x)
 * goes on with the columns, f[r] = f[r] - (c_p[r] d[p]) for p = 0 .. P-1 (coefficients
 * sigma .. sigma + 3 of the column); then
 *     u[i] = ((N0 f0 + N1 f1) + N2 f2) + N3 f3, u[i] = u[i] - (g_e x[col_e]) over the row's
 *            gains of x in stored order (g_e = ((N0 c0 + N1 c1) + N2 c2) + N3 c3),
 * then the checks and the clamp of the per-tick law; the latch as above. At d = 0 the
 * commands are stsp_step()'s on the spline table bit for bit (up to the sign of a zero).
 * The span's record (its basis quotient, coefficients and that fold, v and d folded in) is
 * kept in ctrl.span, the spline table's span cache, which stsp_step() would use and a
 * parametric instance never passes to it: an ordinary tick inside the recorded span of its
 * stage evaluates the basis and the record's fold only; a later one searches again from the
 * record's span, any other from the stage's first span. stsp_set_params() clears the record,
 * init and reset clear it with the instance (a latch comes with another stage); the cold path
 * (maybe a fresh latch) searches from the stage's first span without it.
 *
 * Spline columns in fixed point (Q15/Q31 builds, format 2 with a Q spline gain table; host
 * stospline.table.spline.qparams): per stage s, input i and parameter p one block of S_s + 4
 * scalars in S_k0, the column's scale s_c (1 .. 30) then its S_s + 3 integer B-spline
 * coefficients on the gain spline's spans (S_s = ceil(T_s / 2^k_s), stsp_qspline.h), block
 * (s, i, p) at nu P sum_{s' < s} (S_{s'} + 4) + (i P + p)(S_s + 4). At tick tau of stage s
 * the column's gain is g_p = floor((sum_r c[sigma + r] P_r) / 2^(3 k_s + s_c) + 1/2), exact,
 * as a gain entry's, and
 *     u_q[i] = k0[i] + floor((sum_e g_e z_q[col_e] + sum_p g_p d_q[p]) / 2^F + 1/2)
 * (one rounding of the whole sum, z_q = [x_q, 0, v_q]; the latch as per tick above): the
 * per-tick law over [x_q; d_q] with the splines' gains as evaluated, bit for bit (host
 * qparams.QParamSpec of stospline.table.spline.qparams.quantize_spline_parametric). Init
 * checks n_spline_coef against the layout (STSP_ERR_BAD_DIMS), every scale and, at every
 * tick, every law row with its columns, sum |g| <= 2^F - 1 (STSP_ERR_BAD_VALUES): one
 * evaluation per entry, column and tick. Each tick also finds its stage's blocks (a sum over
 * the stages before it).
 *
 * A per-tick parameter table (format 1) with a spline gain table, a spline one (format 2)
 * with a per-tick table, and a gain table with a band dual are refused at init
 * (STSP_ERR_BAD_DIMS); a parameter table of another scalar kind than the build's with
 * STSP_ERR_BAD_VERSION.
 *
 * Does not use malloc, recursion or VLAs; every loop is bounded by the validated dimensions
 * (n_params <= STSP_MAX_PARAMS, 32 by default). Buffers: stsp_param_t holds a stsp_ctrl_t,
 * the validated copy of the parameter table's header and STSP_MAX_PARAMS scalars of d: 928
 * bytes with the default limits in a float32 build, 348 in Q15, 476 in Q31
 * (arm-none-eabi-gcc -mcpu=cortex-m4, sizeof(stsp_param_t)).
 * stsp_param_step() uses STSP_MAX_LATCH + STSP_MAX_NU scalars of stack; with a spline table
 * its call of the spline code also, in float32, a span record (stsp_span_t, on the cold
 * path) and 4 scalars; in fixed point a span record, STSP_MAX_NU accumulators and the spline
 * law's STSP_MAX_NX + 1 + STSP_MAX_LATCH operands. Every tick of a
 * parametric instance is evaluated by this file in plain C loops (not stsp_step()'s ordinary
 * tick): nu P more multiply-adds per tick, and the generic loop overhead
 * (tools/arm/count_params.py, docs/guide/firmware.md).
 */
#ifndef STSP_PARAMS_H
#define STSP_PARAMS_H

#include "stospline/stsp_controller.h"

#ifdef __cplusplus
extern "C" {
#endif

/** Parameter table magic, "STPR" as a little-endian u32. */
#define STSP_PARAMS_MAGIC 0x52505453u
/** Parameter table format understood by this firmware: columns per tick. */
#define STSP_PARAMS_FORMAT_VERSION 1u
/** The other format understood: spline columns of a spline table (float32, Q15, Q31). */
#define STSP_PARAMS_FORMAT_SPLINE 2u
/** Upper bound on the parameters, checked by stsp_param_init() (the problem file allows 32). */
#ifndef STSP_MAX_PARAMS
#define STSP_MAX_PARAMS 32u
#endif

#define stsp_param_init STSP_NAME(stsp_param_init)
#define stsp_set_params STSP_NAME(stsp_set_params)
#define stsp_param_reset STSP_NAME(stsp_param_reset)
#define stsp_param_verify STSP_NAME(stsp_param_verify)
#define stsp_param_step STSP_NAME(stsp_param_step)
#define stsp_params_table_crc32 STSP_NAME(stsp_params_table_crc32)

/**
 * The parameter table (generated: <name>_params.c). Layouts (row-major):
 * S_k0[tick][i][p] = S_k0[(tick*nu + i)*n_params + p],
 * S_lambda0[stage][c][p] = S_lambda0[(stage*n_latch + c)*n_params + p].
 */
#ifdef STSP_ARITH_FIXED_POINT
typedef double stsp_param_value_t; /**< nominal, lower, upper: binary64 in a Q15/Q31 build */
#else
typedef stsp_f32_t stsp_param_value_t;
#endif
typedef struct {
    uint32_t magic;              /**< STSP_PARAMS_MAGIC */
    uint16_t format_version;     /**< STSP_PARAMS_FORMAT_VERSION */
    uint16_t scalar_kind;        /**< STSP_SCALAR_KIND of the build */
    uint16_t n_params;           /**< 1 .. STSP_MAX_PARAMS */
    uint16_t nu;                 /**< the gain table's nu */
    uint16_t n_latch;            /**< the gain table's n_latch */
    uint16_t n_stages;           /**< the gain table's n_stages */
    uint32_t n_ticks;            /**< the gain table's n_ticks */
    const stsp_param_value_t *nominal; /**< [n_params] the design's values */
    const stsp_param_value_t *lower;   /**< [n_params] */
    const stsp_param_value_t *upper;   /**< [n_params] */
#ifdef STSP_ARITH_FIXED_POINT
    const int8_t *d_exp;         /**< [n_params] scale exponents of d (within
                                      +-STSP_Q_EXP_MAX) */
#endif
    const stsp_scalar_t *S_k0;      /**< [n_ticks][nu][n_params]; format 2 (spline columns):
                                         [nu n_params (sp.n_knots - 4 n_stages)], stage s,
                                         input i, parameter p, coefficient r at
                                         nu n_params (knot_start[s] - 4 s)
                                         + (i n_params + p)(S_s + 3) + r; format 2 in
                                         Q15/Q31: blocks of scale and S_s + 3 coefficients
                                         (above) */
    const stsp_scalar_t *S_lambda0; /**< [n_stages][n_latch][n_params] (may be NULL when
                                         n_latch == 0) */
    uint32_t crc32;              /**< see stsp_params_table_crc32() */
    uint8_t problem_sha256[32];  /**< the gain table's problem_sha256 */
    uint32_t n_spline_coef;      /**< format 2: the length of S_k0, nu n_params (sp.n_knots
                                      - 4 n_stages) of the gain table's spline (Q15/Q31:
                                      nu n_params sum_s (S_s + 4)); format 1: 0
                                      (unread) */
} stsp_params_table_t;

/** One parametric controller instance, caller-owned; all fields private but `ctrl`'s
 *  read-only ones (stsp_controller.h). Step it only through stsp_param_step(). */
typedef struct {
    stsp_ctrl_t ctrl;                 /**< the gain table's instance */
    const stsp_params_table_t *params;
    stsp_params_table_t checked;      /**< the validated header (private) */
    uint32_t ready;                   /**< a magic value after a successful init (private) */
    stsp_scalar_t d[STSP_MAX_PARAMS]; /**< theta - nominal in use, d_q in a Q15/Q31 build
                                           (private) */
} stsp_param_t;

/**
 * CRC-32 (as stsp_table_crc32) of n_params, nu, n_latch, n_stages, n_ticks as little-endian
 * u32, then nominal, lower, upper, S_k0 and (when n_latch > 0) S_lambda0 as little-endian
 * binary32 bit patterns, then the 32 bytes of problem_sha256. Format 2: format_version and
 * n_spline_coef as u32 after n_ticks (S_k0 is n_spline_coef long). Fixed point: scalar_kind as a
 * u32 after n_ticks, nominal, lower, upper as little-endian binary64 bit patterns, S_k0 and
 * S_lambda0 as little-endian int16 (Q15) or int32 (Q31), then d_exp one byte each, then the
 * hash. The dimensions and pointers must
 * be valid (stsp_param_init() checks them first).
 */
uint32_t stsp_params_table_crc32(const stsp_params_table_t *params);

/**
 * Bind the gain table (stsp_init(), whose status is returned when not STSP_OK) and its
 * parameter table to an instance, theta = nominal. Precondition (as for stsp_init()): each
 * array is as long as the header says. Errors (instance not ready): STSP_ERR_NULL (a NULL
 * pointer, also an array of the parameter table), STSP_ERR_BAD_MAGIC, STSP_ERR_BAD_VERSION
 * (format, or a scalar kind other than the build's), STSP_ERR_BAD_DIMS (n_params outside
 * 1 .. STSP_MAX_PARAMS, nu, n_latch, n_stages or n_ticks not the gain table's, a spline
 * gain table with format 1 or a per-tick one with format 2, n_spline_coef not the spline's
 * length, or a table with a band dual), STSP_ERR_BAD_CRC, STSP_ERR_BAD_PROBLEM (problem_sha256 not
 * the gain table's), STSP_ERR_BAD_VALUES (a NaN or infinite entry, the spline columns' included,
 * or not lower <= nominal <= upper; fixed point also: a d_exp beyond +-STSP_Q_EXP_MAX, a law or latch row with the
 * columns above 2^F - 1 (spline columns: at some tick), a spline column's scale outside
 * 1 .. 30, or |d_q| > 2^F - 1 at an end of a range).
 */
stsp_status_t stsp_param_init(stsp_param_t *pc, const stsp_table_t *table,
                              const stsp_params_table_t *params);

/**
 * Set the parameters theta[n_params] (see above for when they take effect). Every theta[p]
 * must be finite and within [lower[p], upper[p]]; otherwise STSP_ERR_PARAM_RANGE and the
 * parameters in use are unchanged (the whole vector is checked before any is taken; fixed
 * point: also a d_q beyond the Q range, which init rules out for an unchanged table).
 * STSP_ERR_NULL, STSP_ERR_NOT_INITIALIZED as usual. Not to be called while a step of the same
 * instance runs (from an interrupt, say).
 */
stsp_status_t stsp_set_params(stsp_param_t *pc, const stsp_f32_t *theta);

/** Restart the plan at tick 0 (stsp_reset()); the parameters are kept. */
stsp_status_t stsp_param_reset(stsp_param_t *pc);

/**
 * stsp_verify() of the gain table, then the same for the parameter table: a changed header
 * (STSP_ERR_TABLE_CHANGED) or CRC (STSP_ERR_BAD_CRC) stops the instance (every later step
 * STSP_ERR_NOT_INITIALIZED with u = u_hold) until a new init.
 */
stsp_status_t stsp_param_verify(stsp_param_t *pc);

/**
 * The command for tick `tick` from the measured state x[nx] (x_q in a Q15/Q31 build); writes
 * u[nu] (u_q). The ticks,
 * statuses and the command on an error are stsp_step()'s (stsp_controller.h), with k0' and
 * lambda0' in the law. x and u may overlap.
 */
stsp_status_t stsp_param_step(stsp_param_t *pc, uint32_t tick, const stsp_scalar_t *x,
                              stsp_scalar_t *u);

#ifdef __cplusplus
}
#endif

#endif /* STSP_PARAMS_H */
