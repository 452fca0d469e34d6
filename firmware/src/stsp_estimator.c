/* The controller on a sensor: see stospline/stsp_estimator.h for the contract. The filter
 * (update, predict) is here; the law and the latch are stsp_step()'s, on the estimate. Every
 * tick works on local copies and commits only when the law succeeded, so a refused step leaves
 * the instance as it was. One source for float32, Q15 and Q31: the arithmetic of the filter's
 * rows and the checks of the table's values differ (STSP_ARITH_FIXED_POINT), the rest is
 * shared. */
#include "stospline/stsp_types.h"
#include "stospline/stsp_estimator.h"
#include "stsp_crc32.h"
#include "stsp_internal.h"
#ifndef STSP_ARITH_FIXED_POINT
#include "stsp_f32bits.h"
#include "stsp_knots.h"
#endif

#include <string.h>

#define STSP_EST_READY 0x45005300u
#define STSP_EST_STOPPED 0x45015301u

static uint32_t stsp_est_samples(const stsp_est_table_t *e)
{
    return (e->n_ticks / e->every) + (((e->n_ticks % e->every) != 0u) ? 1u : 0u);
}

static uint32_t stsp_est_models(const stsp_est_table_t *e)
{
    return e->model_start[e->n_stages];
}

static uint32_t stsp_est_row(const stsp_est_table_t *e)
{
    return (uint32_t)e->nx + (uint32_t)e->nu + 1u;
}

uint32_t stsp_est_table_crc32(const stsp_est_table_t *est)
{
    const uint32_t nx = est->nx;
    uint32_t crc = stsp_crc32_begin();
    crc = stsp_crc32_u32(crc, nx);
    crc = stsp_crc32_u32(crc, est->nu);
    crc = stsp_crc32_u32(crc, est->ny);
    crc = stsp_crc32_u32(crc, est->n_stages);
    crc = stsp_crc32_u32(crc, est->n_ticks);
    crc = stsp_crc32_u32(crc, est->every);
    crc = stsp_crc32_u32(crc, stsp_est_models(est));
    crc = stsp_crc32_u32s(crc, est->model_start, (uint32_t)est->n_stages + 1u);
    crc = stsp_crc32_scalars(crc, est->model, stsp_est_models(est) * nx * stsp_est_row(est));
    crc = stsp_crc32_scalars(crc, est->C, (uint32_t)est->ny * nx);
    if (est->gain != NULL) { /* NULL: the gains are a spline (stsp_est_init_spline()) */
        crc = stsp_crc32_scalars(crc, est->gain, stsp_est_samples(est) * nx * est->ny);
    }
    crc = stsp_crc32_scalars(crc, est->xhat0, nx);
#ifdef STSP_ARITH_FIXED_POINT
    crc = stsp_crc32_i8s(crc, est->y_exp, est->ny);
    crc = stsp_crc32_i8s(crc, est->e_exp, est->ny);
    crc = stsp_crc32_bytes(crc, est->shift, (uint32_t)est->ny + (2u * nx));
#endif
    crc = stsp_crc32_bytes(crc, est->problem_sha256, 32u);
    return stsp_crc32_end(crc);
}

#ifndef STSP_ARITH_FIXED_POINT
static int stsp_est_finite(const stsp_f32_t *a, uint32_t count)
{
    uint32_t i;
    for (i = 0u; i < count; ++i) {
        if (stsp_isfinite_f32(a[i]) == 0) {
            return 0;
        }
    }
    return 1;
}
#endif

/* The estimator table against the validated gain table (h): everything but the CRC. Its
 * gain is NULL exactly when the gains are a spline (`spline` 1). */
static stsp_status_t stsp_est_check(const stsp_est_table_t *e, const stsp_header_t *h,
                                    int spline)
{
    uint32_t s;
    if ((e->model_start == NULL) || (e->model == NULL) || (e->C == NULL) ||
        ((e->gain == NULL) && (spline == 0)) || (e->xhat0 == NULL)) {
        return STSP_ERR_NULL;
    }
#ifdef STSP_ARITH_FIXED_POINT
    if ((e->y_exp == NULL) || (e->e_exp == NULL) || (e->shift == NULL)) {
        return STSP_ERR_NULL;
    }
#endif
    if (e->magic != STSP_EST_MAGIC) {
        return STSP_ERR_BAD_MAGIC;
    }
    if ((e->format_version != STSP_EST_FORMAT_VERSION) ||
        (e->scalar_kind != STSP_SCALAR_KIND)) {
        return STSP_ERR_BAD_VERSION;
    }
    if ((e->nx != h->nx) || (e->nu != h->nu) || (e->n_stages != h->n_stages) ||
        (e->n_ticks != h->n_ticks) || (e->ny == 0u) || (e->ny > STSP_MAX_NY) ||
        (e->every == 0u) || (e->model_start[0] != 0u) || ((e->gain != NULL) && (spline != 0))) {
        return STSP_ERR_BAD_DIMS;
    }
    for (s = 0u; s < e->n_stages; ++s) {
        const uint32_t maps = e->model_start[s + 1u] - e->model_start[s];
        const uint32_t ticks = h->stage_start[s + 1u] - h->stage_start[s];
        if ((e->model_start[s + 1u] < e->model_start[s]) || ((maps != 1u) && (maps != ticks))) {
            return STSP_ERR_BAD_DIMS;
        }
    }
    return STSP_OK;
}

#ifndef STSP_ARITH_FIXED_POINT
static int stsp_est_values_ok(const stsp_est_table_t *e)
{
    const uint32_t nx = e->nx;
    return stsp_est_finite(e->model, stsp_est_models(e) * nx * stsp_est_row(e)) &
           ((e->gain == NULL) ? 1 : stsp_est_finite(e->gain, stsp_est_samples(e) * nx * e->ny)) &
           stsp_est_finite(e->C, (uint32_t)e->ny * nx) & stsp_est_finite(e->xhat0, nx);
}
#else
/* Fixed point (stsp_estimator.h): |acc| <= 2^STSP_EST_ACC_BITS for inputs in their Q ranges
 * when every row's absolute sum (entries, 2^F-weighted constant as |c|, pass-through
 * coefficient) is at most 2^(STSP_EST_ACC_BITS - F). */
#define STSP_EST_ACC_BITS 61u
#define STSP_EST_ROW_MAX (UINT64_C(1) << (STSP_EST_ACC_BITS - (uint32_t)STSP_Q_FRAC_BITS))

static uint64_t stsp_est_abs(stsp_scalar_t a)
{
    const int64_t w = (int64_t)a;
    return (w < 0) ? (uint64_t)(-w) : (uint64_t)w;
}

/* Sum of |a[0..count)|, count <= STSP_MAX_NX + STSP_MAX_NU + 1: no wrap-around. */
static uint64_t stsp_est_abs_sum(const stsp_scalar_t *a, uint32_t count)
{
    uint64_t sum = 0u;
    uint32_t i;
    for (i = 0u; i < count; ++i) {
        sum += stsp_est_abs(a[i]);
    }
    return sum;
}

/* 1 when each of `rows` rows of `width` entries (stride `width`), plus `pass`, fits. */
static int stsp_est_rows_ok(const stsp_scalar_t *a, uint32_t rows, uint32_t width, uint64_t pass)
{
    uint32_t r;
    for (r = 0u; r < rows; ++r) {
        if ((stsp_est_abs_sum(&a[r * width], width) + pass) > STSP_EST_ROW_MAX) {
            return 0;
        }
    }
    return 1;
}

static int stsp_est_values_ok(const stsp_est_table_t *e)
{
    const uint32_t nx = e->nx;
    const uint32_t ny = e->ny;
    const uint32_t F = (uint32_t)STSP_Q_FRAC_BITS;
    uint32_t i;
    uint32_t k;
    if ((stsp_q_exps_ok(e->y_exp, ny) == 0) || (stsp_q_exps_ok(e->e_exp, ny) == 0)) {
        return 0;
    }
    for (i = 0u; i < (ny + (2u * nx)); ++i) {
        if ((e->shift[i] < 1u) || (e->shift[i] > (STSP_EST_ACC_BITS - F))) {
            return 0;
        }
    }
    for (i = 0u; i < ny; ++i) {
        /* the reading's coefficient 2^up, up = k + y_exp - e_exp in [0, 61 - F] */
        const int32_t up = (int32_t)e->shift[i] + ((int32_t)e->y_exp[i] - (int32_t)e->e_exp[i]);
        if ((e->e_exp[i] > e->y_exp[i]) || (up > ((int32_t)STSP_EST_ACC_BITS - (int32_t)F)) ||
            (stsp_est_rows_ok(&e->C[i * nx], 1u, nx, UINT64_C(1) << (uint32_t)up) == 0)) {
            return 0;
        }
    }
    for (k = 0u; k < stsp_est_samples(e); ++k) {
        for (i = 0u; i < nx; ++i) {
            const uint64_t pass = UINT64_C(1) << e->shift[ny + i];
            if (stsp_est_rows_ok(&e->gain[((k * nx) + i) * ny], 1u, ny, pass) == 0) {
                return 0;
            }
        }
    }
    /* a predictor row: [Ad - I | Bd | fd], fd weighted 2^F in the sum (counted as |fd|), the
     * pass-through x̂_q 2^k */
    for (k = 0u; k < stsp_est_models(e); ++k) {
        for (i = 0u; i < nx; ++i) {
            const uint64_t pass = UINT64_C(1) << e->shift[ny + nx + i];
            if (stsp_est_rows_ok(&e->model[((k * nx) + i) * stsp_est_row(e)], 1u,
                                 stsp_est_row(e), pass) == 0) {
                return 0;
            }
        }
    }
    return 1;
}

/* The accumulator's start: 2^62 (keeps a valid sum positive) + 2^(k-1) (rounding), 1 <= k <=
 * 61 - F. */
static uint64_t stsp_est_acc(uint32_t k)
{
    return (UINT64_C(1) << 62) + (UINT64_C(1) << (k - 1u));
}

/* acc + a b modulo 2^64: exact for |a b| <= 2^62 (no signed overflow: each factor is at most
 * 2^31 in magnitude, or a pass-through power of two checked by init). */
static uint64_t stsp_est_mac(uint64_t acc, int64_t a, int64_t b)
{
    const int64_t product = a * b;
    return acc + (uint64_t)product;
}

/* 2^k as an int64 (k <= 62). */
static int64_t stsp_est_pow2(uint32_t k)
{
    const uint64_t p = UINT64_C(1) << k;
    return (int64_t)p;
}

/* floor(sum / 2^k + 1/2) of acc = stsp_est_acc(k) + sum (|sum| <= 2^61: a positive acc below
 * 2^63, an exact shift), saturated to [-2^F, 2^F - 1]; *clamped set when it saturated. */
static stsp_scalar_t stsp_est_round(uint64_t acc, uint32_t k, uint32_t *clamped)
{
    const uint64_t shifted = acc >> k;
    const int64_t q = (int64_t)shifted - stsp_est_pow2(62u - k);
    const int64_t one = stsp_est_pow2((uint32_t)STSP_Q_FRAC_BITS);
    int64_t out = q;
    if (q > (one - 1)) {
        out = one - 1;
        *clamped = 1u;
    } else if (q < -one) {
        out = -one;
        *clamped = 1u;
    } else {
        /* in range */
    }
    return (stsp_scalar_t)out;
}
#endif

static stsp_status_t stsp_est_refuse(stsp_est_t *est, stsp_status_t status)
{
    (void)memset(est, 0, sizeof *est);
    return status;
}

static void stsp_est_start(stsp_est_t *est)
{
    uint32_t j;
    est->next_tick = 0u;
    est->stage = 0u;
    for (j = 0u; j < est->checked.nx; ++j) {
        est->xhat[j] = est->checked.xhat0[j];
    }
    for (j = 0u; j < est->checked.nu; ++j) {
        est->u_last[j] = est->ctrl.hold[j];
    }
}

/* stsp_est_init() up to the values of the estimator table (the instance not ready yet);
 * `spline` 1 when a gain spline follows. */
static stsp_status_t stsp_est_bind(stsp_est_t *est, const stsp_table_t *table,
                                   const stsp_est_table_t *est_table, int spline)
{
    stsp_status_t st;
    (void)memset(est, 0, sizeof *est);
    if (est_table == NULL) {
        return STSP_ERR_NULL;
    }
    st = stsp_init(&est->ctrl, table);
    if (st != STSP_OK) {
        return stsp_est_refuse(est, st);
    }
    est->checked = *est_table;
    st = stsp_est_check(&est->checked, &est->ctrl.checked, spline);
    if (st != STSP_OK) {
        return stsp_est_refuse(est, st);
    }
    if (stsp_est_table_crc32(&est->checked) != est->checked.crc32) {
        return stsp_est_refuse(est, STSP_ERR_BAD_CRC);
    }
    if (memcmp(est->checked.problem_sha256, table->problem_sha256, 32u) != 0) {
        return stsp_est_refuse(est, STSP_ERR_BAD_PROBLEM);
    }
    if (stsp_est_values_ok(&est->checked) == 0) {
        return stsp_est_refuse(est, STSP_ERR_BAD_VALUES);
    }
    est->table = est_table;
    return STSP_OK;
}

stsp_status_t stsp_est_init(stsp_est_t *est, const stsp_table_t *table,
                            const stsp_est_table_t *est_table)
{
    stsp_status_t st;
    if (est == NULL) {
        return STSP_ERR_NULL;
    }
    st = stsp_est_bind(est, table, est_table, 0);
    if (st == STSP_OK) {
        stsp_est_start(est);
        est->ready = STSP_EST_READY;
    }
    return st;
}

#ifndef STSP_ARITH_FIXED_POINT
/* The samples of stage s, q0(s) .. q0(s + 1) - 1 (the top of stsp_estimator.h). */
static uint32_t stsp_est_first_sample(const stsp_est_table_t *e, uint32_t tick)
{
    return (tick / e->every) + (((tick % e->every) != 0u) ? 1u : 0u);
}

uint32_t stsp_est_gain_spline_crc32(const stsp_est_gain_spline_t *spline,
                                    const stsp_est_table_t *est)
{
    const uint32_t ns1 = (uint32_t)est->n_stages + 1u;
    uint32_t crc = stsp_crc32_begin();
    crc = stsp_crc32_u32(crc, est->n_stages);
    crc = stsp_crc32_u32(crc, (uint32_t)est->nx * est->ny);
    crc = stsp_crc32_u32(crc, spline->n_knots);
    crc = stsp_crc32_u32(crc, spline->n_entries);
    crc = stsp_crc32_u32(crc, spline->n_coef);
    crc = stsp_crc32_u32s(crc, spline->knot_start, ns1);
    crc = stsp_crc32_f32s(crc, spline->knot, spline->n_knots);
    crc = stsp_crc32_u32s(crc, spline->entry_start, ns1);
    crc = stsp_crc32_bytes(crc, spline->entry, spline->n_entries);
    crc = stsp_crc32_u32s(crc, spline->coef_start, ns1);
    crc = stsp_crc32_f32s(crc, spline->coef, spline->n_coef);
    crc = stsp_crc32_u32(crc, spline->est_crc32);
    return stsp_crc32_end(crc);
}

/* 1 when start[0..ns] runs from 0 to `total`, nondecreasing. */
static int stsp_est_starts_ok(const uint32_t *start, uint32_t ns, uint32_t total)
{
    uint32_t s;
    if ((start[0] != 0u) || (start[ns] != total)) {
        return 0;
    }
    for (s = 0u; s < ns; ++s) {
        if (start[s + 1u] < start[s]) {
            return 0;
        }
    }
    return 1;
}

/* Stage s of a gain spline whose start arrays are valid: its knots, entries and coefficients
 * as stsp_est_gain_spline_t says for its samples. */
static int stsp_est_spline_stage_ok(const stsp_est_gain_spline_t *sp, const stsp_est_table_t *e,
                                    const uint32_t *stage_start, uint32_t s)
{
    const uint32_t T = stsp_est_first_sample(e, stage_start[s + 1u]) -
                       stsp_est_first_sample(e, stage_start[s]);
    const uint32_t k0 = sp->knot_start[s];
    const uint32_t nk = sp->knot_start[s + 1u] - k0;
    const uint32_t e0 = sp->entry_start[s];
    const uint32_t ne = sp->entry_start[s + 1u] - e0;
    const uint32_t nc = sp->coef_start[s + 1u] - sp->coef_start[s];
    uint32_t i;
    if (T == 0u) {
        return ((nk == 0u) && (ne == 0u) && (nc == 0u)) ? 1 : 0;
    }
    if ((nk < 8u) || (T >= 16777216u) || ((nc % (nk - 4u)) != 0u) || ((nc / (nk - 4u)) != ne) ||
        (stsp_knots_ok(&sp->knot[k0], nk, T) == 0)) {
        return 0;
    }
    for (i = 0u; i < ne; ++i) {
        if ((sp->entry[e0 + i] >= ((uint32_t)e->nx * e->ny)) ||
            ((i > 0u) && (sp->entry[e0 + i] <= sp->entry[e0 + i - 1u]))) {
            return 0;
        }
    }
    return 1;
}

/* The gain spline against the validated estimator table (e): everything but the CRC and the
 * values. */
static stsp_status_t stsp_est_spline_check(const stsp_est_gain_spline_t *sp,
                                           const stsp_est_table_t *e, const uint32_t *stage_start)
{
    const uint32_t ns = e->n_stages;
    uint32_t s;
    if ((sp->knot_start == NULL) || (sp->knot == NULL) || (sp->entry_start == NULL) ||
        (sp->entry == NULL) || (sp->coef_start == NULL) || (sp->coef == NULL)) {
        return STSP_ERR_NULL;
    }
    if (sp->magic != STSP_EST_SPLINE_MAGIC) {
        return STSP_ERR_BAD_MAGIC;
    }
    if ((stsp_est_starts_ok(sp->knot_start, ns, sp->n_knots) == 0) ||
        (stsp_est_starts_ok(sp->entry_start, ns, sp->n_entries) == 0) ||
        (stsp_est_starts_ok(sp->coef_start, ns, sp->n_coef) == 0)) {
        return STSP_ERR_BAD_DIMS;
    }
    for (s = 0u; s < ns; ++s) {
        if (stsp_est_spline_stage_ok(sp, e, stage_start, s) == 0) {
            return STSP_ERR_BAD_DIMS;
        }
    }
    return STSP_OK;
}

stsp_status_t stsp_est_init_spline(stsp_est_t *est, const stsp_table_t *table,
                                   const stsp_est_table_t *est_table,
                                   const stsp_est_gain_spline_t *spline)
{
    stsp_status_t st;
    if (est == NULL) {
        return STSP_ERR_NULL;
    }
    st = stsp_est_bind(est, table, est_table, 1);
    if (st != STSP_OK) {
        return st;
    }
    if (spline == NULL) {
        return stsp_est_refuse(est, STSP_ERR_NULL);
    }
    est->spline_checked = *spline;
    st = stsp_est_spline_check(&est->spline_checked, &est->checked, est->ctrl.checked.stage_start);
    if (st != STSP_OK) {
        return stsp_est_refuse(est, st);
    }
    if (stsp_est_gain_spline_crc32(&est->spline_checked, &est->checked) !=
        est->spline_checked.crc32) {
        return stsp_est_refuse(est, STSP_ERR_BAD_CRC);
    }
    if (est->spline_checked.est_crc32 != est->checked.crc32) {
        return stsp_est_refuse(est, STSP_ERR_BAD_PROBLEM);
    }
    if (stsp_est_finite(est->spline_checked.coef, est->spline_checked.n_coef) == 0) {
        return stsp_est_refuse(est, STSP_ERR_BAD_VALUES);
    }
    est->spline = spline;
    stsp_est_start(est);
    est->ready = STSP_EST_READY;
    return STSP_OK;
}
#endif

stsp_status_t stsp_est_reset(stsp_est_t *est)
{
    stsp_status_t st;
    if (est == NULL) {
        return STSP_ERR_NULL;
    }
    if (est->ready != STSP_EST_READY) {
        return STSP_ERR_NOT_INITIALIZED;
    }
    st = stsp_reset(&est->ctrl);
    if (st == STSP_OK) {
        stsp_est_start(est);
    }
    return st;
}

/* 1 when the table's header is no longer the validated copy. */
static int stsp_est_header_changed(const stsp_est_table_t *a, const stsp_est_table_t *b)
{
    return ((a->magic != b->magic) || (a->format_version != b->format_version) ||
            (a->scalar_kind != b->scalar_kind) || (a->nx != b->nx) || (a->nu != b->nu) ||
            (a->ny != b->ny) || (a->n_stages != b->n_stages) || (a->n_ticks != b->n_ticks) ||
            (a->every != b->every) || (a->model_start != b->model_start) ||
            (a->model != b->model) || (a->C != b->C) || (a->gain != b->gain) ||
#ifdef STSP_ARITH_FIXED_POINT
            (a->y_exp != b->y_exp) || (a->e_exp != b->e_exp) || (a->shift != b->shift) ||
#endif
            (a->xhat0 != b->xhat0)) ? 1 : 0;
}

#ifndef STSP_ARITH_FIXED_POINT
/* stsp_est_verify() of the bound gain spline: its header as validated, its CRC. */
static stsp_status_t stsp_est_spline_verify(const stsp_est_t *est)
{
    const stsp_est_gain_spline_t *a = &est->spline_checked;
    const stsp_est_gain_spline_t *b = est->spline;
    stsp_est_gain_spline_t now;
    if ((a->magic != b->magic) || (a->n_knots != b->n_knots) || (a->n_entries != b->n_entries) ||
        (a->n_coef != b->n_coef) || (a->knot_start != b->knot_start) || (a->knot != b->knot) ||
        (a->entry_start != b->entry_start) || (a->entry != b->entry) ||
        (a->coef_start != b->coef_start) || (a->coef != b->coef) ||
        (a->est_crc32 != b->est_crc32)) {
        return STSP_ERR_TABLE_CHANGED;
    }
    now = *a;
    now.crc32 = b->crc32;
    return (stsp_est_gain_spline_crc32(&now, &est->checked) != now.crc32) ? STSP_ERR_BAD_CRC
                                                                         : STSP_OK;
}
#endif

stsp_status_t stsp_est_verify(stsp_est_t *est)
{
    stsp_status_t st;
    stsp_est_table_t now;
    if (est == NULL) {
        return STSP_ERR_NULL;
    }
    if (est->ready != STSP_EST_READY) {
        return STSP_ERR_NOT_INITIALIZED;
    }
    st = stsp_verify(&est->ctrl);
    if (st == STSP_OK) {
        if (stsp_est_header_changed(&est->checked, est->table) != 0) {
            st = STSP_ERR_TABLE_CHANGED;
        } else {
            /* The validated header, the table's CRC field and hash: what init checked. */
            now = est->checked;
            now.crc32 = est->table->crc32;
            (void)memcpy(now.problem_sha256, est->table->problem_sha256, 32u);
            if ((stsp_est_table_crc32(&now) != now.crc32) ||
                (memcmp(now.problem_sha256, est->checked.problem_sha256, 32u) != 0)) {
                st = STSP_ERR_BAD_CRC;
            }
        }
    }
#ifndef STSP_ARITH_FIXED_POINT
    if ((st == STSP_OK) && (est->spline != NULL)) {
        st = stsp_est_spline_verify(est);
    }
#endif
    if (st != STSP_OK) {
        est->ready = STSP_EST_STOPPED;
    }
    return st;
}

/* The map of tick j (stage s). */
static const stsp_scalar_t *stsp_est_map(const stsp_est_table_t *e, const uint32_t *stage_start,
                                         uint32_t s, uint32_t j)
{
    uint32_t k = e->model_start[s];
    if ((e->model_start[s + 1u] - k) > 1u) {
        k += j - stage_start[s];
    }
    return &e->model[k * (uint32_t)e->nx * stsp_est_row(e)];
}

/* The rows of the filter, per arithmetic (stsp_estimator.h gives both orders of evaluation):
 * innovation i from reading y_i and x̂; update of x̂_r from row r of the gain; prediction of
 * x̂_r from row r of the map, x̂+ and u. The fixed-point rows set *clamped when they
 * saturate. */
#ifndef STSP_ARITH_FIXED_POINT
static stsp_f32_t stsp_est_innovation(const stsp_est_table_t *e, uint32_t i, stsp_f32_t y,
                                      const stsp_f32_t *xh, uint32_t *clamped)
{
    const stsp_f32_t *C = &e->C[i * (uint32_t)e->nx];
    stsp_f32_t acc = y;
    uint32_t j;
    (void)clamped;
    for (j = 0u; j < e->nx; ++j) {
        acc = acc - (C[j] * xh[j]);
    }
    return acc;
}

static stsp_f32_t stsp_est_corrected(const stsp_est_table_t *e, uint32_t r, const stsp_f32_t *F,
                                     const stsp_f32_t *innov, stsp_f32_t x, uint32_t *clamped)
{
    stsp_f32_t acc = x;
    uint32_t i;
    (void)r;
    (void)clamped;
    for (i = 0u; i < e->ny; ++i) {
        acc = acc + (F[i] * innov[i]);
    }
    return acc;
}

static stsp_f32_t stsp_est_predicted(const stsp_est_table_t *e, uint32_t r,
                                     const stsp_f32_t *row, const stsp_f32_t *xp,
                                     const stsp_f32_t *u, uint32_t *clamped)
{
    const uint32_t nx = e->nx;
    const uint32_t nu = e->nu;
    stsp_f32_t acc = row[nx + nu];
    uint32_t c;
    (void)r;
    (void)clamped;
    for (c = 0u; c < nx; ++c) {
        acc = acc + (row[c] * xp[c]);
    }
    for (c = 0u; c < nu; ++c) {
        acc = acc + (row[nx + c] * u[c]);
    }
    return acc;
}

/* A reading the filter can take: every y[i] finite. */
static int stsp_est_reading_ok(const stsp_est_table_t *e, const stsp_f32_t *y)
{
    return stsp_est_finite(y, e->ny);
}
#else
static stsp_scalar_t stsp_est_innovation(const stsp_est_table_t *e, uint32_t i, stsp_scalar_t y,
                                         const stsp_scalar_t *xh, uint32_t *clamped)
{
    const stsp_scalar_t *C = &e->C[i * (uint32_t)e->nx];
    const uint32_t k = e->shift[i];
    const int32_t up = (int32_t)k + ((int32_t)e->y_exp[i] - (int32_t)e->e_exp[i]);
    uint64_t acc = stsp_est_mac(stsp_est_acc(k), y, stsp_est_pow2((uint32_t)up));
    uint32_t j;
    for (j = 0u; j < e->nx; ++j) {
        acc = stsp_est_mac(acc, C[j], xh[j]);
    }
    return stsp_est_round(acc, k, clamped);
}

static stsp_scalar_t stsp_est_corrected(const stsp_est_table_t *e, uint32_t r,
                                        const stsp_scalar_t *F, const stsp_scalar_t *innov,
                                        stsp_scalar_t x, uint32_t *clamped)
{
    const uint32_t k = e->shift[(uint32_t)e->ny + r];
    uint64_t acc = stsp_est_mac(stsp_est_acc(k), x, stsp_est_pow2(k));
    uint32_t i;
    for (i = 0u; i < e->ny; ++i) {
        acc = stsp_est_mac(acc, F[i], innov[i]);
    }
    return stsp_est_round(acc, k, clamped);
}

/* x̂+_r 2^k + fd 2^F + (Ad - I) x̂+ + Bd u: the stored map is the increment. */
static stsp_scalar_t stsp_est_predicted(const stsp_est_table_t *e, uint32_t r,
                                        const stsp_scalar_t *row, const stsp_scalar_t *xp,
                                        const stsp_scalar_t *u, uint32_t *clamped)
{
    const uint32_t nx = e->nx;
    const uint32_t nu = e->nu;
    const uint32_t k = e->shift[(uint32_t)e->ny + nx + r];
    uint64_t acc = stsp_est_mac(stsp_est_acc(k), xp[r], stsp_est_pow2(k));
    uint32_t c;
    acc = stsp_est_mac(acc, row[nx + nu], stsp_est_pow2((uint32_t)STSP_Q_FRAC_BITS));
    for (c = 0u; c < nx; ++c) {
        acc = stsp_est_mac(acc, row[c], xp[c]);
    }
    for (c = 0u; c < nu; ++c) {
        acc = stsp_est_mac(acc, row[nx + c], u[c]);
    }
    return stsp_est_round(acc, k, clamped);
}

/* Every integer reading is one the filter takes. */
static int stsp_est_reading_ok(const stsp_est_table_t *e, const stsp_scalar_t *y)
{
    (void)e;
    (void)y;
    return 1;
}
#endif

/* x̂ = Ad x̂+ + Bd u + fd with tick j's map (stage s); in place of xh (nx). */
static void stsp_est_predict(const stsp_est_t *est, const uint32_t *stage_start, uint32_t s,
                             uint32_t j, stsp_scalar_t *xh, const stsp_scalar_t *u,
                             uint32_t *clamped)
{
    const stsp_est_table_t *e = &est->checked;
    const uint32_t w = stsp_est_row(e);
    const stsp_scalar_t *map = stsp_est_map(e, stage_start, s, j);
    stsp_scalar_t xp[STSP_MAX_NX];
    uint32_t r;
    for (r = 0u; r < e->nx; ++r) {
        xp[r] = xh[r];
    }
    for (r = 0u; r < e->nx; ++r) {
        xh[r] = stsp_est_predicted(e, r, &map[r * w], xp, u, clamped);
    }
}

#ifndef STSP_ARITH_FIXED_POINT
/* A stage's part of the gain spline, as the update reads it. */
typedef struct {
    const stsp_f32_t *coef;  /* the first coefficient of the span's first entry */
    const uint8_t *entry;    /* the stage's entries */
    uint32_t n_entries;
    uint32_t stride;         /* S + 3 */
    stsp_f32_t n[4];         /* N[0..3] at the sample */
} stsp_est_gains_t;

/* The span and basis of sample `sample` in stage s (the top of stsp_estimator.h), into g.
 * The arrays are read within the lengths init validated whatever they hold now: a stage whose
 * layout no longer fits them (the table changed after init, until stsp_est_verify() notices)
 * gets no entries (F = 0: no update), a knot changed to NaN a wrong gain; no access outside
 * the arrays. */
static void stsp_est_gain_basis(const stsp_est_gain_spline_t *sp, uint32_t s, uint32_t tau_q,
                                stsp_est_gains_t *g)
{
    const uint32_t k0 = sp->knot_start[s];
    const uint32_t k1 = sp->knot_start[s + 1u];
    const uint32_t e0 = sp->entry_start[s];
    const uint32_t e1 = sp->entry_start[s + 1u];
    const uint32_t c0 = sp->coef_start[s];
    const stsp_f32_t tau = (stsp_f32_t)tau_q;
    const stsp_f32_t *U = &sp->knot[k0];
    stsp_f32_t left[4];
    stsp_f32_t right[4];
    uint32_t lo = 0u;
    uint32_t hi;
    uint32_t k;
    uint32_t r;
    g->n_entries = 0u;
    g->entry = sp->entry;
    g->coef = sp->coef;
    g->stride = 0u;
    if ((k1 > sp->n_knots) || (k1 < k0) || ((k1 - k0) < 8u) || (e1 > sp->n_entries) ||
        (e1 < e0) || (c0 > sp->n_coef) || ((e1 - e0) > ((sp->n_coef - c0) / (k1 - k0 - 4u)))) {
        return;
    }
    hi = k1 - k0 - 8u; /* S - 1 */
    while (lo < hi) { /* the largest sigma <= S - 1 with U[sigma + 3] <= tau */
        const uint32_t mid = lo + (((hi - lo) + 1u) / 2u);
        if (U[mid + 3u] <= tau) {
            lo = mid;
        } else {
            hi = mid - 1u;
        }
    }
    for (k = 1u; k < 4u; ++k) {
        left[k] = tau - U[lo + 4u - k];
        right[k] = U[lo + 3u + k] - tau;
    }
    g->n[0] = 1.0f;
    for (k = 1u; k < 4u; ++k) {
        stsp_f32_t saved = 0.0f;
        for (r = 0u; r < k; ++r) {
            const stsp_f32_t temp = g->n[r] / (right[r + 1u] + left[k - r]);
            g->n[r] = stsp_mla(saved, right[r + 1u], temp);
            saved = left[k - r] * temp;
        }
        g->n[k] = saved;
    }
    g->entry = &sp->entry[e0];
    g->n_entries = e1 - e0;
    g->stride = k1 - k0 - 4u;
    g->coef = &sp->coef[c0 + lo];
}

/* Row r of F (ny gains) from g, the entries from *next on (those of rows before r passed):
 * ((N0 c0 + N1 c1) + N2 c2) + N3 c3 for a stored entry, +0 else. */
static void stsp_est_gain_row(const stsp_est_gains_t *g, uint32_t r, uint32_t ny, uint32_t *next,
                              stsp_f32_t *F)
{
    uint32_t i;
    uint32_t e = *next;
    for (i = 0u; i < ny; ++i) {
        F[i] = 0.0f;
    }
    while ((e < g->n_entries) && ((g->entry[e] / ny) == r)) {
        const stsp_f32_t *c = &g->coef[e * g->stride];
        stsp_f32_t v = g->n[0] * c[0];
        v = stsp_mla(v, g->n[1], c[1]);
        v = stsp_mla(v, g->n[2], c[2]);
        F[g->entry[e] % ny] = stsp_mla(v, g->n[3], c[3]);
        ++e;
    }
    while ((e < g->n_entries) && ((g->entry[e] / ny) < r)) { /* a table changed after init */
        ++e;
    }
    *next = e;
}

/* x̂ += F (y - C x̂) with the gains of the spline at the sample of `tick` (stage s); in place
 * of xh (nx). Its own function, not inlined, so that the step's frame on per-tick tables is
 * what it was. */
static STSP_NOINLINE void stsp_est_update_spline(const stsp_est_t *est, uint32_t s,
                                                 uint32_t tick, const stsp_f32_t *y,
                                                 stsp_f32_t *xh, uint32_t *clamped)
{
    const stsp_est_table_t *e = &est->checked;
    stsp_est_gains_t g;
    stsp_f32_t F[STSP_MAX_NY];
    stsp_f32_t innov[STSP_MAX_NY];
    uint32_t next = 0u;
    uint32_t r;
    for (r = 0u; r < e->ny; ++r) {
        innov[r] = stsp_est_innovation(e, r, y[r], xh, clamped);
    }
    stsp_est_gain_basis(&est->spline_checked, s, (tick / e->every) -
                        stsp_est_first_sample(e, est->ctrl.checked.stage_start[s]), &g);
    for (r = 0u; r < e->nx; ++r) {
        stsp_est_gain_row(&g, r, e->ny, &next, F);
        xh[r] = stsp_est_corrected(e, r, F, innov, xh[r], clamped);
    }
}
#endif

/* x̂ += F (y - C x̂) with sample `sample`'s gain; in place of xh (nx). */
static void stsp_est_update(const stsp_est_table_t *e, uint32_t sample, const stsp_scalar_t *y,
                            stsp_scalar_t *xh, uint32_t *clamped)
{
    const uint32_t nx = e->nx;
    const uint32_t ny = e->ny;
    const stsp_scalar_t *F = &e->gain[sample * nx * ny];
    stsp_scalar_t innov[STSP_MAX_NY];
    uint32_t i;
    uint32_t r;
    for (i = 0u; i < ny; ++i) {
        innov[i] = stsp_est_innovation(e, i, y[i], xh, clamped);
    }
    for (r = 0u; r < nx; ++r) {
        xh[r] = stsp_est_corrected(e, r, &F[r * ny], innov, xh[r], clamped);
    }
}

static stsp_status_t stsp_est_hold(const stsp_est_t *est, stsp_scalar_t *u, stsp_status_t st)
{
    uint32_t i;
    for (i = 0u; i < est->checked.nu; ++i) {
        u[i] = est->ctrl.hold[i];
    }
    return st;
}

stsp_status_t stsp_est_step(stsp_est_t *est, uint32_t tick, const stsp_scalar_t *y,
                            stsp_scalar_t *u)
{
    const stsp_est_table_t *e;
    const uint32_t *stage_start;
    stsp_scalar_t xh[STSP_MAX_NX];
    stsp_scalar_t cmd[STSP_MAX_NU];
    stsp_status_t st;
    stsp_status_t mine = STSP_OK;
    uint32_t clamped = 0u;
    uint32_t stage;
    uint32_t j;
    if ((est == NULL) || (u == NULL)) {
        return STSP_ERR_NULL;
    }
    if (est->ready != STSP_EST_READY) {
        if (est->ready == STSP_EST_STOPPED) {
            return stsp_est_hold(est, u, STSP_ERR_NOT_INITIALIZED);
        }
        return STSP_ERR_NOT_INITIALIZED;
    }
    e = &est->checked;
    stage_start = est->ctrl.checked.stage_start;
    if (tick >= e->n_ticks) {
        return stsp_est_hold(est, u, STSP_ERR_TICK_RANGE);
    }
    if (tick < est->next_tick) {
        if ((tick + 1u) != est->next_tick) {
            return stsp_est_hold(est, u, STSP_ERR_TICK_ORDER);
        }
        for (j = 0u; j < e->nu; ++j) {
            u[j] = est->u_last[j];
        }
        return STSP_WARN_TICK_REPEATED;
    }
    for (j = 0u; j < e->nx; ++j) {
        xh[j] = est->xhat[j];
    }
    /* Missed ticks: the plant held the last command; their samples are lost. */
    stage = est->stage;
    for (j = est->next_tick; j < tick; ++j) {
        while (((stage + 1u) < e->n_stages) && (j >= stage_start[stage + 1u])) {
            ++stage;
        }
        stsp_est_predict(est, stage_start, stage, j, xh, est->u_last, &clamped);
    }
    while (((stage + 1u) < e->n_stages) && (tick >= stage_start[stage + 1u])) {
        ++stage;
    }
    if ((tick % e->every) == 0u) {
        if (y == NULL) {
            mine = STSP_WARN_NO_MEASUREMENT;
        } else if (stsp_est_reading_ok(e, y) == 0) {
            return stsp_est_hold(est, u, STSP_ERR_NONFINITE_MEASUREMENT);
        } else {
#ifndef STSP_ARITH_FIXED_POINT
            if (est->spline != NULL) {
                stsp_est_update_spline(est, stage, tick, y, xh, &clamped);
            } else {
                stsp_est_update(e, tick / e->every, y, xh, &clamped);
            }
#else
            stsp_est_update(e, tick / e->every, y, xh, &clamped);
#endif
        }
    }
    st = stsp_step(&est->ctrl, tick, xh, cmd);
    if (st < STSP_OK) {
        return stsp_est_hold(est, u, st);
    }
    for (j = 0u; j < e->nu; ++j) {
        est->u_last[j] = cmd[j];
    }
    stsp_est_predict(est, stage_start, stage, tick, xh, cmd, &clamped);
    if ((mine == STSP_OK) && (clamped != 0u)) {
        mine = STSP_WARN_STATE_CLAMPED; /* fixed point only: the float32 rows never clamp */
    }
    if (st == STSP_OK) {
        st = mine;
    }
    for (j = 0u; j < e->nx; ++j) {
        est->xhat[j] = xh[j];
    }
    est->stage = stage;
    est->next_tick = tick + 1u;
    for (j = 0u; j < e->nu; ++j) {
        u[j] = cmd[j];
    }
    return st;
}

