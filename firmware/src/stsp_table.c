/* Table validation and serialisation: the checks stsp_init() makes on the header copy
 * (dimensions, layout, values of the configured arithmetic), the header comparison of
 * stsp_verify(), and the CRC-32 over the table's canonical serialisation (stsp_table_crc32,
 * byte order in docs/guide/firmware.md). Cold code: none of it runs on an ordinary tick. */
#include "stsp_internal.h"

#include <float.h>

#include "stsp_crc32.h"

/* The header fields every later call uses, read once (init, and stsp_table_crc32). */
void stsp_copy_header(stsp_header_t *h, const stsp_table_t *t)
{
    (void)memset(h, 0, sizeof *h);
    h->K = t->K;
    h->k0 = t->k0;
    h->L = t->L;
    h->u_min = t->u_min;
    h->u_max = t->u_max;
    h->u_hold = t->u_hold;
    h->Lambda = t->Lambda;
    h->lambda0 = t->lambda0;
    h->stage_start = t->stage_start;
    h->stage_n_latch = t->stage_n_latch;
#ifdef STSP_ARITH_FIXED_POINT
    h->x_exp = t->x_exp;
    h->u_exp = t->u_exp;
    h->v_exp = t->v_exp;
#else
    h->band_qp = t->band_qp;
    if (t->band_qp != NULL) {
        h->band = *t->band_qp;
    }
#endif
    h->spline = t->spline;
    if (t->spline != NULL) {
        h->sp = *t->spline;
    }
    h->n_ticks = t->n_ticks;
    h->nx = t->nx;
    h->nu = t->nu;
    h->n_latch = t->n_latch;
    h->n_stages = t->n_stages;
}

/* 1 if the table header differs from the validated copy in anything a later call relies on
 * (reads only the header structs, never an array). */
int stsp_header_changed(const stsp_header_t *h, const stsp_table_t *t)
{
    int changed = 0;
    if ((t->magic != STSP_TABLE_MAGIC) || (t->format_version != STSP_FORMAT_VERSION) ||
        (t->scalar_kind != STSP_SCALAR_KIND) || (t->nx != h->nx) || (t->nu != h->nu) ||
        (t->n_latch != h->n_latch) || (t->n_stages != h->n_stages) ||
        (t->n_ticks != h->n_ticks)) {
        changed = 1;
    }
    if ((t->K != h->K) || (t->k0 != h->k0) || (t->L != h->L) || (t->u_min != h->u_min) ||
        (t->u_max != h->u_max) || (t->u_hold != h->u_hold) || (t->Lambda != h->Lambda) ||
        (t->lambda0 != h->lambda0) ||
        (t->stage_start != h->stage_start) || (t->stage_n_latch != h->stage_n_latch)) {
        changed = 1;
    }
#ifdef STSP_ARITH_FIXED_POINT
    if ((t->x_exp != h->x_exp) || (t->u_exp != h->u_exp) || (t->v_exp != h->v_exp) ||
        (t->band_qp != NULL)) {
        changed = 1;
    }
    if (t->spline != h->spline) {
        changed = 1;
    } else if (t->spline != NULL) {
        const stsp_qspline_t *p = t->spline;
        const stsp_qspline_t *q = &h->sp;
        if ((p->n_entries != q->n_entries) || (p->n_coef != q->n_coef) ||
            (p->span_log2 != q->span_log2) || (p->row_start != q->row_start) ||
            (p->col != q->col) || (p->shift != q->shift) || (p->coef_start != q->coef_start) ||
            (p->coef != q->coef) || (p->ops != q->ops)) {
            changed = 1;
        }
    } else {
        /* gains per tick, as validated */
    }
#else
    if (t->band_qp != h->band_qp) {
        changed = 1;
    } else if (t->band_qp != NULL) {
        const stsp_bandqp_t *b = t->band_qp;
        if ((b->q != h->band.q) || (b->nx != h->band.nx) || (b->Nt != h->band.Nt) ||
            (b->mt != h->band.mt) || (b->W != h->band.W) || (b->lo != h->band.lo) ||
            (b->hi != h->band.hi) || (b->solve_f32 != h->band.solve_f32)) {
            changed = 1;
        }
    } else {
        /* no band dual, as validated */
    }
    if (t->spline != h->spline) {
        changed = 1;
    } else if (t->spline != NULL) {
        const stsp_spline_t *p = t->spline;
        const stsp_spline_t *q = &h->sp;
        if ((p->n_knots != q->n_knots) || (p->n_entries != q->n_entries) ||
            (p->n_coef != q->n_coef) || (p->knot_start != q->knot_start) ||
            (p->knot != q->knot) || (p->row_start != q->row_start) || (p->col != q->col) ||
            (p->coef_start != q->coef_start) || (p->coef != q->coef) || (p->ops != q->ops)) {
            changed = 1;
        }
    } else {
        /* gains per tick, as validated */
    }
#endif
    return changed;
}

#ifndef STSP_ARITH_FIXED_POINT
/* A band dual belongs to a joint design: q rows, all latched once at stage 0. */
static stsp_status_t stsp_check_band_dims(const stsp_header_t *h)
{
    const stsp_bandqp_t *b = &h->band;
    uint32_t s;
    if (b->solve_f32 == NULL) {
        return STSP_ERR_BAD_DIMS; /* the table does not link the solver: stsp_internal.h */
    }
    if ((b->Nt == NULL) || (b->mt == NULL) || (b->W == NULL) || (b->lo == NULL) ||
        (b->hi == NULL)) {
        return STSP_ERR_NULL;
    }
    if ((b->q == 0u) || (b->q > STSP_BANDQP_MAX) || (b->nx != h->nx) ||
        (b->q != h->stage_n_latch[0])) {
        return STSP_ERR_BAD_DIMS;
    }
    for (s = 1u; s < h->n_stages; ++s) {
        if (h->stage_n_latch[s] != 0u) {
            return STSP_ERR_BAD_DIMS;
        }
    }
    return STSP_OK;
}
#endif

/* The copy's dimensions and layout (tick_hz and the band and spline pointers come from the
 * header: scalars read once). */
static stsp_status_t stsp_check_dims(const stsp_header_t *t, uint32_t tick_hz, int has_band,
                                     int has_spline)
{
    uint32_t s;
    if ((t->nx == 0u) || (t->nx > STSP_MAX_NX) || (t->nu == 0u) || (t->nu > STSP_MAX_NU) ||
        (t->n_latch > STSP_MAX_LATCH) || (t->n_stages == 0u) ||
        (t->n_stages > STSP_MAX_STAGES) || (t->n_ticks == 0u) || (tick_hz == 0u)) {
        return STSP_ERR_BAD_DIMS;
    }
#ifdef STSP_FIXED_NX
    if ((t->nx != STSP_FIXED_NX) || (t->nu != STSP_FIXED_NU) ||
        (t->n_latch != STSP_FIXED_N_LATCH)) {
        return STSP_ERR_BAD_DIMS;
    }
#endif
    /* A spline table's gains are the splines': no per-tick arrays. It may carry a band dual
     * (then the W re-solved for the spline's gains, stsp_bandqp.h). */
    if ((has_spline != 0) && ((t->K != NULL) || (t->k0 != NULL) || (t->L != NULL))) {
        return STSP_ERR_BAD_DIMS;
    }
    /* Every per-tick offset is computed in uint32_t: the largest array must stay addressable. */
    if ((has_spline == 0) &&
        (t->n_ticks > (UINT32_MAX / ((uint32_t)t->nu * ((uint32_t)t->nx + t->n_latch))))) {
        return STSP_ERR_BAD_DIMS;
    }
    if ((t->stage_start == NULL) || (t->stage_n_latch == NULL) || (t->u_min == NULL) ||
        (t->u_max == NULL) || (t->u_hold == NULL) ||
        ((has_spline == 0) && ((t->K == NULL) || (t->k0 == NULL) ||
                               ((t->n_latch > 0u) && (t->L == NULL)))) ||
        ((t->n_latch > 0u) && ((t->Lambda == NULL) || (t->lambda0 == NULL)))) {
        return STSP_ERR_NULL;
    }
#ifdef STSP_ARITH_FIXED_POINT
    if ((t->x_exp == NULL) || (t->u_exp == NULL) || ((t->n_latch > 0u) && (t->v_exp == NULL))) {
        return STSP_ERR_NULL;
    }
#endif
    if ((t->stage_start[0] != 0u) || (t->stage_start[t->n_stages] != t->n_ticks)) {
        return STSP_ERR_BAD_DIMS;
    }
    for (s = 0u; s < t->n_stages; ++s) {
        if ((t->stage_start[s + 1u] <= t->stage_start[s]) || (t->stage_n_latch[s] > t->n_latch)) {
            return STSP_ERR_BAD_DIMS;
        }
    }
#ifdef STSP_ARITH_FIXED_POINT
    /* The band solver latches binary32 multipliers: float32 tables only. */
    if (has_band != 0) {
        return STSP_ERR_BAD_DIMS;
    }
#endif
    if (has_spline != 0) {
        if (stsp_spline_code_ok(t->sp.ops) == 0) {
            return STSP_ERR_BAD_DIMS; /* the table does not link its code: stsp_internal.h */
        }
        {
            const stsp_status_t st = t->sp.ops->check_dims(t);
#ifdef STSP_ARITH_FIXED_POINT
            return st; /* no band dual in a fixed-point build (refused above) */
#else
            if ((st != STSP_OK) || (has_band == 0)) {
                return st;
            }
#endif
        }
    }
#ifdef STSP_ARITH_FIXED_POINT
    return STSP_OK;
#else
    return (has_band != 0) ? stsp_check_band_dims(t) : STSP_OK;
#endif
}

#ifdef STSP_ARITH_FIXED_POINT
/* Fixed point: exponents in range; every law row (tick, input) with
 * |k0| + sum_j |K| + sum_c |L| <= 2^F - 1 and every latch row with |lambda0| + sum_j |Lambda|
 * <= 2^F - 1, the condition under which stsp_law and the latch cannot overflow or leave the
 * Q range (stsp_step); limits with u_min <= u_hold <= u_max. A spline table's law rows are its
 * gains as evaluated at each tick (stsp_spline_ops.check_values, stsp_spline.c: linked, as its
 * layout check passed). */
static stsp_status_t stsp_check_values(const stsp_header_t *t)
{
    const stsp_uacc_t row_max = (stsp_uacc_t)STSP_Q_ONE - 1u;
    const uint32_t nx = t->nx;
    const uint32_t nu = t->nu;
    const uint32_t n_latch = t->n_latch;
    uint32_t r;
    if ((stsp_q_exps_ok(t->x_exp, nx) == 0) || (stsp_q_exps_ok(t->u_exp, nu) == 0) ||
        ((n_latch > 0u) && (stsp_q_exps_ok(t->v_exp, n_latch) == 0))) {
        return STSP_ERR_BAD_VALUES;
    }
    if (t->spline != NULL) {
        const stsp_status_t st = t->sp.ops->check_values(t);
        if (st != STSP_OK) {
            return st;
        }
    }
    for (r = 0u; (t->spline == NULL) && (r < (t->n_ticks * nu)); ++r) {
        stsp_uacc_t sum = stsp_q_abs_sum(&t->k0[r], 1u) + stsp_q_abs_sum(&t->K[r * nx], nx);
        if (n_latch > 0u) {
            sum += stsp_q_abs_sum(&t->L[r * n_latch], n_latch);
        }
        if (sum > row_max) {
            return STSP_ERR_BAD_VALUES;
        }
    }
    for (r = 0u; r < ((uint32_t)t->n_stages * n_latch); ++r) {
        if ((stsp_q_abs_sum(&t->lambda0[r], 1u) + stsp_q_abs_sum(&t->Lambda[r * nx], nx)) >
            row_max) {
            return STSP_ERR_BAD_VALUES;
        }
    }
    for (r = 0u; r < nu; ++r) {
        if ((t->u_min[r] > t->u_hold[r]) || (t->u_max[r] < t->u_hold[r])) {
            return STSP_ERR_BAD_VALUES;
        }
    }
    return STSP_OK;
}

/* 1 if some input has a limit narrower than the Q range [-2^F, 2^F - 1]. */
uint16_t stsp_has_limits(const stsp_header_t *t)
{
    uint32_t i;
    for (i = 0u; i < t->nu; ++i) {
        if (((stsp_acc_t)t->u_min[i] > -STSP_Q_ONE) ||
            ((stsp_acc_t)t->u_max[i] < (STSP_Q_ONE - 1))) {
            return 1u;
        }
    }
    return 0u;
}
#else
/* A key of a finite binary64 whose integer order is the numeric order (-0 and +0 equal):
 * lo <= hi without a double-precision compare, which on a core without a double-precision
 * FPU would link the soft-float comparison routines into every program (the band solver's
 * own are linked only with a band table, stsp_internal.h). */
static int64_t stsp_f64_order(const double *value)
{
    uint64_t bits;
    uint64_t magnitude_bits;
    int64_t magnitude;
    (void)memcpy(&bits, value, sizeof bits);
    magnitude_bits = bits & 0x7FFFFFFFFFFFFFFFu;
    magnitude = (int64_t)magnitude_bits;
    return ((bits >> 63) != 0u) ? -magnitude : magnitude;
}

/* Band dual data finite and every band ordered (lo <= hi; lo == hi is an equality row). */
static stsp_status_t stsp_check_band_values(const stsp_bandqp_t *b)
{
    const uint32_t q = b->q;
    uint32_t i;
    if ((stsp_all_finite_f64(b->Nt, q * (uint32_t)b->nx) == 0) ||
        (stsp_all_finite_f64(b->mt, q) == 0) || (stsp_all_finite_f64(b->W, q * q) == 0) ||
        (stsp_all_finite_f64(b->lo, q) == 0) || (stsp_all_finite_f64(b->hi, q) == 0)) {
        return STSP_ERR_BAD_VALUES;
    }
    for (i = 0u; i < q; ++i) {
        if (stsp_f64_order(&b->lo[i]) > stsp_f64_order(&b->hi[i])) {
            return STSP_ERR_BAD_VALUES;
        }
    }
    return STSP_OK;
}

/* Gains (per tick, or the spline coefficients) finite; limits and the safe command finite,
 * with u_min <= u_hold <= u_max; band data finite and ordered. */
static stsp_status_t stsp_check_values(const stsp_header_t *t)
{
    const uint32_t nx = t->nx;
    const uint32_t nu = t->nu;
    const uint32_t n_latch = t->n_latch;
    const uint32_t ns = t->n_stages;
    const uint32_t nt = t->n_ticks;
    uint32_t i;
    if (t->spline != NULL) {
        if (stsp_all_finite(t->sp.coef, t->sp.n_coef) == 0) {
            return STSP_ERR_BAD_VALUES;
        }
    } else if ((stsp_all_finite(t->K, nt * nu * nx) == 0) ||
               (stsp_all_finite(t->k0, nt * nu) == 0) ||
               ((n_latch > 0u) && (stsp_all_finite(t->L, nt * nu * n_latch) == 0))) {
        return STSP_ERR_BAD_VALUES;
    } else {
        /* finite gains per tick */
    }
    if ((n_latch > 0u) && ((stsp_all_finite(t->Lambda, ns * n_latch * nx) == 0) ||
                           (stsp_all_finite(t->lambda0, ns * n_latch) == 0))) {
        return STSP_ERR_BAD_VALUES;
    }
    for (i = 0u; i < nu; ++i) {
        const stsp_f32_t lo = t->u_min[i];
        const stsp_f32_t hi = t->u_max[i];
        const stsp_f32_t hold = t->u_hold[i];
        if ((stsp_isfinite_f32(lo) == 0) || (stsp_isfinite_f32(hi) == 0) ||
            (stsp_isfinite_f32(hold) == 0) || !(lo <= hold) || !(hi >= hold)) {
            return STSP_ERR_BAD_VALUES;
        }
    }
    return (t->band_qp != NULL) ? stsp_check_band_values(&t->band) : STSP_OK;
}

/* 1 if some input has a limit other than -FLT_MAX/FLT_MAX (selects the fast-path check). */
uint16_t stsp_has_limits(const stsp_header_t *t)
{
    uint32_t i;
    for (i = 0u; i < t->nu; ++i) {
        if ((t->u_min[i] > -FLT_MAX) || (t->u_max[i] < FLT_MAX)) {
            return 1u;
        }
    }
    return 0u;
}
#endif /* STSP_ARITH_FIXED_POINT */


/* The CRC of stsp_table_crc32(), with the dimensions and arrays of the header copy `table`
 * and the remaining scalars (tick_hz, scalar_kind, problem_sha256) of the table header. */
uint32_t stsp_crc_of(const stsp_header_t *table, const stsp_table_t *scalars)
{
#ifdef STSP_ARITH_FIXED_POINT
    /* Only stsp_table_crc32() of a table init would refuse can have a band dual here. */
    const stsp_bandqp_t *b = scalars->band_qp;
#else
    const stsp_bandqp_t *b = (table->band_qp != NULL) ? &table->band : NULL;
#endif
    const stsp_spline_gains_t *sp = (table->spline != NULL) ? &table->sp : NULL;
    const uint32_t nx = table->nx;
    const uint32_t nu = table->nu;
    const uint32_t n_latch = table->n_latch;
    const uint32_t ns = table->n_stages;
    const uint32_t nt = table->n_ticks;
    uint32_t crc = stsp_crc32_begin();
    uint32_t s;
    crc = stsp_crc32_u32(crc, nx);
    crc = stsp_crc32_u32(crc, nu);
    crc = stsp_crc32_u32(crc, n_latch);
    crc = stsp_crc32_u32(crc, ns);
    crc = stsp_crc32_u32(crc, nt);
    crc = stsp_crc32_u32(crc, scalars->tick_hz);
#ifdef STSP_ARITH_FIXED_POINT
    crc = stsp_crc32_u32(crc, (uint32_t)scalars->scalar_kind);
#endif
    for (s = 0u; s <= ns; ++s) {
        crc = stsp_crc32_u32(crc, table->stage_start[s]);
    }
    for (s = 0u; s < ns; ++s) {
        crc = stsp_crc32_u32(crc, (uint32_t)table->stage_n_latch[s]);
    }
    if (sp == NULL) {
        crc = stsp_crc32_scalars(crc, table->K, nt * nu * nx);
        crc = stsp_crc32_scalars(crc, table->k0, nt * nu);
    }
    if (n_latch > 0u) {
        if (sp == NULL) {
            crc = stsp_crc32_scalars(crc, table->L, nt * nu * n_latch);
        }
        crc = stsp_crc32_scalars(crc, table->Lambda, ns * n_latch * nx);
        crc = stsp_crc32_scalars(crc, table->lambda0, ns * n_latch);
    }
    crc = stsp_crc32_scalars(crc, table->u_min, nu);
    crc = stsp_crc32_scalars(crc, table->u_max, nu);
    crc = stsp_crc32_scalars(crc, table->u_hold, nu);
#ifdef STSP_ARITH_FIXED_POINT
    crc = stsp_crc32_i8s(crc, table->x_exp, nx);
    crc = stsp_crc32_i8s(crc, table->u_exp, nu);
    if (n_latch > 0u) {
        crc = stsp_crc32_i8s(crc, table->v_exp, n_latch);
    }
#endif
    /* In stsp_spline.c, reached through the table (stsp_internal.h): init refuses a spline
     * table without its code before the CRC, and stsp_table_crc32() leaves the spline out. */
    if ((sp != NULL) && (stsp_spline_code_ok(sp->ops) != 0)) {
        crc = sp->ops->crc(crc, sp, ns, nu);
    }
    if (b != NULL) {
        const uint32_t q = b->q;
        crc = stsp_crc32_u32(crc, q);
        crc = stsp_crc32_u32(crc, (uint32_t)b->nx);
        crc = stsp_crc32_f64s(crc, b->Nt, q * (uint32_t)b->nx);
        crc = stsp_crc32_f64s(crc, b->mt, q);
        crc = stsp_crc32_f64s(crc, b->W, q * q);
        crc = stsp_crc32_f64s(crc, b->lo, q);
        crc = stsp_crc32_f64s(crc, b->hi, q);
    }
    crc = stsp_crc32_bytes(crc, scalars->problem_sha256,
                           (uint32_t)sizeof scalars->problem_sha256);
    return stsp_crc32_end(crc);
}

uint32_t stsp_table_crc32(const stsp_table_t *table)
{
    stsp_header_t h;
    stsp_copy_header(&h, table);
    return stsp_crc_of(&h, table);
}

/* The checks of stsp_init() on the header copy h, read once from `table`. */
stsp_status_t stsp_check_table(const stsp_header_t *h, const stsp_table_t *table)
{
    stsp_status_t st = stsp_check_dims(h, table->tick_hz, (table->band_qp != NULL) ? 1 : 0,
                                       (table->spline != NULL) ? 1 : 0);
    if (st != STSP_OK) {
        return st;
    }
    if (stsp_crc_of(h, table) != table->crc32) {
        return STSP_ERR_BAD_CRC;
    }
    return stsp_check_values(h);
}
