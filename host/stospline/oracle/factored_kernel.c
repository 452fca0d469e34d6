/* Host-side kernel of the exact moment oracle for a noise-free, time-invariant stage
 * (stospline.oracle.evaluate.evaluate_table): the forward second-moment recursion over the
 * controller ticks with the tick's moment map in factored form.  Not firmware: it runs on
 * the design host, in double precision, called through cffi (stospline.oracle.kernel).
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
 * (T x n) the state's mean and variance after each tick, um, uv (T x m) the command's over it.
 */
#include <stddef.h>

size_t stsp_oracle_factored_work_size(int n, int m, int P)
{
    size_t dy = (size_t)n + (size_t)P + 1u, dw = (size_t)n + (size_t)m + 1u;
    return 2u * dw * dy + dw * dw + (size_t)n * dw;
}

int stsp_oracle_factored_ticks(int n, int m, int P, long T, const double *K, const double *L,
                               const double *k0, const double *Phi, const double *cost,
                               const double *Fmean, double *M, double *J, double *work,
                               double *xm, double *xv, double *um, double *uv)
{
    const int dy = n + P + 1, dw = n + m + 1;
    double *Tw = work, *TM = Tw + dw * dy, *Mw = TM + dw * dy, *X = Mw + dw * dw;
    const double *one = Phi + (dw - 1) * dw;      /* the constant's row of Phi */
    double acc = *J;
    long j;
    int a, b, c, k;
    const int record = xm != NULL;
    if (n < 1 || m < 1 || P < 0 || T < 0 || (xv != NULL) != record || (um != NULL) != record
        || (uv != NULL) != record) {
        return -2;
    }
    for (a = 0; a < dw * dy; ++a) {
        Tw[a] = 0.0;
    }
    for (a = 0; a < n; ++a) {
        Tw[a * dy + a] = 1.0;
    }
    Tw[(dw - 1) * dy + (dy - 1)] = 1.0;
    for (j = 0; j < T; ++j) {
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
        for (a = 0; a < n; ++a) {                  /* E x+ v' = Fmean E [x; u] v' */
            for (b = 0; b < P; ++b) {
                double s = 0.0;
                for (c = 0; c < n + m; ++c) {
                    s += Fmean[a * (n + m) + c] * TM[c * dy + n + b];
                }
                M[a * dy + n + b] = s;
                M[(n + b) * dy + a] = s;
            }
        }
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
    }
    *J = acc;
    return 0;
}
