/* Runtime parameters: see stospline/stsp_params.h for the contract. The tick reuses the
 * controller's plan and commit (stsp_plan_tick, stsp_commit_tick: range, order, stage and
 * latch decisions), and evaluates the law itself with k0' and lambda0'. One source for every
 * arithmetic: the rows of the law and of the latch, the values' checks and the CRC's
 * serialization differ between float32 and Q15/Q31 (the sections below). */
#include "stospline/stsp_params.h"
#include "stsp_crc32.h"
#include "stsp_internal.h"
#ifdef STSP_ARITH_FIXED_POINT
#include "stsp_qspline.h"
#endif

#include <string.h>

#define STSP_PARAM_READY 0x50005300u
#define STSP_PARAM_STOPPED 0x50015301u

/* 1 for a parameter table with spline columns (format 2). */
static int stsp_param_is_spline(const stsp_params_table_t *p)
{
    return (p->format_version == STSP_PARAMS_FORMAT_SPLINE) ? 1 : 0;
}

/* The length of S_k0: per tick, or n_spline_coef (format 2, checked against the gain
 * table's spline by stsp_param_check()). */
static uint32_t stsp_param_k0_len(const stsp_params_table_t *p)
{
    if (stsp_param_is_spline(p) != 0) {
        return p->n_spline_coef;
    }
    return p->n_ticks * (uint32_t)p->nu * (uint32_t)p->n_params;
}

static uint32_t stsp_param_lambda_len(const stsp_params_table_t *p)
{
    return (uint32_t)p->n_stages * (uint32_t)p->n_latch * (uint32_t)p->n_params;
}

uint32_t stsp_params_table_crc32(const stsp_params_table_t *params)
{
    const uint32_t n = params->n_params;
    uint32_t crc = stsp_crc32_begin();
    crc = stsp_crc32_u32(crc, n);
    crc = stsp_crc32_u32(crc, params->nu);
    crc = stsp_crc32_u32(crc, params->n_latch);
    crc = stsp_crc32_u32(crc, params->n_stages);
    crc = stsp_crc32_u32(crc, params->n_ticks);
    if (stsp_param_is_spline(params) != 0) {
        crc = stsp_crc32_u32(crc, params->format_version);
        crc = stsp_crc32_u32(crc, params->n_spline_coef);
    }
#ifdef STSP_ARITH_FIXED_POINT
    crc = stsp_crc32_u32(crc, params->scalar_kind);
    crc = stsp_crc32_f64s(crc, params->nominal, n);
    crc = stsp_crc32_f64s(crc, params->lower, n);
    crc = stsp_crc32_f64s(crc, params->upper, n);
#else
    crc = stsp_crc32_f32s(crc, params->nominal, n);
    crc = stsp_crc32_f32s(crc, params->lower, n);
    crc = stsp_crc32_f32s(crc, params->upper, n);
#endif
    crc = stsp_crc32_scalars(crc, params->S_k0, stsp_param_k0_len(params));
    if (params->n_latch > 0u) {
        crc = stsp_crc32_scalars(crc, params->S_lambda0, stsp_param_lambda_len(params));
    }
#ifdef STSP_ARITH_FIXED_POINT
    crc = stsp_crc32_i8s(crc, params->d_exp, n);
#endif
    crc = stsp_crc32_bytes(crc, params->problem_sha256, 32u);
    return stsp_crc32_end(crc);
}

#ifdef STSP_ARITH_FIXED_POINT
/* 1 when n_spline_coef is the length of the spline columns' blocks on the gain spline's
 * spans (stsp_qspline.h: per_stage (S_s + 4) summed over the stages). */
static int stsp_param_spline_len_ok(const stsp_params_table_t *p, const stsp_header_t *h,
                                    uint32_t per_stage)
{
    uint32_t width;
    const uint64_t len = stsp_qspline_col_start(&h->sp, h->stage_start, h->n_stages - 1u,
                                                per_stage, &width) +
                         ((uint64_t)per_stage * (uint64_t)width);
    return (len == (uint64_t)p->n_spline_coef) ? 1 : 0;
}
#else
/* 1 when n_spline_coef is the length of the spline columns on the gain spline's knots,
 * nu P (n_knots - 4 n_stages) (n_knots >= 8 n_stages, validated by stsp_init()). */
static int stsp_param_spline_len_ok(const stsp_params_table_t *p, const stsp_header_t *h,
                                    uint32_t per_stage)
{
    const uint32_t knots = h->sp.n_knots - (4u * (uint32_t)h->n_stages);
    return ((knots <= (UINT32_MAX / per_stage)) && (p->n_spline_coef == (per_stage * knots)))
               ? 1 : 0;
}
#endif

/* The parameter table against the validated gain table (h): everything but the CRC and the
 * values. */
static stsp_status_t stsp_param_check(const stsp_params_table_t *p, const stsp_header_t *h)
{
    const int spline = stsp_param_is_spline(p);
    if ((p->nominal == NULL) || (p->lower == NULL) || (p->upper == NULL) ||
        (p->S_k0 == NULL) ||
        ((p->n_latch > 0u) && (p->S_lambda0 == NULL))) {
        return STSP_ERR_NULL;
    }
#ifdef STSP_ARITH_FIXED_POINT
    if (p->d_exp == NULL) {
        return STSP_ERR_NULL;
    }
#endif
    if (p->magic != STSP_PARAMS_MAGIC) {
        return STSP_ERR_BAD_MAGIC;
    }
    if (((p->format_version != STSP_PARAMS_FORMAT_VERSION) &&
         (p->format_version != STSP_PARAMS_FORMAT_SPLINE)) ||
        (p->scalar_kind != STSP_SCALAR_KIND)) {
        return STSP_ERR_BAD_VERSION;
    }
    if ((p->n_params == 0u) || (p->n_params > STSP_MAX_PARAMS) || (p->nu != h->nu) ||
        (p->n_latch != h->n_latch) || (p->n_stages != h->n_stages) ||
        (p->n_ticks != h->n_ticks)) {
        return STSP_ERR_BAD_DIMS;
    }
    /* Per-tick columns with a per-tick table, spline columns with a spline table; a band
     * dual's latch would need sensitivities of its own (a fixed-point table has none). */
    if ((spline == 0) && (h->spline != NULL)) {
        return STSP_ERR_BAD_DIMS;
    }
    if (spline != 0) {
        /* the spline's layout was validated by stsp_init() */
        const uint32_t per_stage = (uint32_t)p->nu * (uint32_t)p->n_params;
        if ((h->spline == NULL) || (h->sp.ops == NULL) || (h->sp.ops->param_law == NULL) ||
            (stsp_param_spline_len_ok(p, h, per_stage) == 0)) {
            return STSP_ERR_BAD_DIMS;
        }
    }
#ifndef STSP_ARITH_FIXED_POINT
    if (h->band_qp != NULL) {
        return STSP_ERR_BAD_DIMS;
    }
#endif
    return STSP_OK;
}

#ifdef STSP_ARITH_FIXED_POINT
/* 2^e as a binary64 from its bits, |e| <= STSP_Q_EXP_MAX + STSP_Q_FRAC_BITS (a normal
 * number: exact). */
static double stsp_param_pow2(int32_t e)
{
    const int32_t biased = e + 1023;
    const uint64_t bits = ((uint64_t)(uint32_t)biased) << 52;
    double value;
    (void)memcpy(&value, &bits, sizeof value);
    return value;
}

/* *q = floor((theta - nominal[p]) 2^(F - d_exp[p]) + 1/2) in binary64, the subtraction and the
 * + 1/2 rounded as binary64 operations (host qparams.ParametricFixedPoint.d_q: the same
 * operations); 1 when it is within [-(2^F - 1), 2^F - 1], else 0 and *q untouched. Every
 * compare is false for NaN. A d_exp changed after init still gives a normal 2^e. */
static int stsp_param_dq(const stsp_params_table_t *p, uint32_t i, double theta,
                         stsp_scalar_t *q)
{
    const double one = stsp_param_pow2(STSP_Q_FRAC_BITS);
    const double y = (theta - p->nominal[i]) *
                     stsp_param_pow2((int32_t)STSP_Q_FRAC_BITS - (int32_t)p->d_exp[i]);
    const double r = y + 0.5;
    int64_t k;
    if (!((r > (1.0 - one)) && (r < one))) {
        return 0; /* floor(r) outside +-(2^F - 1): also keeps the conversion defined */
    }
    k = (int64_t)r; /* truncation; a step down for a negative non-integer is floor */
    if ((double)k > r) {
        k -= 1;
    }
    *q = (stsp_scalar_t)k;
    return 1;
}

/* The law rows (every tick and input) and latch rows (every stage and multiplier) with the
 * columns' entries within 2^F - 1 (stsp_params.h): no sum overflows for any d_q. */
static int stsp_param_rows_ok(const stsp_params_table_t *p, const stsp_header_t *h)
{
    const stsp_uacc_t row_max = (stsp_uacc_t)STSP_Q_ONE - 1u;
    const uint32_t n = p->n_params;
    const uint32_t nx = h->nx;
    const uint32_t n_latch = h->n_latch;
    uint32_t r;
    if (stsp_param_is_spline(p) != 0) {
        /* the law rows with the spline columns, as evaluated at every tick */
        if (stsp_qspline_rows_check(&h->sp, h->stage_start, h->n_stages, h->nu, p->S_k0,
                                    n) != STSP_OK) {
            return 0;
        }
    }
    for (r = 0u; (stsp_param_is_spline(p) == 0) && (r < (h->n_ticks * (uint32_t)h->nu)); ++r) {
        stsp_uacc_t sum = stsp_q_abs_sum(&h->k0[r], 1u) + stsp_q_abs_sum(&h->K[r * nx], nx) +
                          stsp_q_abs_sum(&p->S_k0[r * n], n);
        if (n_latch > 0u) {
            sum += stsp_q_abs_sum(&h->L[r * n_latch], n_latch);
        }
        if (sum > row_max) {
            return 0;
        }
    }
    for (r = 0u; r < ((uint32_t)h->n_stages * n_latch); ++r) {
        if ((stsp_q_abs_sum(&h->lambda0[r], 1u) + stsp_q_abs_sum(&h->Lambda[r * nx], nx) +
             stsp_q_abs_sum(&p->S_lambda0[r * n], n)) > row_max) {
            return 0;
        }
    }
    return 1;
}

/* 1 when every value is finite, lower <= nominal <= upper, the exponents within range, d_q in
 * the Q range at both ends of every range, and every row within the bound. */
static int stsp_param_values_ok(const stsp_params_table_t *p, const stsp_header_t *h)
{
    uint32_t i;
    if ((stsp_all_finite_f64(p->nominal, p->n_params) == 0) ||
        (stsp_all_finite_f64(p->lower, p->n_params) == 0) ||
        (stsp_all_finite_f64(p->upper, p->n_params) == 0) ||
        (stsp_q_exps_ok(p->d_exp, p->n_params) == 0)) {
        return 0;
    }
    for (i = 0u; i < p->n_params; ++i) {
        stsp_scalar_t q = (stsp_scalar_t)0;
        if (!((p->lower[i] <= p->nominal[i]) && (p->nominal[i] <= p->upper[i])) ||
            (stsp_param_dq(p, i, p->lower[i], &q) == 0) ||
            (stsp_param_dq(p, i, p->upper[i], &q) == 0)) {
            return 0;
        }
    }
    return stsp_param_rows_ok(p, h);
}

/* The deviations of theta into d (the range checked). */
static int stsp_param_deviations(const stsp_params_table_t *p, const stsp_f32_t *theta,
                                 stsp_scalar_t *d)
{
    uint32_t i;
    for (i = 0u; i < p->n_params; ++i) {
        if (stsp_param_dq(p, i, (double)theta[i], &d[i]) == 0) {
            return 0;
        }
    }
    return 1;
}

/* The row primitives (stsp_controller.c's fixed-point law): the accumulator starts from its
 * bias plus the parameters' terms, every gain is stored negated, and the row's constant is
 * added after the one rounding. */
typedef stsp_uacc_t stsp_param_acc_t;

static stsp_param_acc_t stsp_param_terms(const stsp_scalar_t *S, const stsp_scalar_t *d,
                                         uint32_t n)
{
    stsp_uacc_t acc = stsp_q_start();
    uint32_t p;
    for (p = 0u; p < n; ++p) {
        acc = stsp_q_mac(acc, S[p], d[p]);
    }
    return acc;
}

#define stsp_param_law_first(c, S, d, n) stsp_param_terms((S), (d), (n))
#define stsp_param_latch_first(c, S, d, n) stsp_param_terms((S), (d), (n))
#define stsp_param_law_mac stsp_q_mac
#define stsp_param_latch_mac stsp_q_mac
#define stsp_param_end(acc, c) stsp_q_round((acc), (c))

/* A command outside the limits is an integer: clamped, never an error. */
static stsp_status_t stsp_param_nonfinite(const stsp_scalar_t *x, const stsp_scalar_t *y,
                                          uint32_t nx, uint32_t nu)
{
    (void)x;
    (void)y;
    (void)nx;
    (void)nu;
    return STSP_OK;
}
#else
/* 1 when every value is finite and lower <= nominal <= upper. */
static int stsp_param_values_ok(const stsp_params_table_t *p, const stsp_header_t *h)
{
    uint32_t i;
    (void)h;
    if ((stsp_all_finite(p->nominal, p->n_params) == 0) ||
        (stsp_all_finite(p->lower, p->n_params) == 0) ||
        (stsp_all_finite(p->upper, p->n_params) == 0) ||
        (stsp_all_finite(p->S_k0, stsp_param_k0_len(p)) == 0) ||
        ((p->n_latch > 0u) && (stsp_all_finite(p->S_lambda0, stsp_param_lambda_len(p)) == 0))) {
        return 0;
    }
    for (i = 0u; i < p->n_params; ++i) {
        if (!((p->lower[i] <= p->nominal[i]) && (p->nominal[i] <= p->upper[i]))) {
            return 0;
        }
    }
    return 1;
}

/* d = theta - nominal (the range checked: every theta[i] within [lower[i], upper[i]]). */
static int stsp_param_deviations(const stsp_params_table_t *p, const stsp_f32_t *theta,
                                 stsp_f32_t *d)
{
    uint32_t i;
    for (i = 0u; i < p->n_params; ++i) {
        d[i] = theta[i] - p->nominal[i];
    }
    return 1;
}

/* e = c; e = e + (S[p] d[p]) for p = 0 .. n-1: a constant term at the parameters in use. */
static stsp_f32_t stsp_param_shift(stsp_f32_t c, const stsp_f32_t *S, const stsp_f32_t *d,
                                   uint32_t n)
{
    stsp_f32_t e = c;
    uint32_t p;
    for (p = 0u; p < n; ++p) {
        e = stsp_mla(e, S[p], d[p]);
    }
    return e;
}

/* The row primitives (stsp_params.h's order): a law row starts from -(k0 + S_k0 d) and
 * subtracts its terms, a latch row starts from lambda0 + S_lambda0 d and adds them. */
typedef stsp_f32_t stsp_param_acc_t;
#define stsp_param_law_first(c, S, d, n) (-stsp_param_shift((c), (S), (d), (n)))
#define stsp_param_latch_first(c, S, d, n) stsp_param_shift((c), (S), (d), (n))
#define stsp_param_law_mac stsp_mls
#define stsp_param_latch_mac stsp_mla
#define stsp_param_end(acc, c) (acc)

/* The error of a command with a NaN or infinite entry, else STSP_OK. */
static stsp_status_t stsp_param_nonfinite(const stsp_f32_t *x, const stsp_f32_t *y, uint32_t nx,
                                          uint32_t nu)
{
    if (stsp_all_finite(y, nu) == 0) {
        return (stsp_all_finite(x, nx) == 0) ? STSP_ERR_NONFINITE_STATE
                                             : STSP_ERR_NONFINITE_OUTPUT;
    }
    return STSP_OK;
}
#endif

static stsp_status_t stsp_param_refuse(stsp_param_t *pc, stsp_status_t status)
{
    (void)memset(pc, 0, sizeof *pc);
    return status;
}

stsp_status_t stsp_param_init(stsp_param_t *pc, const stsp_table_t *table,
                              const stsp_params_table_t *params)
{
    stsp_status_t st;
    if (pc == NULL) {
        return STSP_ERR_NULL;
    }
    (void)memset(pc, 0, sizeof *pc);
    if (params == NULL) {
        return STSP_ERR_NULL;
    }
    st = stsp_init(&pc->ctrl, table);
    if (st != STSP_OK) {
        return stsp_param_refuse(pc, st);
    }
    pc->checked = *params;
    st = stsp_param_check(&pc->checked, &pc->ctrl.checked);
    if (st != STSP_OK) {
        return stsp_param_refuse(pc, st);
    }
    if (stsp_params_table_crc32(&pc->checked) != pc->checked.crc32) {
        return stsp_param_refuse(pc, STSP_ERR_BAD_CRC);
    }
    if (memcmp(pc->checked.problem_sha256, table->problem_sha256, 32u) != 0) {
        return stsp_param_refuse(pc, STSP_ERR_BAD_PROBLEM);
    }
    if (stsp_param_values_ok(&pc->checked, &pc->ctrl.checked) == 0) {
        return stsp_param_refuse(pc, STSP_ERR_BAD_VALUES);
    }
    pc->params = params;
    pc->ready = STSP_PARAM_READY; /* d all zero: theta = nominal */
    return STSP_OK;
}

/* A spline table's span cache (ctrl.span, which stsp_step() would use and a parametric
 * instance never passes to it: stsp_spline.c's param_law) folds ctrl.v and d into its record
 * of a stage: new parameters clear it (next = 0: no record), so that the next tick searches
 * its span again. A latch needs nothing here: it comes with another stage (stage_start
 * increases strictly: the record's first tick is not the stage's), or after init and reset,
 * which clear the record with the instance. */
static void stsp_param_forget_span(stsp_param_t *pc)
{
#ifndef STSP_ARITH_FIXED_POINT
    pc->ctrl.span.next = 0u;
#else
    (void)pc;
#endif
}

stsp_status_t stsp_set_params(stsp_param_t *pc, const stsp_f32_t *theta)
{
    const stsp_params_table_t *p;
    stsp_scalar_t d[STSP_MAX_PARAMS];
    uint32_t i;
    if ((pc == NULL) || (theta == NULL)) {
        return STSP_ERR_NULL;
    }
    if (pc->ready != STSP_PARAM_READY) {
        return STSP_ERR_NOT_INITIALIZED;
    }
    p = &pc->checked;
    /* The whole vector first: a refused one leaves the parameters in use as they were. The
     * compares are false for NaN; a finite range excludes +-Inf. */
    for (i = 0u; i < p->n_params; ++i) {
        if (!((theta[i] >= p->lower[i]) && (theta[i] <= p->upper[i]))) {
            return STSP_ERR_PARAM_RANGE;
        }
    }
    if (stsp_param_deviations(p, theta, d) == 0) {
        return STSP_ERR_PARAM_RANGE;
    }
    for (i = 0u; i < p->n_params; ++i) {
        pc->d[i] = d[i];
    }
    stsp_param_forget_span(pc);
    return STSP_OK;
}

stsp_status_t stsp_param_reset(stsp_param_t *pc)
{
    if (pc == NULL) {
        return STSP_ERR_NULL;
    }
    if (pc->ready != STSP_PARAM_READY) {
        return STSP_ERR_NOT_INITIALIZED;
    }
    return stsp_reset(&pc->ctrl);
}

/* 1 when the table's header is no longer the validated copy. */
static int stsp_param_header_changed(const stsp_params_table_t *a, const stsp_params_table_t *b)
{
#ifdef STSP_ARITH_FIXED_POINT
    if (a->d_exp != b->d_exp) {
        return 1;
    }
#endif
    return ((a->magic != b->magic) || (a->format_version != b->format_version) ||
            (a->scalar_kind != b->scalar_kind) || (a->n_params != b->n_params) ||
            (a->nu != b->nu) || (a->n_latch != b->n_latch) || (a->n_stages != b->n_stages) ||
            (a->n_ticks != b->n_ticks) || (a->nominal != b->nominal) ||
            (a->lower != b->lower) || (a->upper != b->upper) || (a->S_k0 != b->S_k0) ||
            (a->S_lambda0 != b->S_lambda0) || (a->n_spline_coef != b->n_spline_coef)) ? 1 : 0;
}

stsp_status_t stsp_param_verify(stsp_param_t *pc)
{
    stsp_status_t st;
    stsp_params_table_t now;
    if (pc == NULL) {
        return STSP_ERR_NULL;
    }
    if (pc->ready != STSP_PARAM_READY) {
        return STSP_ERR_NOT_INITIALIZED;
    }
    st = stsp_verify(&pc->ctrl);
    if (st == STSP_OK) {
        if (stsp_param_header_changed(&pc->checked, pc->params) != 0) {
            st = STSP_ERR_TABLE_CHANGED;
        } else {
            /* The validated header, the table's CRC field and hash: what init checked. */
            now = pc->checked;
            now.crc32 = pc->params->crc32;
            (void)memcpy(now.problem_sha256, pc->params->problem_sha256, 32u);
            if ((stsp_params_table_crc32(&now) != now.crc32) ||
                (memcmp(now.problem_sha256, pc->checked.problem_sha256, 32u) != 0)) {
                st = STSP_ERR_BAD_CRC;
            }
        }
    }
    if (st != STSP_OK) {
        pc->ready = STSP_PARAM_STOPPED;
        pc->ctrl.ready = STSP_CTRL_STOPPED; /* its steps write u_hold from now on */
    }
    return st;
}

/* The fresh latch of `stage` into v_new, with lambda0' (stsp_params.h's order). */
static void stsp_param_latch(const stsp_param_t *pc, uint16_t stage, const stsp_scalar_t *x,
                             stsp_scalar_t *v_new)
{
    const stsp_header_t *h = &pc->ctrl.checked;
    const uint32_t nx = h->nx;
    const uint32_t n_latch = h->n_latch;
    const uint32_t n = pc->checked.n_params;
    const uint32_t n_stage = h->stage_n_latch[stage];
    uint32_t c;
    for (c = 0u; c < n_latch; ++c) {
        stsp_scalar_t v = (stsp_scalar_t)0;
        if (c < n_stage) {
            const uint32_t row = ((uint32_t)stage * n_latch) + c;
            const stsp_scalar_t *lam = &h->Lambda[row * nx];
            stsp_param_acc_t acc = stsp_param_latch_first(h->lambda0[row],
                                                          &pc->checked.S_lambda0[row * n],
                                                          pc->d, n);
            uint32_t j;
            for (j = 0u; j < nx; ++j) {
                acc = stsp_param_latch_mac(acc, lam[j], x[j]);
            }
            v = stsp_param_end(acc, h->lambda0[row]);
        }
        v_new[c] = v;
    }
}

/* The per-tick law's rows at `tick` with k0' and multipliers v into y; returns nonzero when
 * some command is outside its limits (or not finite). */
static uint32_t stsp_param_rows(const stsp_param_t *pc, uint32_t tick, const stsp_scalar_t *x,
                                const stsp_scalar_t *v, stsp_scalar_t *y)
{
    const stsp_header_t *h = &pc->ctrl.checked;
    const uint32_t nx = h->nx;
    const uint32_t nu = h->nu;
    const uint32_t n_latch = h->n_latch;
    const uint32_t n = pc->checked.n_params;
    const stsp_scalar_t *K = &h->K[tick * (nu * nx)];
    const stsp_scalar_t *k0 = &h->k0[tick * nu];
    const uint32_t s0 = tick * (nu * n);  /* this tick's rows of S_k0, one of n per input */
    /* L may be NULL when n_latch == 0: no pointer arithmetic on it then. */
    const stsp_scalar_t *L = (n_latch > 0u) ? &h->L[tick * (nu * n_latch)] : h->L;
    uint32_t i;
    uint32_t alarm = 0u;
    for (i = 0u; i < nu; ++i) {
        stsp_param_acc_t acc =
            stsp_param_law_first(k0[i], &pc->checked.S_k0[s0 + (i * n)], pc->d, n);
        stsp_scalar_t out;
        uint32_t j;
        for (j = 0u; j < nx; ++j) {
            acc = stsp_param_law_mac(acc, K[j], x[j]);
        }
        if (n_latch > 0u) {
            for (j = 0u; j < n_latch; ++j) {
                acc = stsp_param_law_mac(acc, L[j], v[j]);
            }
            L = &L[n_latch];
        }
        K = &K[nx];
        out = stsp_param_end(acc, k0[i]);
        y[i] = out;
        if (!((out >= h->u_min[i]) && (out <= h->u_max[i]))) {
            alarm = 1u;
        }
    }
    return alarm;
}

/* The commands y, computed with `alarm` set when one is outside its limits (or not finite):
 * STSP_OK, or the error of a non-finite command (float32), or STSP_WARN_SATURATED after
 * clamping y to the limits (bits of *mask). */
static stsp_status_t stsp_param_finish(const stsp_header_t *h, const stsp_scalar_t *x,
                                       stsp_scalar_t *y, uint32_t alarm, uint16_t *mask)
{
    const uint32_t nu = h->nu;
    uint32_t i;
    uint32_t m = 0u;
    stsp_status_t st;
    *mask = 0u;
    if (alarm == 0u) {
        return STSP_OK;
    }
    st = stsp_param_nonfinite(x, y, h->nx, nu);
    if (st != STSP_OK) {
        return st;
    }
    for (i = 0u; i < nu; ++i) {
        if (y[i] > h->u_max[i]) {
            y[i] = h->u_max[i];
            m |= (uint32_t)1u << i;
        } else if (y[i] < h->u_min[i]) {
            y[i] = h->u_min[i];
            m |= (uint32_t)1u << i;
        } else {
            /* within the limits */
        }
    }
    *mask = (uint16_t)m;
    return (m != 0u) ? STSP_WARN_SATURATED : STSP_OK;
}

/* The law at `tick` (of `stage`) with k0' and multipliers v into y, then stsp_param_finish.
 * One compare pair per input tells a command inside the limits (false for NaN and +-Inf: the
 * limits are finite) from one that needs the finiteness check and the clamp. A spline
 * table's command comes from the spline code (stsp_spline_ops.param_law), with its span cache
 * in ctrl.span when v is ctrl.v (the ordinary tick; not the cold path's v_new, which may be a
 * fresh latch). */
static stsp_status_t stsp_param_law(stsp_param_t *pc, uint32_t tick, uint16_t stage,
                                    const stsp_scalar_t *x, const stsp_scalar_t *v,
                                    stsp_scalar_t *y, uint16_t *mask)
{
    const stsp_header_t *h = &pc->ctrl.checked;
    uint32_t alarm = 0u;
    if (stsp_param_is_spline(&pc->checked) != 0) {
        uint32_t i;
        h->sp.ops->param_law(&pc->ctrl, (uint32_t)stage, tick, x, v, pc->checked.S_k0,
                             pc->checked.n_spline_coef, pc->d, pc->checked.n_params,
                             (v == pc->ctrl.v) ? 1u : 0u, y);
        for (i = 0u; i < h->nu; ++i) {
            if (!((y[i] >= h->u_min[i]) && (y[i] <= h->u_max[i]))) {
                alarm = 1u;
            }
        }
    } else {
        alarm = stsp_param_rows(pc, tick, x, v, y);
    }
    return stsp_param_finish(h, x, y, alarm, mask);
}

stsp_status_t stsp_param_step(stsp_param_t *pc, uint32_t tick, const stsp_scalar_t *x,
                              stsp_scalar_t *u)
{
    stsp_ctrl_t *ctrl;
    stsp_scalar_t v_new[STSP_MAX_LATCH];
    stsp_scalar_t y[STSP_MAX_NU];
    stsp_plan_t plan = {0u, 0u};
    stsp_status_t status;
    uint16_t mask = 0u;
    if ((u == NULL) || (pc == NULL)) {
        return STSP_ERR_NULL;
    }
    ctrl = &pc->ctrl;
    if ((pc->ready != STSP_PARAM_READY) || (ctrl->ready != STSP_CTRL_READY)) {
        if (pc->ready == STSP_PARAM_STOPPED) {
            stsp_hold(ctrl, u);
        }
        return STSP_ERR_NOT_INITIALIZED;
    }
    if (x == NULL) {
        stsp_hold(ctrl, u);
        return STSP_ERR_NULL;
    }
    /* An ordinary tick (the expected one inside the latched stage, as stsp_step() tells it):
     * the law on the multipliers kept, no plan. */
    if ((tick == ctrl->next_tick) && (tick < ctrl->stage_end)) {
        status = stsp_param_law(pc, tick, ctrl->stage, x, ctrl->v, y, &mask);
        if (status < STSP_OK) {
            stsp_hold(ctrl, u);
            return status;
        }
        stsp_copy(u, y, ctrl->checked.nu);
        ctrl->sat_mask = mask;
        ctrl->next_tick = tick + 1u;
        return status;
    }
    stsp_zero(v_new, STSP_MAX_LATCH);
    status = stsp_plan_tick(ctrl, tick, x, v_new, &plan);
    if (status >= STSP_OK) {
        stsp_status_t st;
        if (plan.relatch != 0u) {
            stsp_param_latch(pc, plan.stage, x, v_new);
        }
        st = stsp_param_law(pc, tick, plan.stage, x, v_new, y, &mask);
        if (st != STSP_OK) {
            status = st; /* an error, or STSP_WARN_SATURATED over a tick warning */
        }
    }
    if (status < STSP_OK) {
        stsp_hold(ctrl, u);
        return status;
    }
    stsp_copy(u, y, ctrl->checked.nu);
    ctrl->sat_mask = mask;
    stsp_commit_tick(ctrl, tick, &plan, v_new);
    /* stsp_step() is not called on this instance: its ordinary tick's state (stage_end, the
     * kept rows) is left as stsp_commit_tick() sets it and never read. */
    return status;
}

