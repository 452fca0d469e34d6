/**
 * @file stsp_estimator.h
 * @brief The controller on a sensor: a linear filter's estimate x̂ feeds the latched law.
 *
 * For a problem with a [measurement] table (docs/theory/estimator.md): the sensor reads
 * y = C x + noise at every tick j with j % every == 0, and the controller runs, at tick j,
 *
 *     update    x̂+ = x̂ + F[j / every] (y - C x̂)       (a sampling tick with a reading)
 *     law       u  = stsp_step(tick j, x̂+)              (latch and law of stsp_controller.h)
 *     predict   x̂  = Ad x̂+ + Bd u + fd                  (the plant's mean map over the tick)
 *
 * starting from the table's prior mean x̂ = xhat0 at tick 0. u is the command written (after
 * the clamp to the actuator limits): the one the plant holds over the tick.
 *
 * float32, Q15 and Q31 builds (the fixed-point arithmetic is below). Does not use malloc,
 * recursion or VLAs;
 * every loop is bounded by the validated dimensions (nx <= STSP_MAX_NX, nu <= STSP_MAX_NU,
 * ny <= STSP_MAX_NY) or, for skipped ticks, by n_ticks.
 *
 * Evaluation order (fixed, binary32, no fused multiply-add: -ffp-contract=off), with
 * acc -= a b meaning acc = acc - (a b) rounded twice:
 *     innovation  e[i] = y[i]; e[i] -= C[i][j] x̂[j] for j = 0 .. nx-1
 *     update      x̂[r] += F[r][i] e[i] for i = 0 .. ny-1, each step acc = acc + (F e)
 *     predict     acc = fd[r]; acc += Ad[r][j] x̂+[j] for j = 0 .. nx-1, then
 *                 acc += Bd[r][i] u[i] for i = 0 .. nu-1; x̂[r] = acc
 * (host/stospline/estimator/spec.py is the same arithmetic in numpy, checked bit for bit).
 *
 * Spline gains (float32 only, stsp_est_init_spline()): the table's gain is NULL and F of
 * sample q = tick / every in stage s is evaluated from stsp_est_gain_spline_t at
 * tau = (float)(q - q0(s)) (exact), q0(s) = ceil(stage_start[s] / every) the stage's first
 * sample: the span sigma = the largest in 0 .. S-1 with U[sigma + 3] <= tau (a binary search),
 * i = sigma + 3, left[k] = tau - U[i+1-k], right[k] = U[i+k] - tau (k = 1..3), N[0] = 1 and for
 * k = 1..3: saved = +0; for r = 0..k-1: temp = N[r] / (right[r+1] + left[k-r]),
 * N[r] = saved + right[r+1] temp, saved = left[k-r] temp; then N[k] = saved (The NURBS Book
 * A2.2, every operation rounded); each stored entry F[r][i] = ((N[0] c[sigma] + N[1]
 * c[sigma+1]) + N[2] c[sigma+2]) + N[3] c[sigma+3], every entry not stored +0; then the update
 * above (host/stospline/estimator/gain_spline.py evaluates the same, bit for bit). The basis is
 * computed once per sample, the gains one row of F at a time (STSP_MAX_NY scalars of stack).
 *
 * Fixed point (STSP_ARITH_Q15/Q31, F = STSP_Q_FRAC_BITS; host/stospline/estimator/qformat.py
 * is the same arithmetic, checked bit for bit): x̂ is held in the law's state format
 * x̂ = x̂_q 2^(x_exp - F) (stsp_table_t.x_exp), the reading is y = y_q 2^(y_exp - F) and the
 * innovation e = e_q 2^(e_exp - F). Each row (innovation i, update r, prediction r) is one
 * exact sum in a 64-bit accumulator, then rounded half up by a shift and saturated:
 *     innovation  acc = y_q[i] 2^(k + y_exp[i] - e_exp[i]) + sum_j C[i][j] x̂_q[j]
 *     update      acc = x̂_q[r] 2^k + sum_i F[r][i] e_q[i]
 *     predict     acc = x̂+_q[r] 2^k + fd[r] 2^F + sum_j (Ad - I)[r][j] x̂+_q[j]
 *                       + sum_i Bd[r][i] u_q[i]
 *     out_q = floor(acc / 2^k + 1/2), saturated to [-2^F, 2^F - 1]
 * with k = shift[row] (1 .. 61 - F) and the entries stored scaled by 2^(z_exp - out_exp + k),
 * fd by 2^(k - x_exp) (C stored negated: -C; the predictor's map as its increment Ad - I).
 * stsp_est_init() requires every row's absolute sum, the pass-through coefficient and the
 * 2^F-weighted constant included, to be at most 2^(61 - F): then |acc| <= 2^61
 * for all inputs, the sums are exact and only the result can leave its Q range, which the step
 * reports as STSP_WARN_STATE_CLAMPED (the innovation or the estimate saturated).
 *
 * Buffers: stsp_est_t holds a stsp_ctrl_t, the validated copy of the estimator table's
 * header, STSP_MAX_NX + STSP_MAX_NU scalars (x̂ and the last command), 12 bytes of state and
 * (float32) the bound gain spline's pointer and validated header: 1056 bytes with the default
 * limits (arm-none-eabi-gcc -mcpu=cortex-m4, sizeof(stsp_est_t); Q15 400 bytes).
 * stsp_est_step() uses 2 STSP_MAX_NX + STSP_MAX_NY + STSP_MAX_NU scalars of stack plus
 * stsp_step()'s.
 */
#ifndef STSP_ESTIMATOR_H
#define STSP_ESTIMATOR_H

#include "stospline/stsp_controller.h"

#ifdef __cplusplus
extern "C" {
#endif

/** Estimator table magic, "STSE" as a little-endian u32. */
#define STSP_EST_MAGIC 0x45535453u
/** Estimator table format understood by this firmware. */
#define STSP_EST_FORMAT_VERSION 1u
/** Upper bound on the sensor's outputs, checked by stsp_est_init(). */
#ifndef STSP_MAX_NY
#define STSP_MAX_NY 8u
#endif

#define stsp_est_init STSP_NAME(stsp_est_init)
#define stsp_est_reset STSP_NAME(stsp_est_reset)
#define stsp_est_verify STSP_NAME(stsp_est_verify)
#define stsp_est_step STSP_NAME(stsp_est_step)
#define stsp_est_table_crc32 STSP_NAME(stsp_est_table_crc32)
#define stsp_est_init_spline STSP_NAME(stsp_est_init_spline)
#define stsp_est_gain_spline_crc32 STSP_NAME(stsp_est_gain_spline_crc32)

/** Gain spline magic, "STSG" as a little-endian u32. */
#define STSP_EST_SPLINE_MAGIC 0x47535453u

/**
 * The filter's tables (generated next to the gain table, same problem file). Layouts
 * (row-major): model[k][r*(nx + nu + 1) + c] = [Ad | Bd | fd] row r of predictor map k
 * (fixed point: [Ad - I | Bd | fd]);
 * stage s uses maps model_start[s] .. model_start[s+1] - 1: one for every tick of the stage
 * (a time-invariant stage) or one per tick (a time-varying one); C[i*nx + j];
 * gain[s][r*ny + i] = F of sample s, at tick s * every, for s < ceil(n_ticks / every);
 * xhat0[nx] the prior mean. Fixed point: the entries are scaled as described at the top,
 * C holds -C, y_exp/e_exp [ny] and shift [ny + 2 nx] (innovation rows, update rows, prediction
 * rows) follow the problem hash.
 */
typedef struct {
    uint32_t magic;              /**< STSP_EST_MAGIC */
    uint16_t format_version;     /**< STSP_EST_FORMAT_VERSION */
    uint16_t scalar_kind;        /**< STSP_SCALAR_KIND of the build */
    uint16_t nx;                 /**< states: the gain table's nx */
    uint16_t nu;                 /**< inputs: the gain table's nu */
    uint16_t ny;                 /**< sensor outputs, 1 .. STSP_MAX_NY */
    uint16_t n_stages;           /**< the gain table's n_stages */
    uint32_t n_ticks;            /**< the gain table's n_ticks */
    uint32_t every;              /**< a sample every `every` ticks (>= 1), from tick 0 */
    const uint32_t *model_start; /**< [n_stages + 1] */
    const stsp_scalar_t *model;  /**< [model_start[n_stages]][nx][nx + nu + 1] */
    const stsp_scalar_t *C;      /**< [ny][nx] (fixed point: -C) */
    const stsp_scalar_t *gain;   /**< [ceil(n_ticks / every)][nx][ny] */
    const stsp_scalar_t *xhat0;  /**< [nx] */
    uint32_t crc32;              /**< see stsp_est_table_crc32() */
    uint8_t problem_sha256[32];  /**< the gain table's problem_sha256 */
#ifdef STSP_ARITH_FIXED_POINT
    const int8_t *y_exp;         /**< [ny]: reading scale exponents */
    const int8_t *e_exp;         /**< [ny]: innovation scale exponents, <= y_exp */
    const uint8_t *shift;        /**< [ny + 2 nx]: row shifts k, each 1 .. 61 - F */
#endif
} stsp_est_table_t;

/**
 * The update gains as cubic B-splines of the sample (float32 builds; generated next to the
 * estimator table, whose gain is then NULL): per stage s with T > 0 samples (T = q0(s + 1) -
 * q0(s), see the top), the clamped knot vector knot[knot_start[s] .. knot_start[s+1]) =
 * [0,0,0,0, b_1 < ... < b_(S-1), T,T,T,T] (integers, T < 2^24, S >= 1 spans), the stored
 * entries entry[entry_start[s] .. entry_start[s+1]) (r * ny + i of F[r][i], increasing, below
 * nx ny) and their coefficients coef[coef_start[s] ..], S + 3 per entry, entry-major; a stage
 * without samples has no knots, entries or coefficients.
 */
typedef struct {
    uint32_t magic;              /**< STSP_EST_SPLINE_MAGIC */
    uint32_t n_knots;            /**< knot_start[n_stages] */
    uint32_t n_entries;          /**< entry_start[n_stages] */
    uint32_t n_coef;             /**< coef_start[n_stages] */
    const uint32_t *knot_start;  /**< [n_stages + 1] */
    const stsp_f32_t *knot;      /**< [n_knots] */
    const uint32_t *entry_start; /**< [n_stages + 1] */
    const uint8_t *entry;        /**< [n_entries] */
    const uint32_t *coef_start;  /**< [n_stages + 1] */
    const stsp_f32_t *coef;      /**< [n_coef] */
    uint32_t est_crc32;          /**< the crc32 of the estimator table it belongs to */
    uint32_t crc32;              /**< see stsp_est_gain_spline_crc32() */
} stsp_est_gain_spline_t;

/** One estimator-controller instance, caller-owned; all fields private but `ctrl`'s
 *  read-only ones (stsp_controller.h). */
typedef struct {
    stsp_ctrl_t ctrl;                  /**< the law on x̂+ */
    const stsp_est_table_t *table;
    stsp_est_table_t checked;          /**< the validated header (private) */
    uint32_t ready;                    /**< a magic value after a successful init (private) */
    uint32_t next_tick;                /**< the tick x̂ is the prediction for (private) */
    uint32_t stage;                    /**< the stage of tick next_tick (private) */
    stsp_scalar_t xhat[STSP_MAX_NX];   /**< the prediction for next_tick (private) */
    stsp_scalar_t u_last[STSP_MAX_NU]; /**< the last command written (private) */
#ifndef STSP_ARITH_FIXED_POINT
    const stsp_est_gain_spline_t *spline;  /**< the gain spline, or NULL (private) */
    stsp_est_gain_spline_t spline_checked; /**< its validated header (private) */
#endif
} stsp_est_t;

/**
 * CRC-32 (as stsp_table_crc32) of nx, nu, ny, n_stages, n_ticks, every and
 * model_start[n_stages] as little-endian u32, model_start as u32 each, then model, C, gain,
 * xhat0 as little-endian binary32 bit patterns (gain not when NULL; fixed point: int16/int32 two's complement,
 * then y_exp, e_exp and shift one byte each), then the 32 bytes of problem_sha256. The
 * dimensions and pointers must be valid (stsp_est_init() checks them first).
 */
uint32_t stsp_est_table_crc32(const stsp_est_table_t *est);

/**
 * Bind the gain table (stsp_init(), whose status is returned when not STSP_OK) and the
 * estimator table to an instance, x̂ = xhat0 at tick 0. Precondition (as for stsp_init()):
 * each array is as long as the header says (ny and every size C and gain, and only the CRC
 * can tell them wrong). Errors (instance not ready):
 * STSP_ERR_NULL (a NULL pointer, also an array of the estimator table), STSP_ERR_BAD_MAGIC,
 * STSP_ERR_BAD_VERSION (format or scalar kind not the build's), STSP_ERR_BAD_DIMS (nx, nu, n_stages or
 * n_ticks not the gain table's, ny outside 1 .. STSP_MAX_NY, every == 0, model_start not 0 then
 * one or a stage's ticks per stage), STSP_ERR_BAD_CRC, STSP_ERR_BAD_PROBLEM (problem_sha256 not
 * the gain table's: tables from different problem files), STSP_ERR_BAD_VALUES (a NaN or
 * infinite entry; fixed point: an exponent beyond +-STSP_Q_EXP_MAX, e_exp > y_exp, a shift
 * outside 1 .. 61 - F, or a row whose absolute sum exceeds 2^(61 - F)).
 */
stsp_status_t stsp_est_init(stsp_est_t *est, const stsp_table_t *table,
                            const stsp_est_table_t *est_table);

#ifndef STSP_ARITH_FIXED_POINT
/**
 * CRC-32 (as stsp_table_crc32) of n_stages, nx ny, n_knots, n_entries and n_coef as
 * little-endian u32, knot_start (n_stages + 1 u32), knot (binary32), entry_start (u32), entry
 * (bytes), coef_start (u32), coef (binary32), then est_crc32 (u32). The layout must be valid
 * (stsp_est_init_spline() checks it first).
 */
uint32_t stsp_est_gain_spline_crc32(const stsp_est_gain_spline_t *spline,
                                    const stsp_est_table_t *est);

/**
 * stsp_est_init() with the update gains as a spline (float32 builds): the estimator table's
 * gain must be NULL and its CRC leaves gain out. The statuses of stsp_est_init() (est_table
 * first), then for the spline: STSP_ERR_NULL (spline or one of its arrays NULL),
 * STSP_ERR_BAD_DIMS (the table's gain not NULL; start arrays not from 0 to n_knots,
 * n_entries, n_coef or decreasing; a stage's knots, entries or coefficients not as
 * stsp_est_gain_spline_t says for its samples), STSP_ERR_BAD_MAGIC, STSP_ERR_BAD_CRC,
 * STSP_ERR_BAD_PROBLEM (est_crc32 not the estimator table's crc32: a spline of another table),
 * STSP_ERR_BAD_VALUES (a NaN or infinite coefficient).
 */
stsp_status_t stsp_est_init_spline(stsp_est_t *est, const stsp_table_t *table,
                                   const stsp_est_table_t *est_table,
                                   const stsp_est_gain_spline_t *spline);
#endif

/** Restart at tick 0 with x̂ = xhat0 (stsp_reset() of the law). */
stsp_status_t stsp_est_reset(stsp_est_t *est);

/**
 * stsp_verify() of the gain table, then the same for the estimator table and its gain
 * spline (when bound): a changed header
 * (STSP_ERR_TABLE_CHANGED) or CRC (STSP_ERR_BAD_CRC) stops the instance (every later step
 * STSP_ERR_NOT_INITIALIZED with u = u_hold) until a new init.
 */
stsp_status_t stsp_est_verify(stsp_est_t *est);

/**
 * The command for tick `tick` from the sensor's reading y[ny]; writes u[nu].
 * y is read only at a sampling tick (tick % every == 0); y == NULL there (the reading is
 * missing) runs the law on the prediction: STSP_WARN_NO_MEASUREMENT, unless stsp_step() has
 * a warning to report. Ticks:
 *   tick == next expected: update, law, predict (the statuses of stsp_step());
 *   tick  > next expected: x̂ is first predicted over the missed ticks with the last command
 *          held (u_hold before the first step), without their samples; then as above
 *          (STSP_WARN_TICK_SKIPPED);
 *   tick == the last one stepped: u is the command written then, STSP_WARN_TICK_REPEATED,
 *          nothing changes;
 *   earlier: STSP_ERR_TICK_ORDER; tick >= n_ticks: STSP_ERR_TICK_RANGE.
 * A NaN or infinite y[i] is STSP_ERR_NONFINITE_MEASUREMENT (float32). Fixed point: y is y_q,
 * u is u_q; an innovation or estimate that saturated is STSP_WARN_STATE_CLAMPED (when
 * stsp_step() and a missing reading have nothing to report). On every negative status u is
 * u_hold (not written when u is NULL, nor before a successful init) and the instance is
 * unchanged: the same tick may be stepped again (with y == NULL, to run on the prediction).
 * An update that overflows gives STSP_ERR_NONFINITE_STATE (from stsp_step()); a prediction
 * that overflows is kept, and every later step returns STSP_ERR_NONFINITE_STATE until a reset.
 * y and u must not overlap the instance or the tables; y may overlap u.
 */
stsp_status_t stsp_est_step(stsp_est_t *est, uint32_t tick, const stsp_scalar_t *y,
                            stsp_scalar_t *u);

#ifdef __cplusplus
}
#endif

#endif /* STSP_ESTIMATOR_H */
