/**
 * @file stsp_bandqp.h
 * @brief Exact on-target solver of the band dual: the joint multipliers for a measured x0.
 *
 * With band constraints lo <= E{C2 x(t_k)} <= hi and joint multipliers, the expected outputs
 * of the law with multiplier vector lam are y = e - W lam, e = Nt x0 + mt (Nt = N(t0)',
 * mt = m~(t0) of the design for zero targets), and the optimal lam solves the concave dual
 *
 *     max  2 lam'e - lam'W lam - 2 sum_i (lam_i > 0 ? lam_i hi_i : lam_i lo_i).
 *
 * W > 0, so the optimum is unique and is the one active set A (rows at a bound, value b_A)
 * whose solution lam_A = W_AA^-1 (e_A - b_A), lam = 0 elsewhere, satisfies the KKT conditions:
 * lam_i >= 0 at an upper bound, <= 0 at a lower bound, and lo <= y <= hi on the other rows.
 *
 * Method: enumerate the active sets of the band rows (equality rows, lo == hi, are always
 * active), each a Cholesky solve in double precision, and stop at the first that satisfies
 * the KKT conditions. Proven bound: at most 3^(band rows) candidate sets, each O(q^3); the
 * solver refuses more than STSP_BANDQP_MAX rows. No allocation, no recursion; the caller
 * provides the work buffer.
 *
 * Spline tables (non-symmetric W). For a law whose gains are a spline's evaluation, the
 * expected outputs are y = e - W lam with W = -C2 Gamma' computed under the evaluated gains
 * (host: stospline.table.spline.band): close to the design's SPD W, but not symmetric. The
 * conditions above are then a (mixed, box-constrained) linear complementarity problem, no
 * longer the optimality conditions of a concave dual. The host accepts such a table only when
 * W is a P-matrix (every principal minor positive); then, for every e, exactly one active set
 * meets the conditions (the box LCP of a P-matrix has a unique solution), every candidate's
 * W_AA is nonsingular, and the enumeration finds that set. The solver needs no flag for it:
 * when W is not exactly symmetric (W[i][j] != W[j][i] for some i, j; a symmetric P-matrix is
 * positive definite, so the Cholesky path covers it) each candidate is solved by Gaussian
 * elimination with partial pivoting instead, and a candidate with a zero or non-finite pivot
 * (or an overflowed solution) is skipped; if no candidate meets the conditions the status is
 * STSP_BANDQP_ERR_INFEASIBLE, as for a W that is not positive definite. Per-tick band tables
 * (W symmetric) take exactly the Cholesky path they always did. The bounds are the same:
 * 3^(band rows) candidates, O(q^3) each.
 */
#ifndef STSP_BANDQP_H
#define STSP_BANDQP_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/** Rows the solver accepts (3^8 = 6561 candidate active sets at most). */
#ifndef STSP_BANDQP_MAX
#define STSP_BANDQP_MAX 8u
#endif

/** Status of the solver (0 success, negative errors). */
typedef enum {
    STSP_BANDQP_OK = 0,
    STSP_BANDQP_ERR_NULL = -1,        /**< a pointer argument is NULL */
    STSP_BANDQP_ERR_DIMS = -2,        /**< q == 0, q > STSP_BANDQP_MAX or nx == 0 */
    STSP_BANDQP_ERR_NONFINITE = -3,   /**< x0 holds NaN or +-Inf, or Nt x0 + mt overflowed */
    STSP_BANDQP_ERR_INFEASIBLE = -4,  /**< no active set meets the conditions (W not > 0, or
                                           a non-symmetric W that is not a P-matrix) */
    STSP_BANDQP_ERR_RANGE = -5        /**< stsp_bandqp_solve_f32(): a multiplier lies beyond
                                           the binary32 range (+-FLT_MAX) */
} stsp_bandqp_status_t;

/** Const problem data, generated with the design (row-major). */
typedef struct stsp_bandqp {
    uint16_t q;              /**< stacked constraint rows */
    uint16_t nx;             /**< states */
    const double *Nt;        /**< [q][nx]: e = Nt x0 + mt */
    const double *mt;        /**< [q] */
    const double *W;         /**< [q][q]: symmetric positive definite (Cholesky), or a
                                  non-symmetric P-matrix (a spline table: Gaussian elimination) */
    const double *lo;        /**< [q] lower bounds (lo == hi: an equality row) */
    const double *hi;        /**< [q] upper bounds */
    /** The controller's band latch calls this: &stsp_bandqp_solve_f32, so that a program links
     * the solver only with a table that has a band dual; NULL: stsp_init() refuses the table
     * (STSP_ERR_BAD_DIMS). The solvers below do not read it. */
    stsp_bandqp_status_t (*solve_f32)(const struct stsp_bandqp *qp, const float *x0, float *v);
} stsp_bandqp_t;

/** Caller-owned scratch: q*q + 3*q doubles and q bytes at most. */
typedef struct {
    double chol[STSP_BANDQP_MAX * STSP_BANDQP_MAX]; /**< Cholesky factor, or eliminated W_AA */
    double e[STSP_BANDQP_MAX];
    double rhs[STSP_BANDQP_MAX];
    double y[STSP_BANDQP_MAX];
    int8_t state[STSP_BANDQP_MAX];
} stsp_bandqp_work_t;

/**
 * Multipliers lam[q] for the measured state x0[nx]; `candidates` (may be NULL) receives the
 * number of active sets tried (<= 3^(band rows)).
 * On STSP_BANDQP_ERR_NONFINITE (x0 not finite, or e = Nt x0 + mt overflowed) and
 * STSP_BANDQP_ERR_INFEASIBLE lam[0..q) is all zeros; on STSP_BANDQP_ERR_NULL and
 * STSP_BANDQP_ERR_DIMS lam is not written.
 */
stsp_bandqp_status_t stsp_bandqp_solve(const stsp_bandqp_t *qp, const float *x0, double *lam,
                                       stsp_bandqp_work_t *work, uint32_t *candidates);

/**
 * The stage-0 latch of a band table (the controller calls it): stsp_bandqp_solve() for x0,
 * then v[c] = (float)lam[c], c < q. Returns STSP_BANDQP_OK; a status of stsp_bandqp_solve()
 * (v not written); or STSP_BANDQP_ERR_RANGE when a multiplier lies beyond +-FLT_MAX (v not
 * written). Its work area and multipliers are on its own stack frame (sizeof
 * (stsp_bandqp_work_t) + STSP_BANDQP_MAX doubles). In the same object as stsp_bandqp_solve():
 * linking either links both (the controller calls this one through stsp_bandqp_t.solve_f32).
 */
stsp_bandqp_status_t stsp_bandqp_solve_f32(const stsp_bandqp_t *qp, const float *x0, float *v);

#ifdef __cplusplus
}
#endif

#endif /* STSP_BANDQP_H */
