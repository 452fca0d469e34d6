/* libFuzzer target on the fixed-point spline gains (firmware/src/stsp_qspline.c; built by
 * CMakeLists.txt with clang, -fsanitize=fuzzer,address,undefined, once for Q15 and once for
 * Q31; the tests fuzz_qspline_q15/_q31 run it for a bounded time).
 *
 * Each input describes a table: 1-3 stages of 1-1500 ticks, 1-3 inputs, 1-6 operands, spans
 * of 2^k ticks (k up to 10: one too many now and then), stored entries per (stage, input),
 * their operand columns and scales (raw bytes: out of range and out of order now and then),
 * coefficients over the type's whole range, and coef_start / n_entries / n_coef as the layout
 * requires or with one corruption. Every array is allocated with exactly its declared length.
 *
 * Invariants: stsp_qspline_check() returns STSP_OK exactly when the layout is the format's
 * (fz_layout_ok, written from the contract in stsp_qspline.h); for an accepted table, every
 * gain of every tick of every stage read by stsp_qspline_gains() (ASan: nothing outside the
 * arrays) equals the exact value computed here in __int128 with floor division (independent
 * of the firmware's biased shift), narrowed to the scalar when it fits it; the entries not
 * stored are 0. Any sanitizer report (a signed overflow too), crash or broken invariant
 * (abort) is a finding. */
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "fuzz_input.h"
#include "stospline/stsp_controller.h"
#include "stsp_qspline.h"

#define FZ_MAX_STAGES 3u
#define FZ_MAX_NU 3u
#define FZ_MAX_NZ 6u
#if defined(STSP_ARITH_Q15)
#define FZ_SCALAR_MIN INT16_MIN
#define FZ_SCALAR_MAX INT16_MAX
#else
#define FZ_SCALAR_MIN INT32_MIN
#define FZ_SCALAR_MAX INT32_MAX
#endif
__extension__ typedef __int128 fz_i128; /* clang and GCC: the reference's exact arithmetic */

/* Exact: floor((sum_r c_r P_r) / 2^sh + 1/2), from the definition. */
static int64_t fz_exact(const stsp_scalar_t *c, uint32_t k, uint32_t d, uint32_t sh)
{
    const fz_i128 D = (fz_i128)1 << k;
    const fz_i128 t = d;
    const fz_i128 P0 = (D - t) * (D - t) * (D - t);
    const fz_i128 P3 = t * t * t;
    const fz_i128 P1 = 3 * P3 - 6 * D * t * t + 4 * D * D * D;
    const fz_i128 P2 = -3 * P3 + 3 * D * t * t + 3 * D * D * t + D * D * D;
    const fz_i128 num = 2 * ((fz_i128)c[0] * P0 + (fz_i128)c[1] * P1 +
                              (fz_i128)c[2] * P2 + (fz_i128)c[3] * P3) +
                         ((fz_i128)1 << sh);
    const fz_i128 den = (fz_i128)1 << (sh + 1u);
    fz_i128 q = num / den; /* truncates toward zero: floor for num < 0 below */
    if ((num < 0) && ((q * den) != num)) {
        q -= 1;
    }
    fuzz_check(P0 + P1 + P2 + P3 == 6 * D * D * D);
    return (int64_t)q;
}

/* The contract of stsp_qspline_check, from the arrays as built. */
static int fz_layout_ok(const stsp_qspline_t *q, const uint32_t *start, uint32_t ns,
                        uint32_t nu, uint32_t nz)
{
    uint32_t s;
    uint32_t r;
    if ((q->row_start[0] != 0u) || (q->row_start[ns * nu] != q->n_entries) ||
        (q->coef_start[0] != 0u) || (q->coef_start[ns] != q->n_coef)) {
        return 0;
    }
    for (r = 0u; r < (ns * nu); ++r) {
        if (q->row_start[r + 1u] < q->row_start[r]) {
            return 0;
        }
    }
    for (s = 0u; s < ns; ++s) {
        if (q->coef_start[s + 1u] < q->coef_start[s]) {
            return 0;
        }
    }
    for (s = 0u; s < ns; ++s) {
        const uint32_t k = q->span_log2[s];
        const uint32_t T = start[s + 1u] - start[s];
        uint64_t stride;
        uint64_t entries;
        if (k > 9u) {
            return 0;
        }
        stride = (uint64_t)((T + (1u << k) - 1u) >> k) + 3u;
        entries = (uint64_t)q->row_start[(s + 1u) * nu] - q->row_start[s * nu];
        if ((uint64_t)(q->coef_start[s + 1u] - q->coef_start[s]) != entries * stride) {
            return 0;
        }
        for (r = s * nu; r < ((s + 1u) * nu); ++r) {
            uint32_t e;
            for (e = q->row_start[r]; e < q->row_start[r + 1u]; ++e) {
                if ((q->col[e] >= nz) ||
                    ((e > q->row_start[r]) && (q->col[e] <= q->col[e - 1u])) ||
                    (q->shift[e] < 1u) || (q->shift[e] > 30u)) {
                    return 0;
                }
            }
        }
    }
    return 1;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    fuzz_in_t in = {data, size};
    const uint32_t ns = 1u + (fuzz_u8(&in) % FZ_MAX_STAGES);
    const uint32_t nu = 1u + (fuzz_u8(&in) % FZ_MAX_NU);
    const uint32_t nz = 1u + (fuzz_u8(&in) % FZ_MAX_NZ);
    const uint32_t corrupt = fuzz_u8(&in) % 8u; /* 0..3: one corruption, else none */
    uint32_t start[FZ_MAX_STAGES + 1u];
    uint8_t logs[FZ_MAX_STAGES];
    uint16_t rows[(FZ_MAX_STAGES * FZ_MAX_NU) + 1u];
    uint32_t cstart[FZ_MAX_STAGES + 1u];
    uint32_t s;
    uint32_t r;
    uint32_t n_entries;
    uint32_t n_coef;
    uint8_t *col;
    uint8_t *shift;
    stsp_scalar_t *coef;
    stsp_qspline_t q;
    start[0] = 0u;
    rows[0] = 0u;
    cstart[0] = 0u;
    for (s = 0u; s < ns; ++s) {
        start[s + 1u] = start[s] + 1u + (fuzz_u32(&in) % 1500u);
        logs[s] = (uint8_t)(fuzz_u8(&in) % 11u);
    }
    for (r = 0u; r < (ns * nu); ++r) {
        rows[r + 1u] = (uint16_t)(rows[r] + (fuzz_u8(&in) % (nz + 1u)));
    }
    n_entries = rows[ns * nu];
    for (s = 0u; s < ns; ++s) {
        const uint32_t T = start[s + 1u] - start[s];
        const uint32_t k = (logs[s] > 9u) ? 9u : logs[s];
        const uint32_t stride = ((T + (1u << k) - 1u) >> k) + 3u;
        cstart[s + 1u] = cstart[s] + ((uint32_t)(rows[(s + 1u) * nu] - rows[s * nu]) * stride);
    }
    n_coef = cstart[ns];
    if (corrupt == 0u) {
        cstart[1] += (fuzz_u8(&in) % 3u) - 1u; /* -1, 0 or +1 */
    } else if (corrupt == 1u) {
        n_entries += fuzz_u8(&in) % 2u;
    } else if (corrupt == 2u) {
        n_coef -= (n_coef > 0u) ? (fuzz_u8(&in) % 2u) : 0u;
    } else if (corrupt == 3u) {
        const uint32_t at = 1u + (fuzz_u8(&in) % (ns * nu));
        rows[at] = (uint16_t)(rows[at] - (fuzz_u8(&in) % 2u)); /* may decrease */
    }
    /* exactly the declared lengths (at least one element, as malloc(0) may return NULL) */
    col = malloc((n_entries > 0u) ? n_entries : 1u);
    shift = malloc((n_entries > 0u) ? n_entries : 1u);
    coef = malloc(sizeof *coef * ((n_coef > 0u) ? n_coef : 1u));
    fuzz_check((col != NULL) && (shift != NULL) && (coef != NULL));
    {
        uint32_t e;
        for (e = 0u; e < n_entries; ++e) {
            const uint32_t b = fuzz_u8(&in);
            const uint32_t h = fuzz_u8(&in);
            /* mostly valid: a column from its place in the row (below), 1 time in 32 a raw
             * byte (out of range when >= nz), 1 in 32 the previous entry's (not increasing) */
            col[e] = (uint8_t)((b < 240u) ? 0u : ((b < 248u) ? 255u : b));
            /* mostly in [1, 30], 1 time in 32 0 or 31 */
            shift[e] = (uint8_t)((h < 248u) ? (1u + (h % 30u)) : (((h & 1u) != 0u) ? 31u : 0u));
        }
        for (r = 0u; r < (ns * nu); ++r) {
            uint32_t a;
            for (a = rows[r]; (a < rows[r + 1u]) && (a < n_entries); ++a) {
                if (col[a] == 0u) {
                    col[a] = (uint8_t)(a - rows[r]);      /* increasing, below nz */
                } else if ((col[a] == 255u) && (a > 0u)) {
                    col[a] = col[a - 1u];
                }
            }
        }
        for (e = 0u; e < n_coef; ++e) {
            coef[e] = (stsp_scalar_t)fuzz_u32(&in);
        }
    }
    q.n_entries = n_entries;
    q.n_coef = n_coef;
    q.span_log2 = logs;
    q.row_start = rows;
    q.col = col;
    q.shift = shift;
    q.coef_start = cstart;
    q.coef = coef;
    {
        const int ok = fz_layout_ok(&q, start, ns, nu, nz);
        const stsp_status_t st = stsp_qspline_check(&q, start, ns, nu, nz);
        fuzz_check(st == (ok ? STSP_OK : STSP_ERR_BAD_DIMS));
        if (ok) {
            for (s = 0u; s < ns; ++s) {
                const uint32_t T = start[s + 1u] - start[s];
                const uint32_t k = logs[s];
                const uint32_t stride = ((T + (1u << k) - 1u) >> k) + 3u;
                /* every tick of short stages, a sample of long ones (time per input) */
                const uint32_t step = (T > 64u) ? (1u + (fuzz_u8(&in) % 37u)) : 1u;
                uint32_t tau;
                for (tau = 0u; tau < T; tau += step) {
                    stsp_scalar_t g[FZ_MAX_NU * FZ_MAX_NZ];
                    uint32_t seen[FZ_MAX_NU * FZ_MAX_NZ];
                    uint32_t off = 0u;
                    uint32_t i;
                    memset(seen, 0, sizeof seen);
                    stsp_qspline_gains(&q, start, s, nu, nz, tau, g);
                    for (i = 0u; i < nu; ++i) {
                        uint32_t e;
                        for (e = rows[(s * nu) + i]; e < rows[(s * nu) + i + 1u]; ++e) {
                            const stsp_scalar_t *c = &coef[cstart[s] + off + (tau >> k)];
                            const uint32_t sh = (3u * k) + shift[e];
                            const int64_t exact = fz_exact(c, k, tau & ((1u << k) - 1u), sh);
                            uint32_t p[4];
                            (void)stsp_qspline_basis(k, tau, p);
                            fuzz_check(stsp_qspline_value(c, p, sh) == exact);
                            if ((exact >= FZ_SCALAR_MIN) && (exact <= FZ_SCALAR_MAX)) {
                                fuzz_check((int64_t)g[(i * nz) + col[e]] == exact);
                            }
                            seen[(i * nz) + col[e]] = 1u;
                            off += stride;
                        }
                    }
                    for (i = 0u; i < (nu * nz); ++i) {
                        fuzz_check(seen[i] || (g[i] == 0));
                    }
                }
            }
        }
    }
    free(col);
    free(shift);
    free(coef);
    return 0;
}
