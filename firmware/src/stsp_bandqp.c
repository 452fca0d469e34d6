/* Exact band-dual solver by bounded active-set enumeration: see stospline/stsp_bandqp.h.
 *
 * Every loop has a constant or checked bound: rows q <= STSP_BANDQP_MAX (checked on entry),
 * states nx <= UINT16_MAX (the type of stsp_bandqp_t.nx), candidates 3^(band rows) <= 3^8
 * (counted before the enumeration starts), Newton steps STSP_BANDQP_SQRT_STEPS. No allocation,
 * no recursion, no VLAs; the work area is the caller's. MISRA C:2012: only the project-wide
 * deviations D1 (15.5, guard clauses) and D2 (21.15, binary32 bit pattern) of
 * docs/guide/firmware.md apply. */
#include "stospline/stsp_bandqp.h"
#include "stsp_f32bits.h"

#include <float.h>
#include <stddef.h>

/* Newton steps of stsp_bandqp_sqrt(), a bound that reaches the root for every positive
 * finite double (the proof is at the function). */
#define STSP_BANDQP_SQRT_STEPS 1100u

/* 1 when row i is an equality row (lo == hi: always active, at its bound), else 0. A row
 * with a NaN bound is a band row, as everywhere in this file. */
static inline uint32_t stsp_bandqp_is_eq(const stsp_bandqp_t *qp, uint32_t i)
{
    return (qp->lo[i] == qp->hi[i]) ? 1u : 0u;
}

/* sqrt(s) for a positive finite s, by Newton's method, which keeps the solver free of libm.
 * From r0 = max(s, 1) >= sqrt(s) the iterates stay >= sqrt(s) and decrease: while
 * r > 2 sqrt(s), s/r < r/4 and the next iterate is below 5r/8; r0/sqrt(s) <= 2^537 for any
 * positive finite double (s = DBL_MAX: 2^512; the least subnormal: 2^537), so at most
 * 537 / log2(8/5) < 793 steps reach r <= 2 sqrt(s), and from there the error squares on every
 * step (about six more); the loop stops at the first step that no longer decreases r. The
 * 1100-step cap is thus never reached for a positive finite s, and it bounds the loop for
 * any input. The sum r + s/r stays finite: it is s + 1 at r0 = s > 1, and afterwards
 * r <= (s + 1) / 2 and s/r <= sqrt(s) <= r. */
static double stsp_bandqp_sqrt(double s)
{
    double r = (s > 1.0) ? s : 1.0;
    uint32_t done = 0u;
    uint32_t it;
    for (it = 0u; (it < STSP_BANDQP_SQRT_STEPS) && (done == 0u); ++it) {
        const double next = 0.5 * (r + (s / r));
        if (next >= r) {
            done = 1u;
        } else {
            r = next;
        }
    }
    return r;
}

/* The active rows (state != 0) in increasing order into idx; returns their number. */
static uint32_t stsp_bandqp_active(const int8_t *state, uint32_t q, uint32_t *idx)
{
    uint32_t i;
    uint32_t n = 0u;
    for (i = 0u; i < q; ++i) {
        if (state[i] != 0) {
            idx[n] = i;
            ++n;
        }
    }
    return n;
}

/* Cholesky factor of W restricted to the rows idx[0..n), packed n x n row-major (lower
 * triangle) into chol. Returns 1, or 0 as soon as a pivot is not positive (or NaN): that
 * submatrix is not positive definite in double precision. */
static uint32_t stsp_bandqp_chol(const double *W, uint32_t q, const uint32_t *idx, uint32_t n,
                                 double *chol)
{
    uint32_t pd = 1u;
    uint32_t i;
    for (i = 0u; (i < n) && (pd != 0u); ++i) {
        uint32_t j;
        for (j = 0u; (j <= i) && (pd != 0u); ++j) {
            double s = W[(idx[i] * q) + idx[j]];
            uint32_t k;
            for (k = 0u; k < j; ++k) {
                s -= chol[(i * n) + k] * chol[(j * n) + k];
            }
            if (i != j) {
                chol[(i * n) + j] = s / chol[(j * n) + j];
            } else if (s > 0.0) {
                chol[(i * n) + i] = stsp_bandqp_sqrt(s);
            } else {
                pd = 0u;
            }
        }
    }
    return pd;
}

/* 1 when W (q x q) is exactly symmetric: the solver then factors each candidate's W_AA by
 * Cholesky (W > 0, a per-tick band table's dual); otherwise by Gaussian elimination with
 * partial pivoting (a spline band table's W', a P-matrix: stsp_bandqp.h). A NaN entry makes W
 * non-symmetric (NaN != NaN); init refuses non-finite band data anyway. */
static uint32_t stsp_bandqp_symmetric(const double *W, uint32_t q)
{
    uint32_t sym = 1u;
    uint32_t i;
    for (i = 0u; i < q; ++i) {
        uint32_t j;
        for (j = 0u; j < i; ++j) {
            if (!(W[(i * q) + j] == W[(j * q) + i])) {
                sym = 0u;
            }
        }
    }
    return sym;
}

/* lam_A = W_AA^-1 (e_A - b_A) in work->rhs[0..na) for a general (non-symmetric) W, by
 * Gaussian elimination with partial pivoting on the copy W_AA in work->chol (row swaps applied
 * to the copy and to the right-hand side together), then back substitution. Returns 1, or 0
 * when a pivot is zero or not finite (W_AA singular in double precision, or an overflow): the
 * candidate is then skipped, as one whose Cholesky factor does not exist. Bounded: na <=
 * STSP_BANDQP_MAX, O(na^3). */
static uint32_t stsp_bandqp_gauss(const stsp_bandqp_t *qp, uint32_t q, const uint32_t *idx,
                                  uint32_t na, stsp_bandqp_work_t *work)
{
    double *M = work->chol;
    double *r = work->rhs;
    uint32_t ok = 1u;
    uint32_t a;
    uint32_t k;
    for (a = 0u; a < na; ++a) {
        const uint32_t row = idx[a];
        uint32_t b;
        for (b = 0u; b < na; ++b) {
            M[(a * na) + b] = qp->W[(row * q) + idx[b]];
        }
        r[a] = work->e[row] - ((work->state[row] > 0) ? qp->hi[row] : qp->lo[row]);
    }
    for (k = 0u; (k < na) && (ok != 0u); ++k) {
        uint32_t piv = k;
        double best = (M[(k * na) + k] < 0.0) ? -M[(k * na) + k] : M[(k * na) + k];
        uint32_t i;
        for (i = k + 1u; i < na; ++i) {
            const double v = M[(i * na) + k];
            const double mag = (v < 0.0) ? -v : v;
            if (mag > best) {
                best = mag;
                piv = i;
            }
        }
        /* A zero (or NaN, or infinite) pivot: no unique solution in double precision. */
        if (!((best > 0.0) && (best <= DBL_MAX))) {
            ok = 0u;
        } else {
            if (piv != k) {
                uint32_t c;
                double t;
                for (c = 0u; c < na; ++c) {
                    t = M[(k * na) + c];
                    M[(k * na) + c] = M[(piv * na) + c];
                    M[(piv * na) + c] = t;
                }
                t = r[k];
                r[k] = r[piv];
                r[piv] = t;
            }
            for (i = k + 1u; i < na; ++i) {
                const double f = M[(i * na) + k] / M[(k * na) + k];
                uint32_t c;
                for (c = k + 1u; c < na; ++c) {
                    M[(i * na) + c] -= f * M[(k * na) + c];
                }
                r[i] -= f * r[k];
            }
        }
    }
    if (ok != 0u) {
        for (a = 0u; a < na; ++a) {
            const uint32_t row = na - 1u - a;
            double s = r[row];
            uint32_t b;
            for (b = row + 1u; b < na; ++b) {
                s -= M[(row * na) + b] * r[b];
            }
            r[row] = s / M[(row * na) + row];
            /* An overflowed solution is no solution (the sign checks would pass a NaN). */
            if ((r[row] - r[row]) != 0.0) {
                ok = 0u;
            }
        }
    }
    return ok;
}

/* lam_A = W_AA^-1 (e_A - b_A) in work->rhs[0..na) (forward then backward substitution with
 * the factor in work->chol); b_A is hi at an upper bound (and on equality rows), lo at a
 * lower one. */
static void stsp_bandqp_subst(const stsp_bandqp_t *qp, const uint32_t *idx, uint32_t na,
                              stsp_bandqp_work_t *work)
{
    uint32_t a;
    for (a = 0u; a < na; ++a) {
        const uint32_t r = idx[a];
        const double bound = (work->state[r] > 0) ? qp->hi[r] : qp->lo[r];
        double s = work->e[r] - bound;
        uint32_t b;
        for (b = 0u; b < a; ++b) {
            s -= work->chol[(a * na) + b] * work->rhs[b];
        }
        work->rhs[a] = s / work->chol[(a * na) + a];
    }
    for (a = 0u; a < na; ++a) {
        const uint32_t row = na - 1u - a;
        double s = work->rhs[row];
        uint32_t b;
        for (b = row + 1u; b < na; ++b) {
            s -= work->chol[(b * na) + row] * work->rhs[b];
        }
        work->rhs[row] = s / work->chol[(row * na) + row];
    }
}

/* The KKT conditions of the candidate whose multipliers are lam: lam_i >= 0 at an upper
 * bound, lam_i <= 0 at a lower bound, lo_i - tol <= y_i <= hi_i + tol on inactive rows, with
 * y = e - W lam (into work->y, up to the first row that fails). Returns 1 when all hold. */
static uint32_t stsp_bandqp_kkt(const stsp_bandqp_t *qp, uint32_t q, const double *lam,
                                stsp_bandqp_work_t *work)
{
    uint32_t ok = 1u;
    uint32_t i;
    for (i = 0u; (i < q) && (ok != 0u); ++i) {
        double y = work->e[i];
        uint32_t j;
        for (j = 0u; j < q; ++j) {
            y -= qp->W[(i * q) + j] * lam[j];
        }
        work->y[i] = y;
        if (stsp_bandqp_is_eq(qp, i) != 0u) {
            /* equality row: no sign condition */
        } else if (work->state[i] > 0) {
            if (lam[i] < 0.0) {
                ok = 0u;
            }
        } else if (work->state[i] < 0) {
            if (lam[i] > 0.0) {
                ok = 0u;
            }
        } else {
            const double hi = qp->hi[i];
            const double tol = 1e-12 * (1.0 + ((hi > 0.0) ? hi : -hi));
            if ((y > (hi + tol)) || (y < (qp->lo[i] - tol))) {
                ok = 0u;
            }
        }
    }
    return ok;
}

/* The next candidate: the band rows' states as a ternary counter (digit 0 inactive, then -1
 * at the lower bound, then +1 at the upper bound; row 0 the least significant digit);
 * equality rows stay at +1. After the last candidate every band row is back to 0. */
static void stsp_bandqp_next(const stsp_bandqp_t *qp, uint32_t q, int8_t *state)
{
    uint32_t carry = 1u;
    uint32_t i;
    for (i = 0u; (i < q) && (carry != 0u); ++i) {
        if (stsp_bandqp_is_eq(qp, i) == 0u) {
            if (state[i] == 0) {
                state[i] = -1;
                carry = 0u;
            } else if (state[i] < 0) {
                state[i] = 1;
                carry = 0u;
            } else {
                state[i] = 0; /* carry into the next band row */
            }
        }
    }
}

stsp_bandqp_status_t stsp_bandqp_solve(const stsp_bandqp_t *qp, const float *x0, double *lam,
                                       stsp_bandqp_work_t *work, uint32_t *candidates)
{
    uint32_t q;
    uint32_t nx;
    uint32_t i;
    uint32_t n_cand = 1u;
    uint32_t tried = 0u;
    uint32_t found = 0u;
    uint32_t sym;
    uint32_t idx[STSP_BANDQP_MAX];

    if (candidates != NULL) {
        *candidates = 0u;
    }
    if ((qp == NULL) || (x0 == NULL) || (lam == NULL) || (work == NULL) || (qp->Nt == NULL) ||
        (qp->mt == NULL) || (qp->W == NULL) || (qp->lo == NULL) || (qp->hi == NULL)) {
        return STSP_BANDQP_ERR_NULL;
    }
    q = qp->q;
    nx = qp->nx;
    if ((q == 0u) || (q > STSP_BANDQP_MAX) || (nx == 0u)) {
        return STSP_BANDQP_ERR_DIMS;
    }
    for (i = 0u; i < q; ++i) {
        lam[i] = 0.0;
    }
    for (i = 0u; i < nx; ++i) {
        if (stsp_isfinite_f32(x0[i]) == 0) {
            return STSP_BANDQP_ERR_NONFINITE;
        }
    }
    /* e = Nt x0 + mt; equality rows start (and stay) active at +1, band rows inactive; the
     * number of candidates is 3^(band rows) <= 3^STSP_BANDQP_MAX. */
    for (i = 0u; i < q; ++i) {
        double acc = qp->mt[i];
        uint32_t j;
        for (j = 0u; j < nx; ++j) {
            acc += qp->Nt[(i * nx) + j] * (double)x0[j];
        }
        /* Finite data and state can still overflow here: then there is nothing to solve. */
        if ((acc - acc) != 0.0) {
            return STSP_BANDQP_ERR_NONFINITE;
        }
        work->e[i] = acc;
        if (stsp_bandqp_is_eq(qp, i) != 0u) {
            work->state[i] = 1;
        } else {
            work->state[i] = 0;
            n_cand *= 3u;
        }
    }

    /* Each candidate active set once, in counter order, until one meets the conditions:
     * W_AA by Cholesky when W is symmetric, by Gaussian elimination otherwise. */
    sym = stsp_bandqp_symmetric(qp->W, q);
    for (tried = 0u; (tried < n_cand) && (found == 0u); ++tried) {
        const uint32_t na = stsp_bandqp_active(work->state, q, idx);
        uint32_t solved;
        if (sym != 0u) {
            solved = stsp_bandqp_chol(qp->W, q, idx, na, work->chol);
            if (solved != 0u) {
                stsp_bandqp_subst(qp, idx, na, work);
            }
        } else {
            solved = stsp_bandqp_gauss(qp, q, idx, na, work);
        }
        if (solved != 0u) {
            uint32_t a;
            for (i = 0u; i < q; ++i) {
                lam[i] = 0.0;
            }
            for (a = 0u; a < na; ++a) {
                lam[idx[a]] = work->rhs[a];
            }
            found = stsp_bandqp_kkt(qp, q, lam, work);
        }
        if (found == 0u) {
            stsp_bandqp_next(qp, q, work->state);
        }
    }
    if (candidates != NULL) {
        *candidates = tried;
    }
    if (found == 0u) {
        for (i = 0u; i < q; ++i) {
            lam[i] = 0.0;
        }
    }
    return (found != 0u) ? STSP_BANDQP_OK : STSP_BANDQP_ERR_INFEASIBLE;
}

stsp_bandqp_status_t stsp_bandqp_solve_f32(const stsp_bandqp_t *qp, const float *x0, float *v)
{
    stsp_bandqp_work_t work;
    double lam[STSP_BANDQP_MAX];
    uint32_t i;
    const stsp_bandqp_status_t st = stsp_bandqp_solve(qp, x0, lam, &work, NULL);
    if (st != STSP_BANDQP_OK) {
        return st;
    }
    if (v == NULL) {
        return STSP_BANDQP_ERR_NULL;
    }
    /* A multiplier beyond the binary32 range has no float value (the conversion would be
     * undefined). */
    for (i = 0u; i < qp->q; ++i) {
        if (!((lam[i] <= (double)FLT_MAX) && (lam[i] >= -(double)FLT_MAX))) {
            return STSP_BANDQP_ERR_RANGE;
        }
    }
    for (i = 0u; i < qp->q; ++i) {
        v[i] = (float)lam[i];
    }
    return STSP_BANDQP_OK;
}
