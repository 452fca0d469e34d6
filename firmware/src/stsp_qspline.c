/* Fixed-point spline gains (stsp_qspline.h): evaluation and layout check. Fixed-point builds
 * only; a program that does not call them does not link them (static library). */
#include "stsp_qspline.h"

#ifdef STSP_ARITH_FIXED_POINT

uint32_t stsp_qspline_basis(uint32_t k, uint32_t tau, uint32_t *p)
{
    const uint32_t D = (uint32_t)1u << k;
    const uint32_t d = tau & (D - 1u);
    const uint32_t e = D - d;                /* in [1, D] */
    const uint32_t D3 = D * D * D;           /* <= 2^27 */
    p[0] = e * e * e;                        /* <= 2^27 */
    p[3] = d * d * d;
    p[1] = (4u * D3) - (3u * d * d * (D + e)); /* 2 D - d = D + e; 3 d^2 (2D - d) < 4 D^3 */
    p[2] = (6u * D3) - p[0] - p[1] - p[3];   /* >= 0: the four sum to 6 D^3 */
    return tau >> k;
}

int64_t stsp_qspline_value(const stsp_scalar_t *c, const uint32_t *p, uint32_t sh)
{
    const uint64_t biased = stsp_qspline_biased(c, p, sh);
    const uint32_t bias_bit = 62u - sh;
    const uint64_t bias = (uint64_t)1u << bias_bit;
    return (int64_t)biased - (int64_t)bias;
}

/* Stage s's spans: S = ceil(T / 2^k). */
static uint32_t stsp_qspline_spans(uint32_t ticks, uint32_t k)
{
    return (ticks >> k) + (((ticks & (((uint32_t)1u << k) - 1u)) != 0u) ? 1u : 0u);
}

static stsp_status_t stsp_qspline_check_stage(const stsp_qspline_t *sp,
                                              const uint32_t *stage_start, uint32_t s,
                                              uint32_t nu, uint32_t nz)
{
    const uint32_t k = sp->span_log2[s];
    const uint32_t e0 = sp->row_start[s * nu];
    const uint32_t e1 = sp->row_start[(s + 1u) * nu];
    const uint32_t n_coef = sp->coef_start[s + 1u] - sp->coef_start[s];
    uint32_t stride;
    uint32_t i;
    if ((k > STSP_QSPLINE_MAX_SPAN_LOG2) || (stage_start[s + 1u] <= stage_start[s])) {
        return STSP_ERR_BAD_DIMS;
    }
    /* (S + 3) per entry, without forming the product (it could wrap) */
    stride = stsp_qspline_spans(stage_start[s + 1u] - stage_start[s], k) + 3u;
    if (((n_coef % stride) != 0u) || ((n_coef / stride) != (e1 - e0))) {
        return STSP_ERR_BAD_DIMS;
    }
    for (i = 0u; i < nu; ++i) {
        uint32_t e;
        for (e = sp->row_start[(s * nu) + i]; e < sp->row_start[(s * nu) + i + 1u]; ++e) {
            if ((sp->col[e] >= nz) || ((e > sp->row_start[(s * nu) + i]) &&
                                       (sp->col[e] <= sp->col[e - 1u]))) {
                return STSP_ERR_BAD_DIMS;
            }
            if ((sp->shift[e] < 1u) || (sp->shift[e] > STSP_QSPLINE_MAX_SHIFT)) {
                return STSP_ERR_BAD_DIMS;
            }
        }
    }
    return STSP_OK;
}

stsp_status_t stsp_qspline_check(const stsp_qspline_t *sp, const uint32_t *stage_start,
                                 uint32_t n_stages, uint32_t nu, uint32_t nz)
{
    const uint32_t rows = n_stages * nu;
    uint32_t i;
    if ((sp == NULL) || (stage_start == NULL) || (sp->span_log2 == NULL) ||
        (sp->row_start == NULL) || (sp->col == NULL) || (sp->shift == NULL) ||
        (sp->coef_start == NULL) || (sp->coef == NULL)) {
        return STSP_ERR_NULL;
    }
    if ((n_stages == 0u) || (nu == 0u) || (nz > 256u) || (sp->row_start[0] != 0u) ||
        (sp->row_start[rows] != sp->n_entries) || (sp->coef_start[0] != 0u) ||
        (sp->coef_start[n_stages] != sp->n_coef)) {
        return STSP_ERR_BAD_DIMS;
    }
    for (i = 0u; i < rows; ++i) {
        if (sp->row_start[i + 1u] < sp->row_start[i]) {
            return STSP_ERR_BAD_DIMS;
        }
    }
    for (i = 0u; i < n_stages; ++i) {
        if (sp->coef_start[i + 1u] < sp->coef_start[i]) {
            return STSP_ERR_BAD_DIMS;
        }
    }
    for (i = 0u; i < n_stages; ++i) {
        const stsp_status_t st = stsp_qspline_check_stage(sp, stage_start, i, nu, nz);
        if (st != STSP_OK) {
            return st;
        }
    }
    return STSP_OK;
}

void stsp_qspline_gains(const stsp_qspline_t *sp, const uint32_t *stage_start, uint32_t s,
                        uint32_t nu, uint32_t nz, uint32_t tau, stsp_scalar_t *g)
{
    const uint32_t k = sp->span_log2[s];
    const uint32_t k3 = 3u * k;
    const uint32_t ticks = stage_start[s + 1u] - stage_start[s];
    const uint32_t stride = stsp_qspline_spans(ticks, k) + 3u;
    const uint16_t *rows = &sp->row_start[s * nu];
    const uint8_t *col = sp->col;
    const uint8_t *shift = sp->shift;
    uint32_t p[4];
    const uint32_t sigma = stsp_qspline_basis(k, tau, p);
    /* entry e's four coefficients of the span: c, then stride further for the next entry */
    const stsp_scalar_t *c = &sp->coef[sp->coef_start[s] + sigma];
    uint32_t e = rows[0];
    uint32_t i;
    for (i = 0u; i < (nu * nz); ++i) {
        g[i] = 0;
    }
    for (i = 0u; i < nu; ++i) {
        stsp_scalar_t *gi = &g[i * nz];
        const uint32_t end = rows[i + 1u];
        for (; e < end; ++e) {
            /* in the scalar's range for a table whose row sums are (stsp_qspline.h) */
            gi[col[e]] = stsp_qspline_narrow(c, p, k3 + shift[e]);
            c = &c[stride];
        }
    }
}

uint64_t stsp_qspline_col_start(const stsp_qspline_t *sp, const uint32_t *stage_start,
                                uint32_t s, uint32_t per_stage, uint32_t *width)
{
    uint64_t first = 0u;
    uint32_t w = 0u;
    uint32_t r;
    for (r = 0u; r <= s; ++r) {
        const uint32_t k_raw = sp->span_log2[r];
        const uint32_t k = (k_raw <= STSP_QSPLINE_MAX_SPAN_LOG2) ? k_raw
                                                                 : STSP_QSPLINE_MAX_SPAN_LOG2;
        if (r > 0u) {
            first += (uint64_t)per_stage * (uint64_t)w;
        }
        w = stsp_qspline_spans(stage_start[r + 1u] - stage_start[r], k) + 4u;
    }
    *width = w;
    return first;
}

/* The scale of a column block: its first word, in [1, 30] when valid (else 0). */
static uint32_t stsp_qspline_col_shift(const stsp_scalar_t *block)
{
    const int32_t sh = (int32_t)block[0];
    return ((sh >= 1) && (sh <= (int32_t)STSP_QSPLINE_MAX_SHIFT)) ? (uint32_t)sh : 0u;
}

stsp_status_t stsp_qspline_rows_check(const stsp_qspline_t *sp, const uint32_t *stage_start,
                                      uint32_t n_stages, uint32_t nu,
                                      const stsp_scalar_t *cols, uint32_t n_params)
{
    const uint64_t row_max = (uint64_t)STSP_Q_ONE - 1u;
    uint32_t per_stage = 0u;
    uint32_t s;
    if (cols != NULL) {
        per_stage = nu * n_params;
    }
    for (s = 0u; s < n_stages; ++s) {
        uint32_t width = 0u;
        const stsp_scalar_t *blocks = cols;
        const uint32_t k = sp->span_log2[s];
        const uint32_t ticks = stage_start[s + 1u] - stage_start[s];
        const uint32_t entries = (uint32_t)sp->row_start[(s + 1u) * nu] - sp->row_start[s * nu];
        const uint32_t stride = (entries > 0u)
                                    ? ((sp->coef_start[s + 1u] - sp->coef_start[s]) / entries)
                                    : 0u;
        uint32_t tau;
        uint32_t b;
        if (cols != NULL) {
            blocks = &cols[stsp_qspline_col_start(sp, stage_start, s, per_stage, &width)];
        }
        for (b = 0u; b < per_stage; ++b) {
            if (stsp_qspline_col_shift(&blocks[b * width]) == 0u) {
                return STSP_ERR_BAD_VALUES;
            }
        }
        for (tau = 0u; tau < ticks; ++tau) {
            uint32_t p[4];
            const uint32_t sigma = stsp_qspline_basis(k, tau, p);
            const stsp_scalar_t *c =
                (entries > 0u) ? &sp->coef[sp->coef_start[s] + sigma] : sp->coef;
            uint32_t e = sp->row_start[s * nu];
            uint32_t i;
            for (i = 0u; i < nu; ++i) {
                const uint32_t end = sp->row_start[(s * nu) + i + 1u];
                uint64_t sum = 0u;
                uint32_t q;
                for (; e < end; ++e) {
                    const int64_t g = stsp_qspline_value(c, p, (3u * k) + sp->shift[e]);
                    /* |g| <= 3 2^31: the sum of at most 256 + STSP_MAX_PARAMS cannot wrap */
                    sum += (uint64_t)((g < 0) ? -g : g);
                    c = &c[stride];
                }
                for (q = 0u; q < (per_stage / nu); ++q) {
                    const stsp_scalar_t *block = &blocks[((i * n_params) + q) * width];
                    const int64_t g = stsp_qspline_value(&block[1u + sigma], p,
                                                         (3u * k) + stsp_qspline_col_shift(block));
                    sum += (uint64_t)((g < 0) ? -g : g);
                }
                if (sum > row_max) {
                    return STSP_ERR_BAD_VALUES;
                }
            }
        }
    }
    return STSP_OK;
}

#endif /* STSP_ARITH_FIXED_POINT */
