/* Host-side kernel of the exact moment oracle (stospline.oracle.evaluate.evaluate_table): the forward
 * second-moment recursion over the controller ticks of one time-invariant stage.  Not
 * firmware: it runs on the design host, in double precision, called through cffi
 * (stospline.oracle.kernel), and equals the numpy loop of evaluate_table to rounding.
 *
 * Notation (oracle.py): n states, m inputs, P latched multipliers, y = [x; v; 1] (d_y =
 * n+P+1), w = [x; u; 1] (d_w = n+m+1), u = -K x - L v - k0 held over the tick.  Per tick j:
 *
 *     Tw   = [[I, 0, 0], [-K_j, -L_j, -k0_j], [0, 0, 1]]     (d_w x d_y)
 *     TM   = Tw M,  Mw = TM Tw'                                E w y', E w w'
 *     J   += cost . vech(Mw)
 *     out  = Phi_x vech(Mw)                                    E x+ x+', E x+ after the tick
 *     Mxv  = Fmean TM[0:n+m, n:n+P]                            E x+ v'
 *     M[x,x] = out[x,x], M[x,1] = M[1,x] = out[x,1], M[x,v] = Mxv, M[v,x] = Mxv'
 *
 * Mw is symmetric, so the caller packs the tick's moment map and cost row on its upper
 * triangle (vech: p <= q, row by row, as numpy.triu_indices) and keeps only the rows the
 * update reads (Phi_x: row a*(n+1)+b is E x+_a x+_b for b < n, and E x+_a for b = n).
 *
 * Row-major, caller-owned arrays: K (T x m x n), L (T x m x P), k0 (T x m), Phi_x
 * (n(n+1) x d_w(d_w+1)/2), cost (d_w(d_w+1)/2), Fmean (n x (n+m)), M (d_y x d_y, in/out),
 * J (in/out), work (stsp_oracle_work_size doubles).  The path (all four NULL, or none): xm,
 * xv (T x n) the state's mean and variance after each tick, um, uv (T x m) the command's
 * over it (oracle.evaluate_table's path=True, which the Q scales read at every tick).
 * xx (T x n x (n+1), or NULL): the state's second moments and mean after each tick, rows
 * [E x_a x_b (b < n), E x_a] (the moments of an output, oracle.evaluate_table's output=).
 */
#include <stddef.h>

/* Any dimension out of range, or a path given in part: -2 (both loops). */
static int oracle_bad_args(int n, int m, int P, long T, const double *xm, const double *xv,
                           const double *um, const double *uv)
{
    const int record = xm != NULL;
    return n < 1 || m < 1 || P < 0 || T < 0 || (xv != NULL) != record
           || (um != NULL) != record || (uv != NULL) != record;
}

/* Tw's fixed rows: the identity on x and the constant; the gain rows are set per tick. */
static void oracle_tw_fixed(double *Tw, int n, int dw, int dy)
{
    int a;
    for (a = 0; a < dw * dy; ++a) {
        Tw[a] = 0.0;
    }
    for (a = 0; a < n; ++a) {
        Tw[a * dy + a] = 1.0;
    }
    Tw[(dw - 1) * dy + (dy - 1)] = 1.0;
}

/* Tw's rows of u at tick j: [-K_j, -L_j, -k0_j]. */
static void oracle_tw_gains(double *Tw, const double *K, const double *L, const double *k0,
                            long j, int n, int m, int P, int dy)
{
    int a, b;
    for (a = 0; a < m; ++a) {
        double *row = Tw + (n + a) * dy;
        for (b = 0; b < n; ++b) {
            row[b] = -K[(j * m + a) * n + b];
        }
        for (b = 0; b < P; ++b) {
            row[n + b] = -L[(j * m + a) * P + b];
        }
        row[dy - 1] = -k0[j * m + a];
    }
}

/* E x+ v' = Fmean E [x; u] v' into M's x-v blocks (both triangles). */
static void oracle_cross_latch(double *M, const double *Fmean, const double *TM, int n, int m,
                               int P, int dy)
{
    int a, b, c;
    for (a = 0; a < n; ++a) {
        for (b = 0; b < P; ++b) {
            double s = 0.0;
            for (c = 0; c < n + m; ++c) {
                s += Fmean[a * (n + m) + c] * TM[c * dy + n + b];
            }
            M[a * dy + n + b] = s;
            M[(n + b) * dy + a] = s;
        }
    }
}

/* The state's moments after a tick, n x (n+1) row-major: [E x_a x_b (b < n), E x_a]. */
static void oracle_record_moments(double *xx, const double *M, int n, int dy)
{
    int a, b;
    for (a = 0; a < n; ++a) {
        for (b = 0; b < n; ++b) {
            xx[a * (n + 1) + b] = M[a * dy + b];
        }
        xx[a * (n + 1) + n] = M[a * dy + dy - 1];
    }
}

size_t stsp_oracle_work_size(int n, int m, int P)
{
    size_t dy = (size_t)n + (size_t)P + 1u, dw = (size_t)n + (size_t)m + 1u;
    return 2u * dw * dy + dw * (dw + 1u) / 2u + (size_t)n * ((size_t)n + 1u);
}

int stsp_oracle_stage_ticks(int n, int m, int P, long T, const double *K, const double *L,
                            const double *k0, const double *Phi_x, const double *cost,
                            const double *Fmean, double *M, double *J, double *work,
                            double *xm, double *xv, double *um, double *uv, double *xx)
{
    const int dy = n + P + 1, dw = n + m + 1, nv = dw * (dw + 1) / 2, nout = n * (n + 1);
    double *Tw = work, *TM = Tw + dw * dy, *vw = TM + dw * dy, *out = vw + nv;
    double acc = *J;
    long j;
    int a, b, c, k;
    const int record = xm != NULL;
    if (oracle_bad_args(n, m, P, T, xm, xv, um, uv)) {
        return -2;
    }
    oracle_tw_fixed(Tw, n, dw, dy);
    for (j = 0; j < T; ++j) {
        oracle_tw_gains(Tw, K, L, k0, j, n, m, P, dy);
        for (a = 0; a < dw; ++a) {                 /* TM = Tw M */
            for (b = 0; b < dy; ++b) {
                double s = 0.0;
                for (c = 0; c < dy; ++c) {
                    s += Tw[a * dy + c] * M[c * dy + b];
                }
                TM[a * dy + b] = s;
            }
        }
        k = 0;
        for (a = 0; a < dw; ++a) {                 /* vech(TM Tw') */
            for (b = a; b < dw; ++b) {
                double s = 0.0;
                for (c = 0; c < dy; ++c) {
                    s += TM[a * dy + c] * Tw[b * dy + c];
                }
                vw[k] = s;
                acc += cost[k] * s;
                ++k;
            }
        }
        if (record) {                              /* u's moments: vech rows n..n+m-1 */
            for (a = 0; a < m; ++a) {
                const int row = n + a;            /* vech index of (row, q): row-major */
                const int base = row * dw - row * (row - 1) / 2 - row;
                const double mu = vw[base + dw - 1];
                um[j * m + a] = mu;
                uv[j * m + a] = vw[base + row] - mu * mu;
            }
        }
        for (a = 0; a < nout; ++a) {               /* the x rows of the moment map */
            double s = 0.0;
            for (c = 0; c < nv; ++c) {
                s += Phi_x[a * nv + c] * vw[c];
            }
            out[a] = s;
        }
        oracle_cross_latch(M, Fmean, TM, n, m, P, dy);  /* E x+ v' */
        for (a = 0; a < n; ++a) {
            for (b = 0; b < n; ++b) {
                M[a * dy + b] = out[a * (n + 1) + b];
            }
            M[a * dy + dy - 1] = out[a * (n + 1) + n];
            M[(dy - 1) * dy + a] = out[a * (n + 1) + n];
        }
        if (record) {
            for (a = 0; a < n; ++a) {
                const double mu = out[a * (n + 1) + n];
                xm[j * n + a] = mu;
                xv[j * n + a] = out[a * (n + 1) + a] - mu * mu;
            }
        }
        if (xx != NULL) {
            oracle_record_moments(xx + j * nout, M, n, dy);
        }
    }
    *J = acc;
    return 0;
}

/* The loop for a noise-free stage: the tick's moment map in factored form.
 *
 * Without noise one tick maps E w w' (w = [x; u; 1], u held) to Phi E w w' Phi' with
 * Phi = exp(Ahat h) (d_w x d_w), so the tick costs O(n d_w^2) products instead of the
 * O(n^2 d_w^2) of the packed moment map (the general kernel of the oracle).
 *
 * Notation as the general kernel: n states, m inputs, P latched multipliers, y = [x; v; 1]
 * (d_y = n+P+1), u = -K x - L v - k0 held over the tick.  Per tick j:
 *
 *     Tw   = [[I, 0, 0], [-K_j, -L_j, -k0_j], [0, 0, 1]]     (d_w x d_y)
 *     TM   = Tw M,  Mw = TM Tw'                                E w y', E w w'
 *     J   += cost . vech(Mw)
 *     X    = Phi[0:n, :] Mw                                    (n x d_w)
 *     E x+ x+' = X Phi[0:n, :]',  E x+ = X Phi[d_w-1, :]'
 *     Mxv  = Fmean TM[0:n+m, n:n+P]                            E x+ v'
 *
 * Row-major, caller-owned arrays: K (T x m x n), L (T x m x P), k0 (T x m), Phi (d_w x d_w),
 * cost (d_w(d_w+1)/2: the cost row on the upper triangle, row by row, off-diagonal entries
 * counted twice), Fmean (n x (n+m)), M (d_y x d_y, in/out), J (in/out), work
 * (stsp_oracle_factored_work_size doubles).  The path (all four NULL, or none): xm, xv
 * (T x n) the state's mean and variance after each tick, um, uv (T x m) the command's over it;
 * xx as the general loop's.
 */

size_t stsp_oracle_factored_work_size(int n, int m, int P)
{
    size_t dy = (size_t)n + (size_t)P + 1u, dw = (size_t)n + (size_t)m + 1u;
    return 2u * dw * dy + dw * dw + (size_t)n * dw;
}

int stsp_oracle_factored_ticks(int n, int m, int P, long T, const double *K, const double *L,
                               const double *k0, const double *Phi, const double *cost,
                               const double *Fmean, double *M, double *J, double *work,
                               double *xm, double *xv, double *um, double *uv, double *xx)
{
    const int dy = n + P + 1, dw = n + m + 1;
    double *Tw = work, *TM = Tw + dw * dy, *Mw = TM + dw * dy, *X = Mw + dw * dw;
    const double *one = Phi + (dw - 1) * dw;      /* the constant's row of Phi */
    double acc = *J;
    long j;
    int a, b, c, k;
    const int record = xm != NULL;
    if (oracle_bad_args(n, m, P, T, xm, xv, um, uv)) {
        return -2;
    }
    oracle_tw_fixed(Tw, n, dw, dy);
    for (j = 0; j < T; ++j) {
        oracle_tw_gains(Tw, K, L, k0, j, n, m, P, dy);
        /* TM = Tw M: the rows of x and of the constant are rows of M. */
        for (a = 0; a < n; ++a) {
            for (b = 0; b < dy; ++b) {
                TM[a * dy + b] = M[a * dy + b];
            }
        }
        for (b = 0; b < dy; ++b) {
            TM[(dw - 1) * dy + b] = M[(dy - 1) * dy + b];
        }
        for (a = n; a < n + m; ++a) {
            for (b = 0; b < dy; ++b) {
                double s = 0.0;
                for (c = 0; c < dy; ++c) {
                    s += Tw[a * dy + c] * M[c * dy + b];
                }
                TM[a * dy + b] = s;
            }
        }
        /* Mw = TM Tw' (upper triangle, mirrored), and the tick's cost. */
        k = 0;
        for (a = 0; a < dw; ++a) {
            for (b = a; b < dw; ++b) {
                double s;
                if (b < n) {
                    s = TM[a * dy + b];
                } else if (b == dw - 1) {
                    s = TM[a * dy + dy - 1];
                } else {
                    s = 0.0;
                    for (c = 0; c < dy; ++c) {
                        s += TM[a * dy + c] * Tw[b * dy + c];
                    }
                }
                Mw[a * dw + b] = s;
                Mw[b * dw + a] = s;
                acc += cost[k] * s;
                ++k;
            }
        }
        if (record) {
            for (a = 0; a < m; ++a) {
                const double mu = Mw[(n + a) * dw + dw - 1];
                um[j * m + a] = mu;
                uv[j * m + a] = Mw[(n + a) * dw + n + a] - mu * mu;
            }
        }
        for (a = 0; a < n; ++a) {                  /* X = Phi[0:n, :] Mw */
            for (b = 0; b < dw; ++b) {
                X[a * dw + b] = 0.0;
            }
            for (c = 0; c < dw; ++c) {
                const double p = Phi[a * dw + c];
                const double *mrow = Mw + c * dw;
                double *xrow = X + a * dw;
                for (b = 0; b < dw; ++b) {
                    xrow[b] += p * mrow[b];
                }
            }
        }
        oracle_cross_latch(M, Fmean, TM, n, m, P, dy);  /* E x+ v' */
        for (a = 0; a < n; ++a) {                  /* E x+ x+' = X Phi_x', E x+ = X Phi_1' */
            const double *xrow = X + a * dw;
            double mu = 0.0;
            for (b = a; b < n; ++b) {
                const double *prow = Phi + b * dw;
                double s = 0.0;
                for (c = 0; c < dw; ++c) {
                    s += xrow[c] * prow[c];
                }
                M[a * dy + b] = s;
                M[b * dy + a] = s;
            }
            for (c = 0; c < dw; ++c) {
                mu += xrow[c] * one[c];
            }
            M[a * dy + dy - 1] = mu;
            M[(dy - 1) * dy + a] = mu;
        }
        if (record) {
            for (a = 0; a < n; ++a) {
                const double mu = M[a * dy + dy - 1];
                xm[j * n + a] = mu;
                xv[j * n + a] = M[a * dy + a] - mu * mu;
            }
        }
        if (xx != NULL) {
            oracle_record_moments(xx + j * n * (n + 1), M, n, dy);
        }
    }
    *J = acc;
    return 0;
}
