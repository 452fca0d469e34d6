/* Latched time-varying affine controller: see stospline/stsp_controller.h for the contract. */
#include "stospline/stsp_controller.h"

#include <string.h>

#include "stsp_crc32.h"

/* A binary32 is finite unless its exponent bits are all ones (NaN, +-Inf). Checked on the bit
 * pattern so that -ffast-math cannot optimise the test away. */
static inline int stsp_isfinite_f32(stsp_f32_t value)
{
    uint32_t bits;
    (void)memcpy(&bits, &value, sizeof bits);
    return (bits & 0x7F800000u) != 0x7F800000u;
}

static inline void stsp_zero(stsp_f32_t *u, uint32_t count)
{
    uint32_t i;
    for (i = 0u; i < count; ++i) {
        u[i] = 0.0f;
    }
}

static stsp_status_t stsp_check_dims(const stsp_table_t *t)
{
    uint32_t s;
    if (t->nx == 0u || t->nx > STSP_MAX_NX || t->nu == 0u || t->nu > STSP_MAX_NU ||
        t->n_latch > STSP_MAX_LATCH || t->n_stages == 0u || t->n_stages > STSP_MAX_STAGES ||
        t->n_ticks == 0u || t->tick_hz == 0u) {
        return STSP_ERR_BAD_DIMS;
    }
    /* Every table offset is computed in uint32_t: the largest array must stay addressable. */
    if (t->n_ticks > UINT32_MAX / ((uint32_t)t->nu * (uint32_t)(t->nx + t->n_latch))) {
        return STSP_ERR_BAD_DIMS;
    }
    if (t->stage_start == NULL || t->stage_np == NULL || t->K == NULL || t->k0 == NULL ||
        (t->n_latch > 0u && (t->L == NULL || t->Lambda == NULL || t->lambda0 == NULL))) {
        return STSP_ERR_NULL;
    }
    if (t->stage_start[0] != 0u || t->stage_start[t->n_stages] != t->n_ticks) {
        return STSP_ERR_BAD_DIMS;
    }
    for (s = 0u; s < t->n_stages; ++s) {
        if (t->stage_start[s + 1u] <= t->stage_start[s] || t->stage_np[s] > t->n_latch) {
            return STSP_ERR_BAD_DIMS;
        }
    }
    return STSP_OK;
}

uint32_t stsp_table_crc32(const stsp_table_t *t)
{
    uint32_t crc = stsp_crc32_begin();
    const uint32_t nx = t->nx, nu = t->nu, np = t->n_latch, ns = t->n_stages, nt = t->n_ticks;
    uint32_t s;
    crc = stsp_crc32_u32(crc, nx);
    crc = stsp_crc32_u32(crc, nu);
    crc = stsp_crc32_u32(crc, np);
    crc = stsp_crc32_u32(crc, ns);
    crc = stsp_crc32_u32(crc, nt);
    crc = stsp_crc32_u32(crc, t->tick_hz);
    for (s = 0u; s <= ns; ++s) {
        crc = stsp_crc32_u32(crc, t->stage_start[s]);
    }
    for (s = 0u; s < ns; ++s) {
        crc = stsp_crc32_u32(crc, (uint32_t)t->stage_np[s]);
    }
    crc = stsp_crc32_f32s(crc, t->K, nt * nu * nx);
    crc = stsp_crc32_f32s(crc, t->k0, nt * nu);
    if (np > 0u) {
        crc = stsp_crc32_f32s(crc, t->L, nt * nu * np);
        crc = stsp_crc32_f32s(crc, t->Lambda, ns * np * nx);
        crc = stsp_crc32_f32s(crc, t->lambda0, ns * np);
    }
    return stsp_crc32_end(crc);
}

stsp_status_t stsp_init(stsp_ctrl_t *ctrl, const stsp_table_t *table)
{
    stsp_status_t st;
    if (ctrl == NULL) {
        return STSP_ERR_NULL;
    }
    (void)memset(ctrl, 0, sizeof *ctrl);
    if (table == NULL) {
        return STSP_ERR_NULL;
    }
    if (table->magic != STSP_TABLE_MAGIC) {
        return STSP_ERR_BAD_MAGIC;
    }
    if (table->format_version != STSP_FORMAT_VERSION ||
        table->scalar_kind != STSP_SCALAR_FLOAT32) {
        return STSP_ERR_BAD_VERSION;
    }
    st = stsp_check_dims(table);
    if (st != STSP_OK) {
        return st;
    }
    if (stsp_table_crc32(table) != table->crc32) {
        return STSP_ERR_BAD_CRC;
    }
    ctrl->table = table;
    ctrl->ready = STSP_TABLE_MAGIC;
    return STSP_OK;
}

stsp_status_t stsp_reset(stsp_ctrl_t *ctrl)
{
    if (ctrl == NULL) {
        return STSP_ERR_NULL;
    }
    if (ctrl->ready != STSP_TABLE_MAGIC) {
        return STSP_ERR_NOT_INITIALIZED;
    }
    ctrl->next_tick = 0u;
    ctrl->stage = 0u;
    ctrl->latched = 0u;
    stsp_zero(ctrl->v, STSP_MAX_LATCH);
    return STSP_OK;
}

/* Stage containing `tick`, searching forward from `from` (ticks only move forward). */
static uint16_t stsp_stage_of(const stsp_table_t *t, uint16_t from, uint32_t tick)
{
    uint16_t s = from;
    while (s + 1u < t->n_stages && t->stage_start[s + 1u] <= tick) {
        ++s;
    }
    return s;
}

stsp_status_t stsp_step(stsp_ctrl_t *ctrl, uint32_t tick, const stsp_f32_t *x, stsp_f32_t *u)
{
    const stsp_table_t *t;
    stsp_status_t status = STSP_OK;
    stsp_f32_t v_new[STSP_MAX_LATCH];
    const stsp_f32_t *v = NULL;
    uint32_t i, j, nx, nu, np;
    uint16_t stage;
    int relatch;

    if (u == NULL || ctrl == NULL) {
        return STSP_ERR_NULL;
    }
    if (ctrl->ready != STSP_TABLE_MAGIC || ctrl->table == NULL) {
        return STSP_ERR_NOT_INITIALIZED; /* nu is unknown without a table: u is not written */
    }
    t = ctrl->table;
    nx = t->nx;
    nu = t->nu;
    stsp_zero(u, nu);
    if (x == NULL) {
        return STSP_ERR_NULL;
    }
    if (tick >= t->n_ticks) {
        return STSP_ERR_TICK_RANGE;
    }
    if (ctrl->next_tick > 0u && tick + 1u < ctrl->next_tick) {
        return STSP_ERR_TICK_ORDER;
    }
    for (j = 0u; j < nx; ++j) {
        if (!stsp_isfinite_f32(x[j])) {
            return STSP_ERR_NONFINITE_STATE;
        }
    }
    if (ctrl->next_tick > 0u && tick + 1u == ctrl->next_tick) {
        status = STSP_WARN_TICK_REPEATED;
    } else if (tick > ctrl->next_tick) {
        status = STSP_WARN_TICK_SKIPPED;
    }

    stage = stsp_stage_of(t, ctrl->stage, tick);
    /* A stage with stage_np > 0 latches a fresh v at its first tick; one with stage_np == 0
     * keeps the v latched earlier (joint multipliers are latched once, at stage 0). */
    np = t->stage_np[stage];
    relatch = (ctrl->latched == 0u) || (stage != ctrl->stage && np > 0u);
    if (relatch) {
        /* v = Lambda x + lambda0, into a scratch copy: the instance changes only on success. */
        const stsp_f32_t *lam = t->Lambda + (uint32_t)stage * t->n_latch * nx;
        for (i = 0u; i < t->n_latch; ++i) {
            stsp_f32_t acc = 0.0f;
            if (i < np) {
                acc = t->lambda0[(uint32_t)stage * t->n_latch + i];
                for (j = 0u; j < nx; ++j) {
                    acc += lam[i * nx + j] * x[j];
                }
                if (!stsp_isfinite_f32(acc)) {
                    return STSP_ERR_NONFINITE_OUTPUT;
                }
            }
            v_new[i] = acc;
        }
        v = v_new;
    } else {
        v = ctrl->v;
    }

    {
        const stsp_f32_t *K = t->K + tick * nu * nx;
        const stsp_f32_t *k0 = t->k0 + tick * nu;
        const stsp_f32_t *L = t->L + tick * nu * t->n_latch;
        for (i = 0u; i < nu; ++i) {
            stsp_f32_t acc = k0[i];
            for (j = 0u; j < nx; ++j) {
                acc += K[i * nx + j] * x[j];
            }
            for (j = 0u; j < t->n_latch; ++j) {
                acc += L[i * t->n_latch + j] * v[j];
            }
            if (!stsp_isfinite_f32(acc)) {
                stsp_zero(u, nu);
                return STSP_ERR_NONFINITE_OUTPUT;
            }
            u[i] = -acc;
        }
    }

    if (relatch) {
        for (i = 0u; i < t->n_latch; ++i) {
            ctrl->v[i] = v_new[i];
        }
        ctrl->latched = 1u;
    }
    ctrl->stage = stage;
    if (tick + 1u > ctrl->next_tick) {
        ctrl->next_tick = tick + 1u;
    }
    return status;
}

#ifdef STSP_HOST_MESSAGES
const char *stsp_status_str(stsp_status_t status)
{
    switch (status) {
    case STSP_OK: return "ok";
    case STSP_WARN_TICK_SKIPPED: return "tick skipped: evaluated at the given tick";
    case STSP_WARN_TICK_REPEATED: return "tick repeated: recomputed without a new latch";
    case STSP_ERR_NULL: return "null pointer argument";
    case STSP_ERR_NOT_INITIALIZED: return "controller not initialized";
    case STSP_ERR_BAD_MAGIC: return "table magic mismatch";
    case STSP_ERR_BAD_VERSION: return "table format or scalar variant not supported";
    case STSP_ERR_BAD_DIMS: return "table dimensions invalid";
    case STSP_ERR_BAD_CRC: return "table CRC mismatch";
    case STSP_ERR_TICK_RANGE: return "tick beyond the end of the table";
    case STSP_ERR_TICK_ORDER: return "tick went backwards";
    case STSP_ERR_NONFINITE_STATE: return "state not finite";
    case STSP_ERR_NONFINITE_OUTPUT: return "command overflowed";
    default: return "unknown status";
    }
}
#endif
