/**
 * @file stsp_controller.h
 * @brief Latched time-varying affine controller evaluated from const gain tables.
 *
 * The whole flashable API. Does not use malloc, recursion or VLAs; every loop is bounded by
 * the table's dimensions, which stsp_init() checks against the STSP_MAX_* limits below.
 *
 * Law, at tick j of stage s (time t0 + j / tick_hz):
 *
 *     at the stage's first tick, if stage_np[s] > 0:
 *                                 v = Lambda[s] x + lambda0[s]          (latch)
 *     every tick:                 u = -K[j] x - k0[j] - L[j] v
 *
 * Stage-wise designs latch at every constrained stage; joint designs latch once, at stage 0
 * (stage_np[s] = 0 afterwards keeps v). Entries of v beyond stage_np[s] are set to zero.
 *
 * and the caller holds u until the next tick (zero-order hold).
 *
 * Buffers: stsp_ctrl_t holds STSP_MAX_LATCH scalars for v plus a few words; the tables stay
 * where the caller put them (const, normally flash) and are never copied.
 */
#ifndef STSP_CONTROLLER_H
#define STSP_CONTROLLER_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/** Scalar type of the float32 variant: IEEE-754 binary32. */
typedef float stsp_f32_t;

/** Table magic, "STSP" as a little-endian u32. */
#define STSP_TABLE_MAGIC 0x53545350u
/** Table format understood by this firmware. */
#define STSP_FORMAT_VERSION 1u
/** Arithmetic variant tag stored in the table: float32 tables. */
#define STSP_SCALAR_FLOAT32 1u

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

/**
 * Status codes: 0 success, positive = the command is valid but something is worth logging,
 * negative = the command is the safe hold value (all zeros) and the error says why.
 */
typedef enum {
    STSP_OK = 0,
    STSP_WARN_TICK_SKIPPED = 1,     /**< tick > expected; evaluated at the given tick (a stage
                                         entered late latches at that tick) */
    STSP_WARN_TICK_REPEATED = 2,    /**< same tick again; recomputed, no new latch */
    STSP_ERR_NULL = -1,             /**< a pointer argument is NULL */
    STSP_ERR_NOT_INITIALIZED = -2,  /**< step/reset before a successful init */
    STSP_ERR_BAD_MAGIC = -3,        /**< the table header's magic is wrong */
    STSP_ERR_BAD_VERSION = -4,      /**< table format or scalar variant not supported */
    STSP_ERR_BAD_DIMS = -5,         /**< dimensions zero, above the STSP_MAX_* limits, or the
                                         stage index arrays inconsistent */
    STSP_ERR_BAD_CRC = -6,          /**< the tables do not match their CRC-32 */
    STSP_ERR_TICK_RANGE = -7,       /**< tick >= n_ticks: the plan is over */
    STSP_ERR_TICK_ORDER = -8,       /**< tick went backwards by more than one repeat */
    STSP_ERR_NONFINITE_STATE = -9,  /**< x holds NaN or +-Inf */
    STSP_ERR_NONFINITE_OUTPUT = -10 /**< the state is finite but u (or the latch) overflowed */
} stsp_status_t;

/**
 * Generated gain tables plus the header that stsp_init() verifies.
 * Layouts (row-major): K[tick][i*nx + j], k0[tick][i], L[tick][i*n_latch + c],
 * Lambda[stage][c*nx + j], lambda0[stage][c]; multiplier columns beyond a stage's
 * stage_np are zero.
 */
typedef struct {
    uint32_t magic;          /**< STSP_TABLE_MAGIC */
    uint16_t format_version; /**< STSP_FORMAT_VERSION */
    uint16_t scalar_kind;    /**< STSP_SCALAR_FLOAT32 */
    uint16_t nx;             /**< states */
    uint16_t nu;             /**< inputs */
    uint16_t n_latch;        /**< latched multipliers per stage (padded width) */
    uint16_t n_stages;
    uint32_t n_ticks;        /**< ticks in the whole plan */
    uint32_t tick_hz;        /**< controller rate */
    const uint32_t *stage_start; /**< [n_stages + 1]: first tick of each stage, then n_ticks */
    const uint16_t *stage_np;    /**< [n_stages]: multipliers latched at each stage start
                                      (0: keep the v latched before) */
    const stsp_f32_t *K;
    const stsp_f32_t *k0;
    const stsp_f32_t *L;
    const stsp_f32_t *Lambda;
    const stsp_f32_t *lambda0;
    uint32_t crc32;              /**< CRC-32 of dims and arrays, see stsp_table_crc32() */
    uint8_t problem_sha256[32];  /**< hash of the problem file the tables came from */
} stsp_table_t;

/** One controller instance; caller-owned, several may run at once (re-entrant). */
typedef struct {
    const stsp_table_t *table;
    uint32_t ready;          /**< STSP_TABLE_MAGIC after a successful init */
    uint32_t next_tick;      /**< tick expected at the next step */
    uint16_t stage;          /**< stage of the last successful step */
    uint16_t latched;        /**< nonzero once v holds a latch for `stage` */
    stsp_f32_t v[STSP_MAX_LATCH];
} stsp_ctrl_t;

/**
 * CRC-32 (IEEE 802.3 polynomial, reflected, as zlib) of the table's canonical serialization:
 * nx, nu, n_latch, n_stages, n_ticks, tick_hz as little-endian u32; stage_start and stage_np
 * as little-endian u32 each; then K, k0, L, Lambda, lambda0 as little-endian binary32 bit
 * patterns. Independent of the target's byte order. The table's dimensions must already be
 * valid (stsp_init() checks them first).
 */
uint32_t stsp_table_crc32(const stsp_table_t *table);

/**
 * Bind a table to an instance after verifying its header, dimensions and CRC.
 * On any error the instance is left not ready (every step returns STSP_ERR_NOT_INITIALIZED).
 */
stsp_status_t stsp_init(stsp_ctrl_t *ctrl, const stsp_table_t *table);

/** Restart the plan at tick 0 (the next step latches stage 0 again). */
stsp_status_t stsp_reset(stsp_ctrl_t *ctrl);

/**
 * Compute the command for tick `tick` from the measured state x[nx]; writes u[nu].
 * On a negative status u is all zeros (the documented safe hold value) and the instance is
 * unchanged; otherwise u is finite. Exceptions: with u == NULL nothing is written, and before
 * a successful init (STSP_ERR_NOT_INITIALIZED) u is not written because nu is unknown.
 */
stsp_status_t stsp_step(stsp_ctrl_t *ctrl, uint32_t tick, const stsp_f32_t *x, stsp_f32_t *u);

#ifdef STSP_HOST_MESSAGES
/** Human-readable text of a status (host builds only). */
const char *stsp_status_str(stsp_status_t status);
#endif

#ifdef __cplusplus
}
#endif

#endif /* STSP_CONTROLLER_H */
