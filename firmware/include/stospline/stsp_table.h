/**
 * @file stsp_table.h
 * @brief The gain table formats (stsp_table_t, per tick or with spline gains) and their CRC-32.
 *
 * Generated tables (the C files of gains/) fill these structs; stsp_init() (stsp_controller.h) checks
 * them. The law they hold is documented in stsp_controller.h, the evaluation of spline gains in
 * stsp_spline.h.
 */
#ifndef STSP_TABLE_H
#define STSP_TABLE_H

#include "stospline/stsp_types.h"
#include "stospline/stsp_bandqp.h"

#ifdef __cplusplus
extern "C" {
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

/** The code of spline gains (stsp_spline.h): stsp_spline_t.ops, stsp_qspline_t.ops. */
typedef struct stsp_spline_ops_s stsp_spline_ops_t;

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
    const stsp_spline_ops_t *ops; /**< &stsp_spline_ops: the code that checks and evaluates
                                       it (stsp_spline.h); NULL: stsp_init() refuses the
                                       table (STSP_ERR_BAD_DIMS) */
} stsp_spline_t;
#endif

#ifdef STSP_ARITH_FIXED_POINT
/**
 * Fixed-point spline gains (Q15/Q31 builds; the compressed format, host
 * stospline.table.spline.fixed_point): each stage's gains as uniform cubic B-splines of the tick, with
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
    const stsp_spline_ops_t *ops; /**< &stsp_spline_ops, as stsp_spline_t.ops */
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

#define stsp_table_crc32 STSP_NAME(stsp_table_crc32) /* stsp_table_crc32_f32, _q15, _q31 */

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

#ifdef __cplusplus
}
#endif

#endif /* STSP_TABLE_H */
