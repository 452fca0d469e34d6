/* Host-side kernel of the exact zero-order-hold designer (stospline.design.zoh): the backward
 * Riccati recursion over the controller ticks of one stage.  Not firmware: it runs on the
 * design host, in double precision, called from Python through cffi (stospline.design.kernels).
 *
 * Notation (design_zoh.py): n states, m inputs, q multipliers acting on the stage, d = n+m+1,
 * z = [x; u; 1], r = n+1 ("x,1" rows: indices 0..n-1 and d-1 of z).  A symmetric matrix is
 * "packed" as its upper triangle, row by row (numpy.triu_indices order).  Per tick j, going
 * backward from T-1 to 0:
 *
 *     H    = mat(A2s vech V) + Hc              (d x d, value before the tick, as z'Hz)
 *     Hl   = N'F,  Hl[:, d-1] += mv           (q x d)
 *     Huu  = Lc Lc'                            (Cholesky, m x m)
 *     Y    = Lc^-1 [Hur, Hlu']                 (m x (r+q));  G = Lc^-T Y = [Gr, Gl]
 *     K[j] = Gr[:, :n], k0[j] = Gr[:, n], L[j] = Gl
 *     V    = H[rs, rs] - Yr'Yr,   [N', mv] = Hl[:, rs] - Yl'Yr,   W += Yl'Yl
 *
 * which is the numpy reference (design_zoh._stage_ticks_numpy) with Hur'Huu^-1 Hur = Yr'Yr
 * etc. written through the Cholesky factor, so V and W stay symmetric by construction.
 *
 * Row-major arrays, all caller-owned (nothing is allocated here):
 *   A2sT  (vs x ds)   transposed packed tick map, vs = r(r+1)/2, ds = d(d+1)/2
 *   Hcs   (ds)        packed expected running cost over one tick
 *   F     (n x d)     E x+ = F z
 *   V     (r x r)     in: value after the stage's last tick; out: before its first tick
 *   N (n x q), W (q x q), mv (q)   in/out likewise (the open multiplier terms)
 *   K (T x m x n), k0 (T x m), L (T x m x q)   out
 *   work  stsp_zoh_work_size(n, m, q) doubles
 */
#include <math.h>
#include <stddef.h>

enum {
    STSP_ZOH_OK = 0,
    STSP_ZOH_ERR_NOT_PD = -1,    /* Huu has a finite pivot <= 0 at tick *bad_tick */
    STSP_ZOH_ERR_DIMS = -2
};

size_t stsp_zoh_update_size(int n, int m, int q);

size_t stsp_zoh_work_size(int n, int m, int q)
{
    size_t d = (size_t)n + (size_t)m + 1u, r = (size_t)n + 1u;
    size_t ds = d * (d + 1u) / 2u, vs = r * (r + 1u) / 2u;
    return d * d + ds + vs + stsp_zoh_update_size(n, m, q);
}

/* Lower Cholesky factor of the m x m block of H at rows/columns off..off+m-1.  Returns 0, or
 * -1 if a pivot is finite and <= 0.  A non-finite pivot (overflow upstream) is not reported
 * here: it propagates as inf/NaN, like the LU solve of the numpy reference, and the caller's
 * finiteness check names it. */
static int cholesky(int m, const double *H, int d, int off, double *Lc)
{
    int i, j, k;
    for (i = 0; i < m; ++i) {
        for (j = 0; j <= i; ++j) {
            double s = H[(size_t)(off + i) * d + (off + j)];
            for (k = 0; k < j; ++k) s -= Lc[i * m + k] * Lc[j * m + k];
            if (i == j) {
                if (isfinite(s) && s <= 0.0) return -1;
                Lc[i * m + i] = sqrt(s);
            } else {
                Lc[i * m + j] = s / Lc[j * m + j];
            }
        }
        for (j = i + 1; j < m; ++j) Lc[i * m + j] = 0.0;
    }
    return 0;
}

/* One backward tick given H (d x d, the value before the tick as z'Hz) and F (E x+ = F z), or
 * instead of F, Hl_in = N'F with mv added to its last column (q x d):
 * the gains of the tick into Kt (m x n), k0t (m), Lt (m x q), and the value before it into
 * vp (packed r x r), N, W, mv (in: after the tick).  work: stsp_zoh_update_size doubles.
 * Returns 0, or STSP_ZOH_ERR_NOT_PD when Huu has a finite pivot <= 0. */
size_t stsp_zoh_update_size(int n, int m, int q)
{
    size_t d = (size_t)n + (size_t)m + 1u, c = (size_t)n + 1u + (size_t)q;
    return (size_t)q * d + (size_t)m * m + 2u * (size_t)m * c;
}

int stsp_zoh_tick_update(int n, int m, int q, const double *H, const double *F,
                         const double *Hl_in, double *vp, double *N, double *W, double *mv,
                         double *Kt, double *k0t, double *Lt, double *work)
{
    const int d = n + m + 1, r = n + 1, c = r + q;
    double *Hl = work, *Lc = Hl + (size_t)q * d, *Y = Lc + (size_t)m * m,
           *G = Y + (size_t)m * c;
    int a, b, i, l, u, p;
#define RS(a) ((a) < n ? (a) : d - 1)
    /* Hl = N'F, last column += mv (uses N, mv of the tick after this one). */
    for (l = 0; l < q; ++l) {
        double *row = Hl + (size_t)l * d;
        if (Hl_in != NULL) {
            for (b = 0; b < d; ++b) row[b] = Hl_in[(size_t)l * d + b];
            continue;
        }
        for (b = 0; b < d; ++b) row[b] = 0.0;
        for (i = 0; i < n; ++i) {
            const double nil = N[i * q + l], *fr = F + (size_t)i * d;
            for (b = 0; b < d; ++b) row[b] += nil * fr[b];
        }
        row[d - 1] += mv[l];
    }

    if (cholesky(m, H, d, n, Lc)) return STSP_ZOH_ERR_NOT_PD;
    /* Y = Lc^-1 [Hur, Hlu'] by forward substitution, then G = Lc^-T Y. */
    for (u = 0; u < m; ++u) {
        const double *hu = H + (size_t)(n + u) * d;
        for (a = 0; a < r; ++a) Y[u * c + a] = hu[RS(a)];
        for (l = 0; l < q; ++l) Y[u * c + r + l] = Hl[l * d + n + u];
        for (i = 0; i < u; ++i) {
            const double f = Lc[u * m + i];
            for (a = 0; a < c; ++a) Y[u * c + a] -= f * Y[i * c + a];
        }
        for (a = 0; a < c; ++a) Y[u * c + a] /= Lc[u * m + u];
    }
    for (u = m - 1; u >= 0; --u) {
        for (a = 0; a < c; ++a) G[u * c + a] = Y[u * c + a];
        for (i = u + 1; i < m; ++i) {
            const double f = Lc[i * m + u];
            for (a = 0; a < c; ++a) G[u * c + a] -= f * G[i * c + a];
        }
        for (a = 0; a < c; ++a) G[u * c + a] /= Lc[u * m + u];
    }
    for (u = 0; u < m; ++u) {
        for (a = 0; a < n; ++a) Kt[u * n + a] = G[u * c + a];
        k0t[u] = G[u * c + n];
        for (l = 0; l < q; ++l) Lt[u * q + l] = G[u * c + r + l];
    }

    /* V = H[rs, rs] - Yr'Yr (packed). */
    for (a = 0, p = 0; a < r; ++a)
        for (b = a; b < r; ++b, ++p) {
            double s = H[RS(a) * d + RS(b)];
            for (u = 0; u < m; ++u) s -= Y[u * c + a] * Y[u * c + b];
            vp[p] = s;
        }
    /* [N', mv] = Hl[:, rs] - Yl'Yr;  W += Yl'Yl. */
    for (l = 0; l < q; ++l) {
        for (a = 0; a < r; ++a) {
            double s = Hl[l * d + RS(a)];
            for (u = 0; u < m; ++u) s -= Y[u * c + r + l] * Y[u * c + a];
            if (a < n) N[a * q + l] = s; else mv[l] = s;
        }
        for (b = l; b < q; ++b) {
            double s = W[l * q + b];
            for (u = 0; u < m; ++u) s += Y[u * c + r + l] * Y[u * c + r + b];
            W[l * q + b] = W[b * q + l] = s;
        }
    }
#undef RS
    return STSP_ZOH_OK;
}

int stsp_zoh_stage_ticks(int n, int m, int q, long T,
                         const double *A2sT, const double *Hcs, const double *F,
                         double *V, double *N, double *W, double *mv,
                         double *K, double *k0, double *L, double *work, long *bad_tick)
{
    const int d = n + m + 1, r = n + 1;
    const int ds = d * (d + 1) / 2, vs = r * (r + 1) / 2;
    double *H, *hs, *vp, *up;
    long t;
    int a, b, p;

    if (n < 1 || m < 1 || q < 0 || T < 0) return STSP_ZOH_ERR_DIMS;
    H = work;                 /* d x d */
    hs = H + (size_t)d * d;   /* ds */
    vp = hs + ds;             /* vs */
    up = vp + vs;             /* stsp_zoh_update_size */

    for (a = 0, p = 0; a < r; ++a)
        for (b = a; b < r; ++b, ++p) vp[p] = 0.5 * (V[a * r + b] + V[b * r + a]);

    for (t = T - 1; t >= 0; --t) {
        /* H = mat(A2s vp) + Hc, as a sum of columns of A2s (vectorisable, fixed order). */
        for (p = 0; p < ds; ++p) hs[p] = Hcs[p];
        for (b = 0; b + 4 <= vs; b += 4) {   /* four columns per pass, same summation order */
            const double *c0 = A2sT + (size_t)b * ds, *c1 = c0 + ds, *c2 = c1 + ds,
                         *c3 = c2 + ds;
            const double v0 = vp[b], v1 = vp[b + 1], v2 = vp[b + 2], v3 = vp[b + 3];
            for (p = 0; p < ds; ++p) {
                double s = hs[p];
                s += c0[p] * v0; s += c1[p] * v1; s += c2[p] * v2; s += c3[p] * v3;
                hs[p] = s;
            }
        }
        for (; b < vs; ++b) {
            const double *col = A2sT + (size_t)b * ds, v = vp[b];
            for (p = 0; p < ds; ++p) hs[p] += col[p] * v;
        }
        for (a = 0, p = 0; a < d; ++a)
            for (b = a; b < d; ++b, ++p) H[a * d + b] = H[b * d + a] = hs[p];
        if (stsp_zoh_tick_update(n, m, q, H, F, NULL, vp, N, W, mv, K + (size_t)t * m * n,
                                 k0 + (size_t)t * m, L + (size_t)t * m * q, up)) {
            if (bad_tick) *bad_tick = t;
            return STSP_ZOH_ERR_NOT_PD;
        }
    }
    for (a = 0, p = 0; a < r; ++a)
        for (b = a; b < r; ++b, ++p) V[a * r + b] = V[b * r + a] = vp[p];
    return STSP_ZOH_OK;
}
