/* Exact band-dual solver by bounded active-set enumeration: see stospline/stsp_bandqp.h. */
#include "stospline/stsp_bandqp.h"

#include <stddef.h>
#include <string.h>

static inline int stsp_isfinite_f32_bits(float value)
{
    uint32_t bits;
    (void)memcpy(&bits, &value, sizeof bits);
    return (bits & 0x7F800000u) != 0x7F800000u;
}

/* Cholesky of W restricted to the rows with state != 0, in place in `chol` (packed by the
 * active index order). Returns 0 if that submatrix is not positive definite. */
static int stsp_chol_active(const double *W, uint32_t q, const int8_t *state, double *chol,
                            uint32_t *idx, uint32_t *na)
{
    uint32_t i, j, k, n = 0u;
    for (i = 0u; i < q; ++i) {
        if (state[i] != 0) {
            idx[n++] = i;
        }
    }
    *na = n;
    for (i = 0u; i < n; ++i) {
        for (j = 0u; j <= i; ++j) {
            double s = W[idx[i] * q + idx[j]];
            for (k = 0u; k < j; ++k) {
                s -= chol[i * n + k] * chol[j * n + k];
            }
            if (i == j) {
                if (!(s > 0.0)) {
                    return 0;
                }
                /* Newton's method for sqrt keeps the solver free of libm: from above it
                 * decreases monotonically, at least halving while r > 2 sqrt(s), so 1100
                 * steps reach the root for any double; near 1 it takes about six. */
                {
                    double r = (s > 1.0) ? s : 1.0;
                    uint32_t it;
                    for (it = 0u; it < 1100u; ++it) {
                        double next = 0.5 * (r + s / r);
                        if (next >= r) {
                            break;
                        }
                        r = next;
                    }
                    chol[i * n + i] = r;
                }
            } else {
                chol[i * n + j] = s / chol[j * n + j];
            }
        }
    }
    return 1;
}

stsp_bandqp_status_t stsp_bandqp_solve(const stsp_bandqp_t *qp, const float *x0, double *lam,
                                       stsp_bandqp_work_t *work, uint32_t *candidates)
{
    uint32_t q, nx, i, j, tried = 0u, na = 0u;
    uint32_t idx[STSP_BANDQP_MAX];
    int done = 0;

    if (candidates != NULL) {
        *candidates = 0u;
    }
    if (qp == NULL || x0 == NULL || lam == NULL || work == NULL || qp->Nt == NULL ||
        qp->mt == NULL || qp->W == NULL || qp->lo == NULL || qp->hi == NULL) {
        return STSP_BANDQP_ERR_NULL;
    }
    q = qp->q;
    nx = qp->nx;
    if (q == 0u || q > STSP_BANDQP_MAX || nx == 0u) {
        return STSP_BANDQP_ERR_DIMS;
    }
    for (i = 0u; i < q; ++i) {
        lam[i] = 0.0;
    }
    for (j = 0u; j < nx; ++j) {
        if (!stsp_isfinite_f32_bits(x0[j])) {
            return STSP_BANDQP_ERR_NONFINITE;
        }
    }
    for (i = 0u; i < q; ++i) {
        double acc = qp->mt[i];
        for (j = 0u; j < nx; ++j) {
            acc += qp->Nt[i * nx + j] * (double)x0[j];
        }
        work->e[i] = acc;
        /* Equality rows are always active (+1); band rows start inactive. */
        work->state[i] = (qp->lo[i] == qp->hi[i]) ? (int8_t)1 : (int8_t)0;
    }

    /* Ternary counter over the band rows: 0 inactive, -1 at lower, +1 at upper. Each
     * candidate is visited once, so the loop runs at most 3^(band rows) times. */
    while (!done) {
        ++tried;
        if (stsp_chol_active(qp->W, q, work->state, work->chol, idx, &na)) {
            uint32_t a, b;
            int ok = 1;
            /* lam_A = W_AA^-1 (e_A - b_A): forward then backward substitution. */
            for (a = 0u; a < na; ++a) {
                uint32_t r = idx[a];
                double s = work->e[r] - ((work->state[r] > 0) ? qp->hi[r] : qp->lo[r]);
                for (b = 0u; b < a; ++b) {
                    s -= work->chol[a * na + b] * work->rhs[b];
                }
                work->rhs[a] = s / work->chol[a * na + a];
            }
            for (a = na; a-- > 0u;) {
                double s = work->rhs[a];
                for (b = a + 1u; b < na; ++b) {
                    s -= work->chol[b * na + a] * work->rhs[b];
                }
                work->rhs[a] = s / work->chol[a * na + a];
            }
            for (i = 0u; i < q; ++i) {
                lam[i] = 0.0;
            }
            for (a = 0u; a < na; ++a) {
                lam[idx[a]] = work->rhs[a];
            }
            /* KKT: signs on active band rows, bands on inactive rows. */
            for (i = 0u; i < q && ok; ++i) {
                const int eq = (qp->lo[i] == qp->hi[i]);
                double y = work->e[i];
                for (j = 0u; j < q; ++j) {
                    y -= qp->W[i * q + j] * lam[j];
                }
                work->y[i] = y;
                if (eq) {
                    continue;
                }
                if (work->state[i] > 0 && lam[i] < 0.0) {
                    ok = 0;
                } else if (work->state[i] < 0 && lam[i] > 0.0) {
                    ok = 0;
                } else if (work->state[i] == 0) {
                    const double tol = 1e-12 * (1.0 + ((qp->hi[i] > 0.0) ? qp->hi[i] : -qp->hi[i]));
                    if (y > qp->hi[i] + tol || y < qp->lo[i] - tol) {
                        ok = 0;
                    }
                }
            }
            if (ok) {
                if (candidates != NULL) {
                    *candidates = tried;
                }
                return STSP_BANDQP_OK;
            }
        }
        /* Next candidate: increment the ternary digits of the band rows (0 -> -1 -> +1). */
        done = 1;
        for (i = 0u; i < q; ++i) {
            if (qp->lo[i] == qp->hi[i]) {
                continue;
            }
            if (work->state[i] == 0) {
                work->state[i] = -1;
                done = 0;
                break;
            }
            if (work->state[i] < 0) {
                work->state[i] = 1;
                done = 0;
                break;
            }
            work->state[i] = 0; /* carry */
        }
    }
    for (i = 0u; i < q; ++i) {
        lam[i] = 0.0;
    }
    if (candidates != NULL) {
        *candidates = tried;
    }
    return STSP_BANDQP_ERR_INFEASIBLE;
}
