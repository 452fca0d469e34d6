/* Host-side kernel of the estimator (stospline.estimator.filter_kernel): the filter's LMMSE
 * gains and the predictor's mean maps of the loop oracle.py evaluates, in double precision
 * with every sum in a fixed order and no BLAS or LAPACK, so that the same inputs give the
 * same bits on every CPU, BLAS kernel and thread count (the numpy recursion's error
 * covariance is a difference of second moments ~1e10 times larger, so the BLAS kernel's last
 * bits moved small gains by up to 6e-9 relative, across float32 and Q31 rounding boundaries).
 * Not firmware: it runs on the design host, called through cffi; built with
 * -ffp-contract=off (no fused multiply-adds, whatever the compiler's default), and uses only
 * + - * / and sqrt, which IEEE 754 rounds correctly.
 *
 * Notation (oracle.py, evaluate_estimator without faults or missed ticks): n states, m inputs,
 * P multipliers, p sensor outputs, z = [x; xh; v; 1] (d = 2n + P + 1), w = [x; u; 1]
 * (dw = n + m + 1).  E zz' = M starts at z0 z0' + prior covariance on x.  At tick j of stage k:
 *
 *   update (j % every == 0)  Pe = cov(x - xh) from M, R = V_j + sum_ab M_xaxb D_a D_b',
 *                            Lf = Pe C' (C Pe C' + R)^+  (pseudo-inverse: eigenvalues at most
 *                            1e-12 of the largest get no gain),  xh += Lf (C x + r - C xh)
 *   latch (first tick of a latching stage)  v = Lambda_k xh + lambda0_k
 *   tick                     u = -K_j xh - L_j v - k0_j,  E x+ x+' = Phi_k(E ww'),
 *                            xh+ = Fmean_k [xh; u; 1]
 *
 * Phi_k = expm(G_k h) with G_k the moment generator of stage k (kron(Ahat, I) + kron(I,
 * Ahat) + the noise columns), Fmean_k = expm(Ahat_k h)[0:n]: Higham's scaling and squaring
 * with Pade approximants, stospline.expm's algorithm (its degree and scaling; LU with partial
 * pivoting for the solve).
 *
 * Arrays row-major, caller-owned: stage_start (n_stages + 1), latch (n_stages: 1 latches at
 * the stage's first tick), Lambda (n_stages x P x n), lambda0 (n_stages x P), K (T x m x n),
 * L (T x m x P), k0 (T x m), Ahat (n_stages x dw x dw), G (n_stages x (n+m) x n x q) the
 * diffusion multipliers of [x; u], C (p x n), V (T x p x p, read at sampling ticks), D
 * (n x p x r, or NULL when r = 0), x0 (n), x0_cov (n x n); out: gain (T x n x p, zero between
 * samples), Fmean (n_stages x n x dw); work (stsp_filter_work_size doubles).
 * Returns 0; -1 bad dimensions; -2 a non-finite intermediate; -3 a matrix exponential that
 * would need more than 8 squarings (the caller runs the numpy loop instead).
 */
#include <stddef.h>
#include <math.h>
#include <stdint.h>

#define FK_MAX_SQUARINGS 8
#define FK_RCOND 1e-12
#define FK_JACOBI_SWEEPS 64

static const double fk_theta[5] = {1.495585217958292e-2, 2.539398330063230e-1,
                                   9.504178996162932e-1, 2.097847961257068e0,
                                   5.371920351148152e0};
static const double fk_b3[4] = {120., 60., 12., 1.};
static const double fk_b5[6] = {30240., 15120., 3360., 420., 30., 1.};
static const double fk_b7[8] = {17297280., 8648640., 1995840., 277200., 25200., 1512., 56.,
                                1.};
static const double fk_b9[10] = {17643225600., 8821612800., 2075673600., 302702400.,
                                 30270240., 2162160., 110880., 3960., 90., 1.};
static const double fk_b13[14] = {64764752532480000., 32382376266240000., 7771770303897600.,
                                  1187353796428800., 129060195264000., 10559470521600.,
                                  670442572800., 33522128640., 1323241920., 40840800., 960960.,
                                  16380., 182., 1.};

static double fk_abs(double x)
{
    return x < 0.0 ? -x : x;
}

static int fk_finite(double x)
{
    return x - x == 0.0;
}

/* C = A B (a x b times b x c), sums in order of the inner index. */
static void fk_mul(double *C, const double *A, const double *B, int a, int b, int c)
{
    int i, j, k;
    for (i = 0; i < a; ++i) {
        for (j = 0; j < c; ++j) {
            double s = 0.0;
            for (k = 0; k < b; ++k) {
                s += A[i * b + k] * B[k * c + j];
            }
            C[i * c + j] = s;
        }
    }
}

/* C = A B' (a x b times (c x b)'). */
static void fk_mul_t(double *C, const double *A, const double *B, int a, int b, int c)
{
    int i, j, k;
    for (i = 0; i < a; ++i) {
        for (j = 0; j < c; ++j) {
            double s = 0.0;
            for (k = 0; k < b; ++k) {
                s += A[i * b + k] * B[j * b + k];
            }
            C[i * c + j] = s;
        }
    }
}

/* X = (Vm - U)^-1 (Vm + U), N x N, by LU with partial pivoting (the first largest pivot);
 * Vm and U are overwritten.  Returns 0, or -2 for a zero pivot. */
static int fk_pade_solve(double *X, double *Vm, double *U, int N, int *piv)
{
    int i, j, k;
    for (i = 0; i < N * N; ++i) {
        const double v = Vm[i], u = U[i];
        Vm[i] = v - u;
        X[i] = v + u;
    }
    for (k = 0; k < N; ++k) {
        int best = k;
        for (i = k + 1; i < N; ++i) {
            if (fk_abs(Vm[i * N + k]) > fk_abs(Vm[best * N + k])) {
                best = i;
            }
        }
        piv[k] = best;
        if (Vm[best * N + k] == 0.0) {
            return -2;
        }
        if (best != k) {
            for (j = 0; j < N; ++j) {
                double t = Vm[k * N + j];
                Vm[k * N + j] = Vm[best * N + j];
                Vm[best * N + j] = t;
                t = X[k * N + j];
                X[k * N + j] = X[best * N + j];
                X[best * N + j] = t;
            }
        }
        for (i = k + 1; i < N; ++i) {
            const double f = Vm[i * N + k] / Vm[k * N + k];
            Vm[i * N + k] = f;
            if (f != 0.0) {
                for (j = k + 1; j < N; ++j) {
                    Vm[i * N + j] -= f * Vm[k * N + j];
                }
                for (j = 0; j < N; ++j) {
                    X[i * N + j] -= f * X[k * N + j];
                }
            }
        }
    }
    for (k = N - 1; k >= 0; --k) {          /* back substitution, every column of X at once */
        for (j = 0; j < N; ++j) {
            double s = X[k * N + j];
            for (i = k + 1; i < N; ++i) {
                s -= Vm[k * N + i] * X[i * N + j];
            }
            X[k * N + j] = s / Vm[k * N + k];
        }
    }
    return 0;
}

/* Doubles of scratch fk_expm needs for an N x N matrix. */
static size_t fk_expm_work(int N)
{
    return (size_t)9 * (size_t)N * (size_t)N;
}

/* X = expm(A), N x N (stospline.expm.expm's algorithm); work: fk_expm_work(N) doubles and
 * piv N ints.  Returns 0, -2 (not finite, or a singular Pade denominator) or -3 (more than
 * FK_MAX_SQUARINGS squarings). */
static int fk_expm(double *X, const double *A, int N, double *work, int *piv)
{
    const size_t NN = (size_t)N * (size_t)N;
    double *A2 = work, *A4 = A2 + NN, *A6 = A4 + NN, *A8 = A6 + NN, *U = A8 + NN,
           *Vm = U + NN, *T = Vm + NN, *As = T + NN, *T2 = As + NN;
    double *Ap[5];
    double norm = 0.0;
    const double *b;
    int i, j, deg, s;
    for (j = 0; j < N; ++j) {
        double col = 0.0;
        for (i = 0; i < N; ++i) {
            col += fk_abs(A[i * N + j]);
        }
        if (!fk_finite(col)) {
            return -2;
        }
        if (col > norm) {
            norm = col;
        }
    }
    Ap[1] = A2;
    Ap[2] = A4;
    Ap[3] = A6;
    Ap[4] = A8;
    fk_mul(A2, A, A, N, N, N);
    for (deg = 3; deg <= 9; deg += 2) {
        const int idx = (deg - 3) / 2;
        if (deg >= 5) {
            fk_mul(Ap[(deg - 1) / 2], Ap[(deg - 3) / 2], A2, N, N, N);
        }
        if (norm <= fk_theta[idx]) {
            int k;
            b = deg == 3 ? fk_b3 : deg == 5 ? fk_b5 : deg == 7 ? fk_b7 : fk_b9;
            for (i = 0; i < (int)NN; ++i) {
                T[i] = 0.0;
                Vm[i] = 0.0;
            }
            for (i = 0; i < N; ++i) {
                T[i * N + i] = b[1];
                Vm[i * N + i] = b[0];
            }
            for (k = 1; k <= deg / 2; ++k) {
                const double *P = Ap[k];
                for (i = 0; i < (int)NN; ++i) {
                    T[i] = T[i] + b[2 * k + 1] * P[i];
                    Vm[i] = Vm[i] + b[2 * k] * P[i];
                }
            }
            fk_mul(U, A, T, N, N, N);
            return fk_pade_solve(X, Vm, U, N, piv);
        }
    }
    s = 0;
    if (norm > 0.0) {
        double r = norm / fk_theta[4];
        while (r > 1.0 && s <= FK_MAX_SQUARINGS) {       /* ceil(log2(norm / theta_13)) */
            r *= 0.5;
            ++s;
        }
    }
    if (s > FK_MAX_SQUARINGS) {
        return -3;
    }
    {
        double scale = 1.0;
        for (i = 0; i < s; ++i) {
            scale *= 0.5;
        }
        for (i = 0; i < (int)NN; ++i) {
            As[i] = A[i] * scale;                          /* exact: a power of two */
        }
    }
    b = fk_b13;
    fk_mul(A2, As, As, N, N, N);
    fk_mul(A4, A2, A2, N, N, N);
    fk_mul(A6, A4, A2, N, N, N);
    for (i = 0; i < (int)NN; ++i) {
        T[i] = b[13] * A6[i] + b[11] * A4[i] + b[9] * A2[i];
    }
    fk_mul(T2, A6, T, N, N, N);
    for (i = 0; i < (int)NN; ++i) {
        T2[i] = T2[i] + b[7] * A6[i] + b[5] * A4[i] + b[3] * A2[i];
    }
    for (i = 0; i < N; ++i) {
        T2[i * N + i] += b[1];
    }
    fk_mul(U, As, T2, N, N, N);
    for (i = 0; i < (int)NN; ++i) {
        T[i] = b[12] * A6[i] + b[10] * A4[i] + b[8] * A2[i];
    }
    fk_mul(Vm, A6, T, N, N, N);
    for (i = 0; i < (int)NN; ++i) {
        Vm[i] = Vm[i] + b[6] * A6[i] + b[4] * A4[i] + b[2] * A2[i];
    }
    for (i = 0; i < N; ++i) {
        Vm[i * N + i] += b[0];
    }
    i = fk_pade_solve(X, Vm, U, N, piv);
    if (i != 0) {
        return i;
    }
    for (j = 0; j < s; ++j) {
        fk_mul(T, X, X, N, N, N);
        for (i = 0; i < (int)NN; ++i) {
            X[i] = T[i];
        }
    }
    return 0;
}

/* The pseudo-inverse of the symmetric p x p matrix S (overwritten) into Sp: cyclic Jacobi
 * rotations (at most FK_JACOBI_SWEEPS sweeps), eigenvalues at most FK_RCOND of the largest
 * in magnitude dropped (numpy.linalg.pinv(hermitian=True, rcond=1e-12)).  Q: p x p work. */
static void fk_pinv_sym(double *Sp, double *S, double *Q, int p)
{
    int i, j, k, sweep;
    double wmax = 0.0;
    for (i = 0; i < p * p; ++i) {
        Q[i] = 0.0;
    }
    for (i = 0; i < p; ++i) {
        Q[i * p + i] = 1.0;
    }
    for (sweep = 0; sweep < FK_JACOBI_SWEEPS; ++sweep) {
        int rotated = 0;
        for (i = 0; i < p - 1; ++i) {
            for (j = i + 1; j < p; ++j) {
                const double aij = S[i * p + j], aii = S[i * p + i], ajj = S[j * p + j];
                double theta, t, c, sn;
                if (fk_abs(aij) <= 1e-18 * (fk_abs(aii) + fk_abs(ajj)) || aij == 0.0) {
                    S[i * p + j] = S[j * p + i] = 0.0;
                    continue;
                }
                rotated = 1;
                theta = (ajj - aii) / (2.0 * aij);
                t = 1.0 / (fk_abs(theta) + sqrt(theta * theta + 1.0));
                if (theta < 0.0) {
                    t = -t;
                }
                c = 1.0 / sqrt(t * t + 1.0);
                sn = t * c;
                for (k = 0; k < p; ++k) {          /* S <- J' S J, rotating rows and columns */
                    const double ski = S[k * p + i], skj = S[k * p + j];
                    S[k * p + i] = c * ski - sn * skj;
                    S[k * p + j] = sn * ski + c * skj;
                }
                for (k = 0; k < p; ++k) {
                    const double sik = S[i * p + k], sjk = S[j * p + k];
                    S[i * p + k] = c * sik - sn * sjk;
                    S[j * p + k] = sn * sik + c * sjk;
                }
                S[i * p + j] = S[j * p + i] = 0.0;
                for (k = 0; k < p; ++k) {
                    const double qki = Q[k * p + i], qkj = Q[k * p + j];
                    Q[k * p + i] = c * qki - sn * qkj;
                    Q[k * p + j] = sn * qki + c * qkj;
                }
            }
        }
        if (!rotated) {
            break;
        }
    }
    for (i = 0; i < p; ++i) {
        if (fk_abs(S[i * p + i]) > wmax) {
            wmax = fk_abs(S[i * p + i]);
        }
    }
    for (i = 0; i < p; ++i) {
        for (j = 0; j < p; ++j) {
            double s = 0.0;
            for (k = 0; k < p; ++k) {
                const double w = S[k * p + k];
                if (fk_abs(w) > FK_RCOND * wmax) {
                    s += Q[i * p + k] * (Q[j * p + k] / w);
                }
            }
            Sp[i * p + j] = s;
        }
    }
}

/* The moment generator of a stage times h (D x D, D = dw^2): vec M row-major, d/dt M = Ahat M
 * + M Ahat' + sum_ij M_ij Gbar_i Gbar_j' (stospline.design.moments.moment_generator). */
static void fk_generator(double *out, const double *Ahat, const double *G, int n, int m, int q,
                         int dw, double h)
{
    const int D = dw * dw;
    int a, b, c, e, k;
    for (a = 0; a < D * D; ++a) {
        out[a] = 0.0;
    }
    for (a = 0; a < dw; ++a) {
        for (b = 0; b < dw; ++b) {
            double *row = out + (size_t)(a * dw + b) * (size_t)D;
            for (c = 0; c < dw; ++c) {
                row[c * dw + b] += Ahat[a * dw + c];       /* kron(Ahat, I) */
                row[a * dw + c] += Ahat[b * dw + c];       /* kron(I, Ahat) */
            }
            if (a < n && b < n) {
                for (c = 0; c < n + m; ++c) {
                    for (e = 0; e < n + m; ++e) {
                        double s = 0.0;
                        for (k = 0; k < q; ++k) {
                            s += G[((size_t)c * n + a) * q + k] * G[((size_t)e * n + b) * q + k];
                        }
                        row[c * dw + e] += s;
                    }
                }
            }
        }
    }
    for (a = 0; a < D * D; ++a) {
        out[a] *= h;
    }
}

static size_t fk_sq(int a)
{
    return (size_t)a * (size_t)a;
}

/* The layout of the work array (doubles), in one place for the size and the pointers. */
typedef struct {
    double *Phi, *Gen, *ew, *M, *Mt, *U, *Tl, *Tw, *TM, *Ta, *Mw, *Ed, *Pe, *R, *S, *Sp, *Qj,
           *PCt, *Lf, *LfC, *FTM, *Fm;
} fk_work;

static size_t fk_layout(fk_work *w, double *base, int n, int m, int P, int p)
{
    const int d = 2 * n + P + 1, dw = n + m + 1, D = dw * dw, big = p > n ? p : n;
    const size_t sizes[22] = {fk_sq(D), fk_sq(D), fk_expm_work(D), fk_sq(d), fk_sq(d),
                              fk_sq(d), fk_sq(d), (size_t)dw * d, (size_t)dw * d,
                              (size_t)dw * d, fk_sq(dw), fk_sq(dw), fk_sq(big), fk_sq(big),
                              fk_sq(big), fk_sq(big), fk_sq(big), (size_t)n * p,
                              (size_t)n * p, fk_sq(big), (size_t)n * (d > p ? d : p),
                              (size_t)n * d};
    double **ptr[22];
    size_t total = 0;
    int i;
    ptr[0] = &w->Phi; ptr[1] = &w->Gen; ptr[2] = &w->ew; ptr[3] = &w->M; ptr[4] = &w->Mt;
    ptr[5] = &w->U; ptr[6] = &w->Tl; ptr[7] = &w->Tw; ptr[8] = &w->TM; ptr[9] = &w->Ta;
    ptr[10] = &w->Mw; ptr[11] = &w->Ed; ptr[12] = &w->Pe; ptr[13] = &w->R; ptr[14] = &w->S;
    ptr[15] = &w->Sp; ptr[16] = &w->Qj; ptr[17] = &w->PCt; ptr[18] = &w->Lf;
    ptr[19] = &w->LfC; ptr[20] = &w->FTM; ptr[21] = &w->Fm;
    for (i = 0; i < 22; ++i) {
        *ptr[i] = base == NULL ? NULL : base + total;
        total += sizes[i];
    }
    return total;
}

size_t stsp_filter_work_size(int n, int m, int P, int p)
{
    fk_work w;
    return fk_layout(&w, NULL, n, m, P, p);
}

size_t stsp_filter_iwork_size(int n, int m)
{
    const int dw = n + m + 1;
    return (size_t)(dw * dw);
}

/* 1 when stage k's Ahat and G equal stage k - 1's (its maps are reused). */
static int fk_same_stage(const double *Ahat, const double *G, int k, size_t na, size_t ng)
{
    size_t i;
    for (i = 0; i < na; ++i) {
        if (Ahat[(size_t)k * na + i] != Ahat[(size_t)(k - 1) * na + i]) {
            return 0;
        }
    }
    for (i = 0; i < ng; ++i) {
        if (G[(size_t)k * ng + i] != G[(size_t)(k - 1) * ng + i]) {
            return 0;
        }
    }
    return 1;
}

int stsp_filter_gains(int n, int m, int P, int p, long T, int n_stages, int every, int q,
                      int r, double h, const int64_t *stage_start, const int *latch,
                      const double *Lambda, const double *lambda0, const double *K,
                      const double *L, const double *k0, const double *Ahat, const double *G,
                      const double *C, const double *V, const double *Dm, const double *x0,
                      const double *x0_cov, double *gain, double *Fmean, double *work,
                      int *iwork)
{
    const int d = 2 * n + P + 1, dw = n + m + 1, D = dw * dw;
    const int xs = 0, hs = n, vs = 2 * n, one = d - 1;
    fk_work w;
    double *Phi, *Gen, *ew, *M, *Mt, *U, *Tl, *Tw, *TM, *Ta, *Mw, *Ed, *Pe, *R, *S, *Sp, *Qj,
           *PCt, *Lf, *LfC, *FTM, *Fm;
    const size_t ng = (size_t)(n + m) * (size_t)n * (size_t)(q > 0 ? q : 1);
    long a, b, c, j;
    int k, st;
    if (n < 1 || m < 1 || P < 0 || p < 1 || T < 1 || n_stages < 1 || every < 1 || q < 0
        || r < 0 || !(h > 0.0) || stage_start[0] != 0 || stage_start[n_stages] != T) {
        return -1;
    }
    for (k = 0; k < n_stages; ++k) {
        if (stage_start[k + 1] <= stage_start[k]) {
            return -1;
        }
    }
    fk_layout(&w, work, n, m, P, p);
    Phi = w.Phi; Gen = w.Gen; ew = w.ew; M = w.M; Mt = w.Mt; U = w.U; Tl = w.Tl; Tw = w.Tw;
    TM = w.TM; Ta = w.Ta; Mw = w.Mw; Ed = w.Ed; Pe = w.Pe; R = w.R; S = w.S; Sp = w.Sp;
    Qj = w.Qj; PCt = w.PCt; Lf = w.Lf; LfC = w.LfC; FTM = w.FTM; Fm = w.Fm;
    /* M = z0 z0' + the prior covariance on x. */
    for (a = 0; a < d * d; ++a) {
        M[a] = 0.0;
    }
    for (a = 0; a < d; ++a) {                        /* z0 = [x0; x0; 0; 1] in Mt */
        Mt[a] = 0.0;
    }
    for (a = 0; a < n; ++a) {
        Mt[xs + a] = x0[a];
        Mt[hs + a] = x0[a];
    }
    Mt[one] = 1.0;
    for (a = 0; a < d; ++a) {
        for (b = 0; b < d; ++b) {
            M[a * d + b] = Mt[a] * Mt[b];
        }
    }
    for (a = 0; a < n; ++a) {
        for (b = 0; b < n; ++b) {
            M[(xs + a) * d + xs + b] += x0_cov[a * n + b];
        }
    }
    for (a = 0; a < T * n * p; ++a) {
        gain[a] = 0.0;
    }
    for (k = 0; k < n_stages; ++k) {
        const double *Ah = Ahat + (size_t)k * fk_sq(dw);
        double *Fk = Fmean + (size_t)k * n * dw;
        if (k > 0 && fk_same_stage(Ahat, G, k, fk_sq(dw), ng)) {
            for (a = 0; a < n * dw; ++a) {
                Fk[a] = Fk[a - n * dw];                  /* Phi is still the last stage's */
            }
        } else {
            fk_generator(Gen, Ah, G + (size_t)k * ng, n, m, q, dw, h);
            st = fk_expm(Phi, Gen, D, ew, iwork);
            if (st != 0) {
                return st;
            }
            for (a = 0; a < dw * dw; ++a) {
                Mw[a] = Ah[a] * h;
            }
            st = fk_expm(Ed, Mw, dw, ew, iwork);
            if (st != 0) {
                return st;
            }
            for (a = 0; a < n * dw; ++a) {
                Fk[a] = Ed[a];
            }
        }
        for (j = stage_start[k]; j < stage_start[k + 1]; ++j) {
            if (j % every == 0) {
                const double *Vj = V + (size_t)j * p * p;
                for (a = 0; a < n; ++a) {
                    for (b = 0; b < n; ++b) {
                        Pe[a * n + b] = ((M[(xs + a) * d + xs + b] - M[(xs + a) * d + hs + b])
                                         - M[(hs + a) * d + xs + b]) + M[(hs + a) * d + hs + b];
                    }
                }
                for (a = 0; a < n; ++a) {
                    for (b = 0; b < a; ++b) {
                        const double s = 0.5 * (Pe[a * n + b] + Pe[b * n + a]);
                        Pe[a * n + b] = Pe[b * n + a] = s;
                    }
                }
                for (a = 0; a < p; ++a) {
                    for (b = 0; b < p; ++b) {
                        double s = 0.0;
                        int x, y, t;
                        for (x = 0; x < n && r > 0; ++x) {
                            for (y = 0; y < n; ++y) {
                                double dd = 0.0;
                                for (t = 0; t < r; ++t) {
                                    dd += Dm[((size_t)x * p + a) * r + t]
                                          * Dm[((size_t)y * p + b) * r + t];
                                }
                                s += M[(xs + x) * d + xs + y] * dd;
                            }
                        }
                        R[a * p + b] = Vj[a * p + b] + s;
                    }
                }
                for (a = 0; a < p; ++a) {
                    for (b = 0; b < a; ++b) {
                        const double s = 0.5 * (R[a * p + b] + R[b * p + a]);
                        R[a * p + b] = R[b * p + a] = s;
                    }
                }
                fk_mul_t(PCt, Pe, C, n, n, p);               /* Pe C' */
                fk_mul(S, C, PCt, p, n, p);                  /* C Pe C' */
                for (a = 0; a < p * p; ++a) {
                    S[a] += R[a];
                }
                for (a = 0; a < p; ++a) {
                    for (b = 0; b < a; ++b) {
                        const double s = 0.5 * (S[a * p + b] + S[b * p + a]);
                        S[a * p + b] = S[b * p + a] = s;
                    }
                }
                fk_pinv_sym(Sp, S, Qj, p);
                fk_mul(Lf, PCt, Sp, n, p, p);
                for (a = 0; a < n * p; ++a) {
                    if (!fk_finite(Lf[a])) {
                        return -2;
                    }
                    gain[(size_t)j * n * p + a] = Lf[a];
                }
                /* xh+ = xh + LfC (x - xh) + Lf r:  M <- U M U' + Lf R Lf' on the xh block. */
                fk_mul(LfC, Lf, C, n, p, n);
                for (a = 0; a < d * d; ++a) {
                    U[a] = 0.0;
                }
                for (a = 0; a < d; ++a) {
                    U[a * d + a] = 1.0;
                }
                for (a = 0; a < n; ++a) {
                    for (b = 0; b < n; ++b) {
                        U[(hs + a) * d + xs + b] += LfC[a * n + b];
                        U[(hs + a) * d + hs + b] -= LfC[a * n + b];
                    }
                }
                fk_mul(Mt, U, M, d, d, d);
                fk_mul_t(M, Mt, U, d, d, d);
                fk_mul(FTM, Lf, R, n, p, p);                  /* Lf R */
                fk_mul_t(Pe, FTM, Lf, n, p, n);               /* Lf R Lf' */
                for (a = 0; a < n; ++a) {
                    for (b = 0; b < n; ++b) {
                        M[(hs + a) * d + hs + b] += Pe[a * n + b];
                    }
                }
            }
            if (j == stage_start[k] && latch[k] && P > 0) {
                const double *Lam = Lambda + (size_t)k * P * n, *lam = lambda0 + (size_t)k * P;
                for (a = 0; a < d * d; ++a) {
                    Tl[a] = 0.0;
                }
                for (a = 0; a < d; ++a) {
                    Tl[a * d + a] = 1.0;
                }
                for (a = 0; a < P; ++a) {
                    Tl[(vs + a) * d + vs + a] = 0.0;
                    for (b = 0; b < n; ++b) {
                        Tl[(vs + a) * d + hs + b] = Lam[a * n + b];
                    }
                    Tl[(vs + a) * d + one] = lam[a];
                }
                fk_mul(Mt, Tl, M, d, d, d);
                fk_mul_t(M, Mt, Tl, d, d, d);
            }
            /* w = Tw z, u = -K xh - L v - k0; Th (in Ta's place) the same on xh. */
            for (a = 0; a < dw * d; ++a) {
                Tw[a] = 0.0;
                Ta[a] = 0.0;
            }
            for (a = 0; a < n; ++a) {
                Tw[a * d + xs + a] = 1.0;
                Ta[a * d + hs + a] = 1.0;
            }
            for (a = 0; a < m; ++a) {
                for (b = 0; b < n; ++b) {
                    Tw[(n + a) * d + hs + b] = -K[((size_t)j * m + a) * n + b];
                }
                for (b = 0; b < P; ++b) {
                    Tw[(n + a) * d + vs + b] = -L[((size_t)j * m + a) * P + b];
                }
                Tw[(n + a) * d + one] = -k0[(size_t)j * m + a];
                for (b = 0; b < d; ++b) {
                    Ta[(n + a) * d + b] = Tw[(n + a) * d + b];
                }
            }
            Tw[(dw - 1) * d + one] = 1.0;
            Ta[(dw - 1) * d + one] = 1.0;
            fk_mul(TM, Tw, M, dw, d, d);                     /* E w z' */
            fk_mul_t(Mw, TM, Tw, dw, d, dw);                 /* E w w' */
            /* The passengers a = [xh'; v; 1] = Ta2 z, Ta2 = [Fmean Th; rows of v and 1]. */
            fk_mul(Fm, Fk, Ta, n, dw, d);                    /* Fmean Th (n x d) */
            fk_mul(FTM, Fk, TM, n, dw, d);                   /* Fmean E w z' = E x+ z' */
            /* Mt = the new M. */
            for (a = 0; a < d * d; ++a) {
                Mt[a] = 0.0;
            }
            for (a = 0; a < n; ++a) {                        /* E x+ x+', E x+ (Phi on Mw) */
                for (b = 0; b <= n; ++b) {
                    const int bb = b < n ? b : dw - 1;
                    const double *row = Phi + (size_t)(a * dw + bb) * (size_t)D;
                    double s = 0.0;
                    for (c = 0; c < D; ++c) {
                        s += row[c] * Mw[c];
                    }
                    if (b < n) {
                        Mt[(xs + a) * d + xs + b] = s;
                    } else {
                        Mt[(xs + a) * d + one] = s;
                    }
                }
            }
            for (a = 0; a < n; ++a) {                        /* E x+ xh+' = E x+ z' Fm' */
                for (b = 0; b < n; ++b) {
                    double s = 0.0;
                    for (c = 0; c < d; ++c) {
                        s += FTM[a * d + c] * Fm[b * d + c];
                    }
                    Mt[(xs + a) * d + hs + b] = s;
                }
                for (b = 0; b < P; ++b) {                    /* E x+ v' */
                    Mt[(xs + a) * d + vs + b] = FTM[a * d + vs + b];
                }
            }
            /* E a a' for a = [xh+; v; 1]: Fm M Fm', Fm M rows of v and 1, M's v/1 block. */
            fk_mul(U, Fm, M, n, d, d);                       /* Fm M (n x d) */
            for (a = 0; a < n; ++a) {
                for (b = 0; b < n; ++b) {
                    double s = 0.0;
                    for (c = 0; c < d; ++c) {
                        s += U[a * d + c] * Fm[b * d + c];
                    }
                    Mt[(hs + a) * d + hs + b] = s;
                }
                for (b = vs; b < d; ++b) {
                    Mt[(hs + a) * d + b] = U[a * d + b];
                }
            }
            for (a = vs; a < d; ++a) {
                for (b = vs; b < d; ++b) {
                    Mt[a * d + b] = M[a * d + b];
                }
            }
            /* Symmetric: the diagonal blocks (x, xh, [v; 1]) averaged with their transposes,
             * the blocks above them copied below. */
            for (a = 0; a < d; ++a) {
                for (b = a + 1; b < d; ++b) {
                    const int same = (a < hs) == (b < hs) && (a < vs) == (b < vs);
                    const double s = same ? 0.5 * (Mt[a * d + b] + Mt[b * d + a]) : Mt[a * d + b];
                    Mt[a * d + b] = Mt[b * d + a] = s;
                }
            }
            for (a = 0; a < d * d; ++a) {
                if (!fk_finite(Mt[a])) {
                    return -2;
                }
                M[a] = Mt[a];
            }
        }
    }
    return 0;
}
