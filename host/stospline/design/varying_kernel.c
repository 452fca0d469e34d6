/* Host-side kernels of stages whose data vary in time: the exact zero-order-hold designer's
 * backward recursion (stsp_tv_zoh_ticks) and the moment oracle's forward one
 * (stsp_tv_oracle_ticks).  Not firmware: double precision on the design host, called through
 * cffi (stospline.design.varying), compiled in one unit after tick_kernel.c, whose
 * stsp_zoh_tick_update does the per-tick Riccati step.
 *
 * Over a tick [t, t+h] the command is held and the moments obey a linear ODE whose generator
 * varies with the data.  The generator is replaced by its interpolating polynomial through P
 * Gauss-Legendre points of the tick (P = 2: a method of order 4, as the fourth-order Magnus
 * expansion the designer used before; P = 3: order 6, the oracle), and that ODE is solved by
 * its Taylor series in time, (k+1) X_{k+1} = hs sum_l G_(l)(X_{k-l}) (+ forcing), G_(l) the
 * coefficient of r^l of the interpolated generator on a sub-step r in [0, 1].  The series is
 * entire; sub-steps keep hs |G| <= 1/2, so about ten terms reach rounding.  Only generator
 * *actions* on one matrix are needed, never the d^2 x d^2 map: O(d^3) per term at most.
 *
 * The actions (d = n+m+1, z = [x; u; 1]) use the data at one point: Ar = [A, B, f] (n x d,
 * the nonzero rows of Ahat), the diffusion on the active multipliers G (na x n x mz; G[p][a][k]
 * is row a, column k of the matrix multiplying z_act[p]) and the running cost Lb (d x d,
 * E L = <Lb, E zz'>):
 *   FORWARD   M -> Ahat M + M Ahat' + sum_pq M[act p, act q] G_p G_q'   (second moments, d x d)
 *   ADJOINT   Y -> Ahat'Y + Y Ahat + [tr(G_p' Y G_q)] at (act p, act q)  (values, d x d; + Lb)
 *   MEAN      X -> Ahat X       (d x c: E z+ X' = flow of E z X', e.g. E x+ v')
 *   MEAN_ADJ  U -> Ahat'U       (d x c: U = flow' [N; 0], i.e. (N'F)' for E x+ = F z)
 * Arrays are row-major and caller-owned; nothing is allocated.
 */
#include <math.h>
#include <stddef.h>

size_t stsp_zoh_update_size(int n, int m, int q);
int stsp_zoh_tick_update(int n, int m, int q, const double *H, const double *F,
                         const double *Hl_in, double *vp, double *N, double *W, double *mv,
                         double *Kt, double *k0t, double *Lt, double *work);

enum { TV_FORWARD = 0, TV_ADJOINT = 1, TV_MEAN = 2, TV_MEAN_ADJ = 3 };
enum { TV_MAX_POINTS = 3, TV_MAX_TERMS = 60, TV_MAX_SUB = 1 << 16, TV_MAX_DIM = 256 };
enum { TV_OK = 0, TV_ERR_NOT_PD = -1, TV_ERR_DIMS = -2, TV_ERR_SERIES = -3 };
/* How the diffusion term is applied (see noise_lists); TV_NOISE_AUTO picks the cheapest. */
enum { TV_NOISE_AUTO = 0, TV_NOISE_PAIRS = 1, TV_NOISE_COLUMNS = 2, TV_NOISE_OPERATOR = 3,
       TV_NOISE_SEGMENTS = 4 };
enum { TV_TERMS_GUESS = 8 };          /* noisy series terms per sub-step, for the cost model */
#define TV_MAX_OPERATOR ((size_t)1 << 18)  /* doubles of one point's operator matrix, at most */

/* The packed diffusion operator of the points of the last tick that built it (kept from tick
 * to tick: rebuilt only when the diffusion changes).  F[(p,q)][(a,b)], p <= q < na and
 * a <= b < n packed row by row, = sum_k G_p[a,k] G_q[b,k] + G_q[a,k] G_p[b,k]; Ft its
 * transpose; src the diffusion it was built from. */
typedef struct {
    double *F, *Ft, *src;
    double *gram, *gcol;       /* scratch of build_operator: (na n)^2 and mz na n */
    int points;                /* points held (0: none yet) */
} tv_ops;

/* The diffusion of a chunk whose noise is affine in time between sample times (linear
 * interpolation): on a segment with end values G_L, G_R, G(w) = (1 - w) G_L + w G_R, so the
 * packed operator is a quadratic in w, (1 - w)^2 F(G_L) + w(1 - w) C + w^2 F(G_R), C the
 * cross operator (F with G_L in one factor and G_R in the other, both ways).  ops holds the
 * three operators of each of the chunk's segments (nseg x 3 x R x C: F's layout for the
 * oracle, Ft's for the designer), ends their end values (nseg x 2 x na x n x mz), idx[t*P + i]
 * the segment of point i of tick t and w[t*P + i] its place in it.  A point's G is
 * interpolated into gpt (P x na x n x mz, work) and its operator formed in 3 R C, instead of
 * 2 mz R C to build it from G; the caller samples no G at the points. */
typedef struct {
    const double *ops, *ends;
    const int *idx;
    const double *w;
    double *gpt;
    int nseg;
} tv_segs;

/* The data of one tick at its P points, and which of them are known to be the same at every
 * point (the caller passes a field that is constant over the chunk once, with stride 0). */
typedef struct {
    int n, d, na, mz, P;
    const int *act;
    const double *Ar;   /* P x n x d */
    const double *G;    /* P x na x n x mz */
    const double *Lb;   /* P x d x d */
    int ar_same, g_same, lb_same;
    int g_const;           /* G is the same for every tick of the chunk */
    int lb_const;          /* Lb is the same for every tick of the chunk */
    const int *ar_nz;      /* positions (row-major in n x d) of Ar's possible nonzeros */
    int ar_cnt;
    double gb[TV_MAX_POINTS];   /* noise_bound of each point */
    /* The diffusion's nonzero entries, point by point and column by column (sparse: applied
     * pair by pair when that is cheaper than the dense products). */
    int path;              /* TV_NOISE_PAIRS, _COLUMNS or _OPERATOR */
    const int *nz_start;   /* P*mz + 1 offsets into nz_p, nz_a, nz_g */
    const int *nz_p, *nz_a;
    const double *nz_g;
    const double *ga, *gf;   /* columns: G point by point, [a][k][p] and [p][k][a] */
    const tv_ops *ops;       /* operator: the packed operator of each point */
    const int *seg_idx;      /* this tick's segment per point (tv_segs), NULL: none */
    const double *seg_w;     /* and its three weights per point */
} tv_tick;

/* One sub-step's generator as a polynomial in r in [0, 1]: the coefficient of r^l is
 * G_(l) = sum_i cs[i][l] G_i.  The drift and the cost are linear in the data and blended
 * (Arl[l] = sum_i cs[i][l] Ar_i, Lbl[l] likewise); the diffusion, quadratic in the data, is
 * applied point by point with the weights cs[i][l] (once, with weight 1 at l = 0, when every
 * point has the same diffusion).  nrm[l] bounds |G_(l)(X)|max / |X|max. */
typedef struct {
    double cs[TV_MAX_POINTS * TV_MAX_POINTS];
    double nrm[TV_MAX_POINTS];
    double gn;                    /* the diffusion's part of sum_l nrm[l] */
    int lb_count[TV_MAX_POINTS];  /* nonzero entries of Lbl[l], listed in lb_at[l] */
    double *Arl, *Lbl;            /* P x n x d, P x d x d */
    int *lb_at;                   /* P x d*d */
    int lb_done;                  /* Lbl and its lists hold a chunk-constant Lb already */
} tv_blend;

static double abs_d(double x) { return fabs(x); }

static double max_abs(const double *x, size_t len)
{
    double r = 0.0;
    size_t e;
    for (e = 0; e < len; ++e) {
        const double a = abs_d(x[e]);
        r = a > r ? a : r;
    }
    return r;
}

static int same_points(const double *x, int P, size_t len)
{
    int i;
    size_t e;
    for (i = 1; i < P; ++i)
        for (e = 0; e < len; ++e)
            if (x[(size_t)i * len + e] != x[e]) return 0;
    return 1;
}

/* The interpolation coefficients of sub-step j of `sub`, in its own variable r in [0, 1]:
 * l_i((j + r) / sub) = sum_e cs[i][e] r^e from l_i(s) = sum_l coef[i][l] s^l. */
static void shift_coefficients(int P, const double *coef, int j, int sub, double *cs)
{
    int i, e, l, t;
    for (i = 0; i < P; ++i)
        for (e = 0; e < P; ++e) {
            double s = 0.0;
            for (l = e; l < P; ++l) {
                double binom = 1.0, jp = 1.0, sp = 1.0;
                for (t = 0; t < e; ++t) binom = binom * (double)(l - t) / (double)(t + 1);
                for (t = e; t < l; ++t) jp *= (double)j;
                for (t = 0; t < l; ++t) sp *= (double)sub;
                s += coef[i * P + l] * binom * jp / sp;
            }
            cs[i * P + e] = s;
        }
}

/* A bound of the diffusion term of one point in both directions, |term|max <= bound |X|max:
 * ADJOINT |tr(G_p' X G_q)| <= |X|max sum_k s_pk s_qk with s_pk = sum_a |G_p[a,k]|, and FORWARD
 * |(sum_pq X[p,q] G_p G_q')[a,b]| <= |X|max sum_k c_ak c_bk with c_ak = sum_p |G_p[a,k]|; by
 * Cauchy-Schwarz both are at most max(max_p sum_k s_pk^2, max_a sum_k c_ak^2).  (A bound of all
 * the entries at once would be na or n times larger: more sub-steps and terms for nothing.) */
/* max over o < outer of sum_k (sum_{j < inner} |G[o so + j si + k]|)^2, the columns k summed
 * KB at a time over contiguous entries. */
static double square_sums(const double *G, int outer, int inner, size_t so, size_t si, int mz)
{
    enum { KB = 8 };
    double out = 0.0, acc[KB];
    int o, j, k, k0, kb;
    for (o = 0; o < outer; ++o) {
        double sum = 0.0;
        for (k0 = 0; k0 < mz; k0 += KB) {
            kb = mz - k0 < KB ? mz - k0 : KB;
            for (k = 0; k < kb; ++k) acc[k] = 0.0;
            for (j = 0; j < inner; ++j) {
                const double *g = G + (size_t)o * so + (size_t)j * si + (size_t)k0;
                for (k = 0; k < kb; ++k) acc[k] += abs_d(g[k]);
            }
            for (k = 0; k < kb; ++k) sum += acc[k] * acc[k];
        }
        out = sum > out ? sum : out;
    }
    return out;
}

static double noise_bound(const tv_tick *v, int i)
{
    const int n = v->n, na = v->na, mz = v->mz;
    const double *G = v->G + (size_t)i * na * n * mz;                /* G[(p n + a) mz + k] */
    const double rows = square_sums(G, na, n, (size_t)n * mz, (size_t)mz, mz);  /* s_pk */
    const double cols = square_sums(G, n, na, (size_t)mz, (size_t)n * mz, mz);  /* c_ak */
    return rows > cols ? rows : cols;
}

/* Data equal at every point are taken as they are: the weights of the constant coefficient sum
 * to 1, and the others to 0, only up to rounding. */
static void blend(const tv_tick *v, const double *coef, int j, int sub, tv_blend *bl)
{
    const int P = v->P, n = v->n, d = v->d;
    const size_t nd = (size_t)n * d, D = (size_t)d * d;
    double rows[TV_MAX_DIM], cols[TV_MAX_DIM];
    int i, l, a, z;
    size_t e;
    shift_coefficients(P, coef, j, sub, bl->cs);
    for (l = 0; l < P; ++l) {
        double *Ar = bl->Arl + l * nd, *Lb = bl->Lbl + l * D, g = 0.0, rmax = 0.0;
        /* Ar on its nonzero pattern (the rest stays 0 from the loop's start). */
        for (z = 0; z < v->ar_cnt; ++z) {
            const int at = v->ar_nz[z];
            double s = 0.0;
            if (v->ar_same)
                s = l == 0 ? v->Ar[at] : 0.0;
            else
                for (i = 0; i < P; ++i) s += bl->cs[i * P + l] * v->Ar[i * nd + (size_t)at];
            Ar[at] = s;
        }
        if (!(v->lb_const && bl->lb_done)) {
            if (v->lb_same) {
                for (e = 0; e < D; ++e) Lb[e] = l == 0 ? v->Lb[e] : 0.0;
            } else {
                for (e = 0; e < D; ++e) Lb[e] = 0.0;
                for (i = 0; i < P; ++i) {
                    const double w = bl->cs[i * P + l];
                    for (e = 0; e < D; ++e) Lb[e] += w * v->Lb[i * D + e];
                }
            }
            bl->lb_count[l] = 0;
            for (e = 0; e < D; ++e)
                if (Lb[e] != 0.0) bl->lb_at[l * D + (size_t)bl->lb_count[l]++] = (int)e;
        }
        for (a = 0; a < d; ++a) rows[a] = cols[a] = 0.0;
        for (z = 0; z < v->ar_cnt; ++z) {
            const int at = v->ar_nz[z];
            rows[at / d] += abs_d(Ar[at]);
            cols[at % d] += abs_d(Ar[at]);
        }
        for (a = 0; a < d; ++a) {
            if (rows[a] > rmax) rmax = rows[a];
            if (cols[a] > rmax) rmax = cols[a];
        }
        if (v->g_same)
            g = l == 0 ? v->gb[0] : 0.0;
        else
            for (i = 0; i < P; ++i) g += abs_d(bl->cs[i * P + l]) * v->gb[i];
        bl->nrm[l] = 2.0 * rmax + g;
        bl->gn = l == 0 ? g : bl->gn + g;
    }
    bl->lb_done = v->lb_const;
}

/* Sizes of the packed operator: rows (p <= q < na) and columns (a <= b < n). */
static size_t op_rows(int na) { return (size_t)na * (na + 1) / 2u; }
static size_t op_cols(int n) { return (size_t)n * (n + 1) / 2u; }

/* Whether the operator of one point fits TV_MAX_OPERATOR (else it is never built). */
static int op_fits(int n, int na) { return op_rows(na) * op_cols(n) <= TV_MAX_OPERATOR; }

/* point_noise from the packed operator of point i, O(na^2 n^2 / 4) whatever mz: ADJOINT
 * out[p,q] = sum_{a<=b} F[(p,q),(a,b)] X~[a,b], FORWARD out[a,b] = sum_{p<=q} F[(p,q),(a,b)]
 * X~[act p, act q], X~ the upper triangle with its diagonal halved (F counts it twice). */
#if defined(__GNUC__) && __GNUC__ >= 6 && defined(__x86_64__) && defined(__GLIBC__) \
    && !defined(__clang__) && !defined(STSP_TV_NO_CLONES)
/* Also compiled for AVX2, picked at load time where the CPU has it: element-wise loops only
 * and no FMA (GCC's avx2 target does not enable it), so both give the same numbers
 * (tools/bench/varying_clones.py compares them; STSP_TV_NO_CLONES builds the default only). */
#define TV_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define TV_CLONES
#endif

TV_CLONES
static void operator_noise(int kind, const tv_tick *v, int i, const double *X, double *out,
                           double *tmp)
{
    const int n = v->n, d = v->d, na = v->na;
    const size_t R = op_rows(na), C = op_cols(n);
    const int side = kind == TV_FORWARD ? n : na, in = kind == TV_FORWARD ? na : n;
    const double *M = (kind == TV_FORWARD ? v->ops->F : v->ops->Ft) + (size_t)i * R * C;
    const size_t len = kind == TV_FORWARD ? C : R;
    double *restrict acc = tmp;
    double c[4];
    const double *rw[4];
    size_t e, r;
    int a, b, h = 0;
    for (e = 0; e < len; ++e) acc[e] = 0.0;
    /* Four rows at a time: acc is read and written once per four rows of the operator. */
    for (a = 0, r = 0; a < in; ++a)
        for (b = a; b < in; ++b, ++r) {
            const double x = kind == TV_FORWARD ? X[v->act[a] * d + v->act[b]] : X[a * d + b];
            if (x == 0.0) continue;
            c[h] = a == b ? 0.5 * x : x;
            rw[h++] = M + r * len;
            if (h == 4) {
                const double c0 = c[0], c1 = c[1], c2 = c[2], c3 = c[3];
                const double *restrict r0 = rw[0], *restrict r1 = rw[1], *restrict r2 = rw[2],
                             *restrict r3 = rw[3];
                for (e = 0; e < len; ++e)
                    acc[e] += c0 * r0[e] + c1 * r1[e] + c2 * r2[e] + c3 * r3[e];
                h = 0;
            }
        }
    while (h > 0) {
        const double ch = c[--h];
        const double *restrict row = rw[h];
        for (e = 0; e < len; ++e) acc[e] += ch * row[e];
    }
    for (a = 0, e = 0; a < side; ++a)
        for (b = a; b < side; ++b, ++e) out[a * side + b] = out[b * side + a] = acc[e];
}

/* F and Ft of each point of the tick from its diffusion, unless the operator held was built
 * from the same diffusion: through the Gram matrix of the rows of G, gram[(p,a)][(q,b)] =
 * sum_k G_p[a,k] G_q[b,k] for q >= p (mz (na n)^2 / 2, long contiguous rows), then
 * F[(p,q),(a,b)] = gram[(p,a)][(q,b)] + gram[(p,b)][(q,a)]. */
static void build_operator(const tv_tick *v, int points, tv_ops *ops)
{
    const int n = v->n, na = v->na, mz = v->mz;
    const size_t R = op_rows(na), C = op_cols(n), blk = (size_t)na * n * mz, w = (size_t)na * n;
    size_t e, r, c;
    int i, p, q, k, a, b;
    if (ops->points == points) {
        for (e = 0; e < (size_t)points * blk && ops->src[e] == v->G[e]; ++e) {}
        if (e == (size_t)points * blk) return;
    }
    for (e = 0; e < (size_t)points * blk; ++e) ops->src[e] = v->G[e];
    ops->points = points;
    for (i = 0; i < points; ++i) {
        const double *G = v->G + (size_t)i * blk;                 /* G[(p*n + a)*mz + k] */
        double *F = ops->F + (size_t)i * R * C, *Ft = ops->Ft + (size_t)i * R * C;
        double *gram = ops->gram, *gcol = ops->gcol;              /* gcol[k][(p,a)] */
        for (e = 0; e < w; ++e)
            for (k = 0; k < mz; ++k) gcol[(size_t)k * w + e] = G[e * mz + k];
        for (p = 0; p < na; ++p)
            for (a = 0; a < n; ++a) {
                double *restrict row = gram + ((size_t)p * n + a) * w;
                const double *restrict g = G + ((size_t)p * n + a) * mz;
                for (e = (size_t)p * n; e < w; ++e) row[e] = 0.0;
                for (k = 0; k < mz; ++k) {
                    const double c1 = g[k];
                    const double *restrict col = gcol + (size_t)k * w;
                    if (c1 != 0.0)
                        for (e = (size_t)p * n; e < w; ++e) row[e] += c1 * col[e];
                }
            }
        for (p = 0, r = 0; p < na; ++p)
            for (q = p; q < na; ++q, ++r)
                for (a = 0, c = 0; a < n; ++a)
                    for (b = a; b < n; ++b, ++c)
                        F[r * C + c] = gram[((size_t)p * n + a) * w + (size_t)q * n + b]
                                       + gram[((size_t)p * n + b) * w + (size_t)q * n + a];
        for (r = 0; r < R; ++r)
            for (c = 0; c < C; ++c) Ft[c * R + r] = F[r * C + c];
    }
}

/* The operator of each point of the tick from its segment's three (tv_segs), into Ft (the
 * designer, `adjoint`) or F (the oracle): 3 R C per point, two points in the same segment in
 * one pass over its operators.  What ops held before is lost. */
TV_CLONES
static void form_operator(const tv_tick *v, int points, const tv_segs *sg, int adjoint,
                          tv_ops *ops)
{
    const size_t len = op_rows(v->na) * op_cols(v->n);
    double wt[TV_MAX_POINTS][3];
    size_t e;
    int i;
    for (i = 0; i < points; ++i) {
        const double w = v->seg_w[i];
        wt[i][0] = (1.0 - w) * (1.0 - w); wt[i][1] = w * (1.0 - w); wt[i][2] = w * w;
    }
    for (i = 0; i < points; ++i) {
        const double *restrict s0 = sg->ops + (size_t)v->seg_idx[i] * 3u * len;
        const double *restrict s1 = s0 + len, *restrict s2 = s1 + len;
        const double a0 = wt[i][0], a1 = wt[i][1], a2 = wt[i][2];
        double *restrict out = (adjoint ? ops->Ft : ops->F) + (size_t)i * len;
        if (i + 1 < points && v->seg_idx[i + 1] == v->seg_idx[i]) {
            const double b0 = wt[i + 1][0], b1 = wt[i + 1][1], b2 = wt[i + 1][2];
            double *restrict nxt = out + len;
            for (e = 0; e < len; ++e) {
                const double x0 = s0[e], x1 = s1[e], x2 = s2[e];
                out[e] = a0 * x0 + a1 * x1 + a2 * x2;
                nxt[e] = b0 * x0 + b1 * x1 + b2 * x2;
            }
            ++i;
        } else {
            for (e = 0; e < len; ++e) out[e] = a0 * s0[e] + a1 * s1[e] + a2 * s2[e];
        }
    }
    ops->points = 0;                       /* not the operator of any G: build_operator rebuilds */
}

/* The diffusion term of point i on X, compactly: FORWARD the n x n block
 * sum_pq X[act p, act q] G_p G_q' (on the x rows and columns), ADJOINT the na x na block
 * tr(G_p' X G_q) (at act p, act q); O(mz na n (n + na)) per call.  Every Brownian column at
 * once, on the copies `noise_lists` made: ga[a][k][p] = gf[p][k][a] = G_p[a, k].  ADJOINT:
 * tmp[b][k, p] = (X G_p)[b, k], then out = sum over (b, k) of the outer products
 * tmp[b][k, :] ga[b][k, :]'.  FORWARD: tmp[p][k, b] = sum_q X[p, q] G_q[b, k], then out = sum
 * over (p, k) of gf[p][k, :] tmp[p][k, :]'.  Each loop is an axpy over a contiguous row of
 * mz na (or mz n) entries: it vectorises and carries no dependency chain. */
static void point_noise(int kind, const tv_tick *v, int i, const double *X, double *out,
                        double *tmp)
{
    const int n = v->n, d = v->d, na = v->na, mz = v->mz;
    const size_t blk = (size_t)na * n * mz;
    const double *ga = v->ga + (size_t)i * blk, *gf = v->gf + (size_t)i * blk;
    int k, a, b, p, q;
    if (v->path == TV_NOISE_OPERATOR || v->path == TV_NOISE_SEGMENTS) {
        operator_noise(kind, v, i, X, out, tmp);
        return;
    }
    if (kind == TV_FORWARD) {
        const int row = mz * n;
        for (a = 0; a < n * n; ++a) out[a] = 0.0;
        for (p = 0; p < na; ++p) {
            double *restrict t = tmp + (size_t)p * row;
            for (b = 0; b < row; ++b) t[b] = 0.0;
            for (q = 0; q < na; ++q) {
                const double c = X[v->act[p] * d + v->act[q]];
                const double *restrict g = gf + (size_t)q * row;
                if (c != 0.0)
                    for (b = 0; b < row; ++b) t[b] += c * g[b];
            }
            for (k = 0; k < mz; ++k) {
                const double *restrict u = gf + (size_t)p * row + (size_t)k * n;
                const double *restrict w = t + (size_t)k * n;
                for (a = 0; a < n; ++a) {
                    const double c = u[a];
                    double *restrict o = out + (size_t)a * n;
                    if (c != 0.0)
                        for (b = a; b < n; ++b) o[b] += c * w[b];
                }
            }
        }
    } else {
        const int row = mz * na;
        for (a = 0; a < na * na; ++a) out[a] = 0.0;
        for (b = 0; b < n; ++b) {
            double *restrict t = tmp + (size_t)b * row;
            for (p = 0; p < row; ++p) t[p] = 0.0;
            for (a = 0; a < n; ++a) {
                const double c = X[(size_t)b * d + a];
                const double *restrict g = ga + (size_t)a * row;
                if (c != 0.0)
                    for (p = 0; p < row; ++p) t[p] += c * g[p];
            }
            for (k = 0; k < mz; ++k) {
                const double *restrict u = t + (size_t)k * na;
                const double *restrict w = ga + (size_t)b * row + (size_t)k * na;
                for (p = 0; p < na; ++p) {
                    const double c = u[p];
                    double *restrict o = out + (size_t)p * na;
                    if (c != 0.0)
                        for (q = p; q < na; ++q) o[q] += c * w[q];
                }
            }
        }
    }
    {
        const int side = kind == TV_FORWARD ? n : na;
        for (a = 0; a < side; ++a)                     /* the lower triangle */
            for (b = 0; b < a; ++b) out[a * side + b] = out[b * side + a];
    }
}

/* next += w * a compact diffusion block of `point_noise`. */
static void add_noise(int kind, const tv_tick *v, double w, const double *blk, double *next)
{
    const int n = v->n, d = v->d, na = v->na;
    int a, b;
    if (kind == TV_FORWARD) {
        for (a = 0; a < n; ++a)
            for (b = 0; b < n; ++b) next[a * d + b] += w * blk[a * n + b];
    } else {
        for (a = 0; a < na; ++a)
            for (b = 0; b < na; ++b) next[v->act[a] * d + v->act[b]] += w * blk[a * na + b];
    }
}

/* next += w * the diffusion term of point i on X from its nonzero entries (FORWARD: at the x
 * rows and columns, ADJOINT: at the active multipliers). */
static void pair_noise(int kind, const tv_tick *v, int i, double w, const double *X,
                       double *next)
{
    const int d = v->d;
    int k, e1, e2;
    for (k = 0; k < v->mz; ++k) {
        const int lo = v->nz_start[i * v->mz + k], hi = v->nz_start[i * v->mz + k + 1];
        for (e1 = lo; e1 < hi; ++e1) {
            const double g1 = w * v->nz_g[e1];
            const int p1 = v->act[v->nz_p[e1]], a1 = v->nz_a[e1];
            for (e2 = lo; e2 < hi; ++e2) {
                const double g = g1 * v->nz_g[e2];
                const int p2 = v->act[v->nz_p[e2]], a2 = v->nz_a[e2];
                if (kind == TV_FORWARD) next[a1 * d + a2] += g * X[p1 * d + p2];
                else next[p1 * d + p2] += g * X[a1 * d + a2];
            }
        }
    }
}

/* The tick's diffusion laid out for the way it is applied, chosen by cost per point and
 * noisy series term (`force`, if not TV_NOISE_AUTO, overrides the choice):
 *   PAIRS     sum_k nnz_k^2 (nnz_k the nonzeros of Brownian column k): the nonzero lists;
 *   COLUMNS   about mz na n (n + na) 3/4: G copied in the layouts of point_noise;
 *   OPERATOR  na^2 n^2 / 4, plus 2 mz na^2 n^2 / 4 to build it (`build_operator`) when the
 *             diffusion differs from the last tick's, spread over the tick's terms (guessed
 *             TV_TERMS_GUESS per sub-step; over the chunk's `ticks` when the diffusion is
 *             the same for all of them).  Only with `ops` (NULL: never).
 *   SEGMENTS  na^2 n^2 / 4, plus 3 na^2 n^2 / 4 to form it (`form_operator`) from the
 *             operators of the tick's segments, whenever the caller gave them (`sg`, for
 *             noise interpolated linearly, only where they cost less than the pairs or the
 *             columns: stospline.design.varying._segments_pay) and with `ops`; forced
 *             without them, OPERATOR.
 * The pairs are taken whenever they cost at most na n (n + na) mz and no segments are given.
 * `adjoint`: the designer's direction (the operator formed is Ft). */
static void noise_lists(tv_tick *v, int *start, int *np_, int *na_, double *g, tv_ops *ops,
                        int force, int sub, long ticks, const tv_segs *sg, int adjoint)
{
    const int n = v->n, na = v->na, mz = v->mz, points = v->g_same ? 1 : v->P;
    const int fits = ops != NULL && op_fits(n, na);
    const int segs = fits && sg != NULL && v->seg_idx != NULL;
    long pairs = 0, dense = (long)na * n * (n + na) * mz;
    int i, k, p, a, e = 0;
    v->nz_start = start; v->nz_p = np_; v->nz_a = na_; v->nz_g = g;
    v->ops = ops;
    if (force == TV_NOISE_AUTO && segs) {      /* given only where they pay (the caller's model) */
        v->path = TV_NOISE_SEGMENTS;
        form_operator(v, points, sg, adjoint, ops);
        return;
    }
    /* The nonzeros of each Brownian column (in start, as counts), for the cost of the pairs;
     * their lists below only if the pairs are taken. */
    for (i = 0; i < points * mz; ++i) start[i] = 0;
    for (i = 0; i < points; ++i) {
        const double *restrict Gi = v->G + (size_t)i * na * n * mz;
        int *restrict cnt = start + i * mz;
        for (p = 0; p < na * n; ++p)
            for (k = 0; k < mz; ++k) cnt[k] += Gi[(size_t)p * mz + k] != 0.0;
    }
    for (i = 0; i < points * mz; ++i) pairs += (long)start[i] * start[i];
    v->path = force != TV_NOISE_AUTO ? force
              : pairs <= dense * points ? TV_NOISE_PAIRS : TV_NOISE_COLUMNS;
    if (v->path == TV_NOISE_SEGMENTS && !segs) v->path = TV_NOISE_OPERATOR;
    if (v->path == TV_NOISE_OPERATOR && !fits) v->path = TV_NOISE_COLUMNS;
    if (force == TV_NOISE_AUTO && fits) {
        const double terms = (double)TV_TERMS_GUESS * sub, op = (double)op_rows(na) * op_cols(n);
        const size_t len = (size_t)points * na * n * mz;
        size_t at = 0;
        double build = (2.0 * mz + 1.0) * op * points, best;
        if (ops->points == points)
            for (at = 0; at < len && ops->src[at] == v->G[at]; ++at) {}
        if (at == len && ops->points == points) build = 0.0;
        else if (v->g_const) build /= (double)ticks;     /* built once for the chunk */
        best = v->path == TV_NOISE_PAIRS ? terms * (double)pairs
               : terms * 0.75 * (double)dense * points;
        if (v->path == TV_NOISE_COLUMNS && terms * op * points + build < best)
            v->path = TV_NOISE_OPERATOR;
    }
    if (v->path == TV_NOISE_PAIRS) {
        for (i = 0; i < points; ++i)
            for (k = 0; k < mz; ++k) {
                start[i * mz + k] = e;
                for (p = 0; p < na; ++p)
                    for (a = 0; a < n; ++a) {
                        const double x = v->G[(((size_t)i * na + p) * n + a) * mz + k];
                        if (x != 0.0) { np_[e] = p; na_[e] = a; g[e] = x; ++e; }
                    }
            }
        start[points * mz] = e;
    }
    if (v->path == TV_NOISE_COLUMNS) {
        const size_t blk = (size_t)na * n * mz, cap = TV_MAX_POINTS * blk;
        double *ga = g + cap, *gf = ga + cap;
        for (i = 0; i < points; ++i)
            for (p = 0; p < na; ++p)
                for (a = 0; a < n; ++a)
                    for (k = 0; k < mz; ++k) {
                        const double x = v->G[(((size_t)i * na + p) * n + a) * mz + k];
                        ga[i * blk + ((size_t)a * mz + k) * na + p] = x;
                        gf[i * blk + ((size_t)p * mz + k) * n + a] = x;
                    }
        v->ga = ga; v->gf = gf;
    }
    if (v->path == TV_NOISE_OPERATOR) build_operator(v, points, ops);
    if (v->path == TV_NOISE_SEGMENTS) form_operator(v, points, sg, adjoint, ops);
}

/* acc += the drift part of G_(l) on X (d x cols; MEAN reads only its first `rows` rows, the
 * others being zero), before symmetrisation: FORWARD and MEAN Ahat X (rows < n of acc),
 * ADJOINT and MEAN_ADJ Ahat'X (all rows).  Ahat has only n nonzero rows, Ar.  The FORWARD and
 * ADJOINT terms are acc + acc'. */
static void add_drift(int kind, const tv_tick *v, const tv_blend *bl, int l, const double *X,
                      int cols, int rows, double *acc)
{
    const int d = v->d;
    const double *Ar = bl->Arl + (size_t)l * v->n * d;
    const int fwd = kind == TV_FORWARD || kind == TV_MEAN;
    int z, b;
    for (z = 0; z < v->ar_cnt; ++z) {
        const int at = v->ar_nz[z], a = at / d, c = at % d;
        const double s = Ar[at];
        const double *restrict xr;
        double *restrict out;
        if (s == 0.0) continue;
        if (fwd) {                                     /* row a += Ahat[a, c] X[c, :] */
            if (c >= rows) continue;
            xr = X + (size_t)c * cols; out = acc + (size_t)a * cols;
        } else {                                       /* row c += Ahat[a, c] X[a, :] */
            xr = X + (size_t)a * cols; out = acc + (size_t)c * cols;
        }
        for (b = 0; b < cols; ++b) out[b] += s * xr[b];
    }
}

/* Work of `taylor` for matrices of d x cols (cols <= cmax), with the blended data of one
 * sub-step (`tv_blend`) after it. */
/* Scratch of point_noise and operator_noise. */
static size_t noise_tmp_size(int n, int na, int mz)
{
    size_t t = (size_t)na * n * mz;
    if (op_rows(na) > t) t = op_rows(na);
    if (op_cols(n) > t) t = op_cols(n);
    return t;
}

static size_t taylor_size(int n, int m, int na, int mz, int cmax)
{
    const size_t d = (size_t)n + (size_t)m + 1u, D = d * (size_t)(cmax > (int)d ? cmax : (int)d);
    return (TV_MAX_POINTS + 2u) * D + noise_tmp_size(n, na, mz)
           + TV_MAX_POINTS * TV_MAX_POINTS * d * d;
}

/* The operators of `tv_ops` (when one fits) and the diffusion they were built from. */
static size_t ops_size(int n, int na, int mz)
{
    const int fits = op_fits(n, na);
    const size_t op = fits ? op_rows(na) * op_cols(n) : 0u, w = (size_t)na * n;
    return TV_MAX_POINTS * (2u * op + w * mz) + (fits ? w * w + w * mz : 0u);
}

static double *ops_at(tv_ops *ops, double *at, int n, int na, int mz)
{
    const size_t op = op_fits(n, na) ? op_rows(na) * op_cols(n) : 0u;
    ops->F = at;
    ops->Ft = at + TV_MAX_POINTS * op;
    ops->src = ops->Ft + TV_MAX_POINTS * op;
    ops->gram = ops->src + TV_MAX_POINTS * (size_t)na * n * mz;
    ops->gcol = ops->gram + (op ? (size_t)na * n * na * n : 0u);
    ops->points = 0;
    return at + ops_size(n, na, mz);
}

static size_t blend_size(int n, int m)
{
    const size_t d = (size_t)n + (size_t)m + 1u;
    return TV_MAX_POINTS * ((size_t)n * d + d * d);
}

/* X (d x cols) <- X(1) for dX/dr = hs (G(r) X [+ Lb(r), ADJOINT]) on r in [0, 1], G(r) the
 * blended generator of `bl`; FORWARD also adds hs * integral of <Lb(r), X(r)> to *J.  Each
 * term's diffusion blocks are kept per point (they enter the next P terms with different
 * weights); the drift is applied blended, lag by lag, and a lag whose contribution is below
 * 2^-60 of the sum is left out. */
static int taylor(int kind, const tv_tick *v, const tv_blend *bl, double hs, double *X, int cols,
                  double *J, double *work)
{
    const int P = v->P, d = v->d, n = v->n, points = v->g_same ? 1 : v->P;
    const int noisy = (kind == TV_FORWARD || kind == TV_ADJOINT) && v->na > 0;
    const size_t D = (size_t)d * cols, nb = (size_t)d * d;
    const int sym = kind == TV_FORWARD || kind == TV_ADJOINT;
    double *ring = work, *next = ring + (size_t)P * D, *tmp = next + D,
           *ringN = tmp + noise_tmp_size(n, v->na, v->mz);
    double tmax[TV_MAX_POINTS], xmax = max_abs(X, D);
    int live[TV_MAX_POINTS];      /* the term in this ring slot has its diffusion applied */
    int k, l, i;
    size_t e;
    if (D == 0) return TV_OK;
    for (e = 0; e < D; ++e) ring[e] = X[e];
    tmax[0] = xmax;
    for (k = 0; k < TV_MAX_TERMS; ++k) {
        const int lmax = k < P - 1 ? k : P - 1;
        const double *term = ring + (size_t)(k % P) * D;
        double nmax = 0.0, bound = 0.0;
        if (kind == TV_FORWARD && J != NULL) {         /* <Lb(r), term> r^k, integrated */
            double acc = 0.0;
            for (l = 0; l < P; ++l) {
                const double *lb = bl->Lbl + (size_t)l * D;
                const int *at = bl->lb_at + (size_t)l * D;
                double inner = 0.0;
                int z;
                for (z = 0; z < bl->lb_count[l]; ++z) inner += lb[at[z]] * term[at[z]];
                acc += inner / (double)(k + l + 1);
            }
            *J += hs * acc;
        }
        /* The diffusion of a term whose every contribution (this term's and the next P - 1
         * terms') is below 2^-60 of the sum is left out, as a negligible drift lag is. */
        live[k % P] = noisy && !(bl->gn * tmax[k % P] * hs <= 0x1p-60 * xmax * (double)(k + 1));
        if (live[k % P] && v->path != TV_NOISE_PAIRS)
            for (i = 0; i < points; ++i)
                point_noise(kind, v, i, term, ringN + ((size_t)(k % P) * P + i) * nb, tmp);
        /* The symmetric kinds gather half of the term in `next` (drift Z, half the noise and
         * forcing) and take next + next' below. */
        for (e = 0; e < D; ++e) next[e] = 0.0;
        for (l = 0; l <= lmax; ++l) {
            const int s = (k - l) % P;
            if (l > 0 && bl->nrm[l] * tmax[s] * hs <= 0x1p-60 * xmax * (double)(k + 1))
                continue;
            add_drift(kind, v, bl, l, ring + (size_t)s * D, cols,
                      kind == TV_MEAN && k - l > 0 ? n : d, next);
            if (!live[s]) continue;
            for (i = 0; i < points; ++i) {
                const double w = v->g_same ? (l == 0 ? 0.5 : 0.0) : 0.5 * bl->cs[i * P + l];
                if (w == 0.0) continue;
                if (v->path == TV_NOISE_PAIRS)
                    pair_noise(kind, v, i, w, ring + (size_t)s * D, next);
                else add_noise(kind, v, w, ringN + ((size_t)s * P + i) * nb, next);
            }
        }
        if (kind == TV_ADJOINT && k < P) {
            const double *lb = bl->Lbl + (size_t)k * D;
            const int *at = bl->lb_at + (size_t)k * D;
            int z;
            for (z = 0; z < bl->lb_count[k]; ++z) next[at[z]] += 0.5 * lb[at[z]];
        }
        {
            double *dst = ring + (size_t)((k + 1) % P) * D;
            const double f = hs / (double)(k + 1);
            if (sym) {
                int r, c;
                for (r = 0; r < d; ++r)
                    for (c = r; c < d; ++c) {
                        const double t = (next[r * d + c] + next[c * d + r]) * f, a = abs_d(t);
                        dst[r * d + c] = dst[c * d + r] = t;
                        X[r * d + c] += t;
                        if (c != r) X[c * d + r] += t;
                        nmax = a > nmax ? a : nmax;
                    }
            } else {
                for (e = 0; e < D; ++e) {
                    const double t = next[e] * f, a = abs_d(t);
                    dst[e] = t;
                    X[e] += t;
                    nmax = a > nmax ? a : nmax;
                }
            }
        }
        tmax[(k + 1) % P] = nmax;
        if (k < P) {                /* the scale of the sum, once the forcing is in */
            const double x = max_abs(X, D);
            if (x > xmax) xmax = x;
        }
        /* Stop when this term and a bound of the next one are below rounding: hs |G| <= 1/2
         * then shrinks every later term. */
        for (l = 0; l < P && l <= k + 1; ++l)
            bound += bl->nrm[l] * tmax[(k + 1 - l) % P];
        if (k >= P - 1 && nmax <= 0x1p-56 * xmax && bound * hs <= 0x1p-57 * xmax * (k + 2))
            return TV_OK;
    }
    return TV_ERR_SERIES;
}

/* Sub-steps of one tick: enough that h/sub times the bound of the interpolated generator on
 * the tick (the sum of its coefficients' bounds) is at most 1/2.  Leaves sub-step 0 of 1 in
 * `bl`.  0: non-finite data, or more than TV_MAX_SUB. */
static int sub_steps(const tv_tick *v, const double *coef, double h, tv_blend *bl)
{
    double bound = 0.0, need;
    int l;
    blend(v, coef, 0, 1, bl);
    for (l = 0; l < v->P; ++l) bound += bl->nrm[l];
    need = 2.0 * h * bound;
    if (!(need <= (double)TV_MAX_SUB)) return 0;       /* also NaN */
    return need <= 1.0 ? 1 : (int)need + 1;
}

static tv_tick tick_of(int n, int d, int na, int mz, int P, const int *act, const double *Ar,
                       const double *G, const double *Lb, const int *same, const int *ar_nz,
                       int ar_cnt, const tv_segs *sg, long t)
{
    tv_tick v;
    int i;
    v.n = n; v.d = d; v.na = na; v.mz = mz; v.P = P; v.act = act;
    v.Ar = same[0] ? Ar : Ar + (size_t)t * P * n * d;
    v.G = same[1] ? G : G + (size_t)t * P * na * n * mz;
    v.seg_idx = NULL; v.seg_w = NULL;
    if (sg != NULL && sg->nseg > 0) {                 /* G at the points, from the segments */
        const size_t blk = (size_t)na * (size_t)n * (size_t)mz;
        v.seg_idx = sg->idx + (size_t)t * (size_t)P;
        v.seg_w = sg->w + (size_t)t * (size_t)P;
        for (i = 0; i < P; ++i) {
            const double w = v.seg_w[i];
            const double *restrict gl = sg->ends + (size_t)v.seg_idx[i] * 2u * blk;
            const double *restrict gr = gl + blk;
            double *restrict out = sg->gpt + (size_t)i * blk;
            size_t e;
            for (e = 0; e < blk; ++e) out[e] = gl[e] * (1.0 - w) + gr[e] * w;
        }
        v.G = sg->gpt;
    }
    v.Lb = same[2] ? Lb : Lb + (size_t)t * P * d * d;
    v.ar_same = same[0] || same_points(v.Ar, P, (size_t)n * d);
    v.g_same = (same[1] && v.seg_idx == NULL) || same_points(v.G, P, (size_t)na * n * mz);
    v.lb_same = same[2] || same_points(v.Lb, P, (size_t)d * d);
    v.lb_const = same[2];
    v.g_const = same[1] && v.seg_idx == NULL;
    v.ar_nz = ar_nz; v.ar_cnt = ar_cnt;
    for (i = 0; i < (v.g_same ? 1 : P); ++i) v.gb[i] = noise_bound(&v, i);
    return v;
}

/* Integer work of either loop: the diffusion's nonzero lists. */
size_t stsp_tv_iwork_size(int n, int m, int na, int mz)
{
    const size_t d = (size_t)n + (size_t)m + 1u;
    return TV_MAX_POINTS * (size_t)mz + 1u + 2u * TV_MAX_POINTS * (size_t)na * n * mz
           + TV_MAX_POINTS * d * d;
}

static void lists_of(tv_tick *v, int *iwork, double *gwork, tv_ops *ops, int force, int sub,
                     long ticks, const tv_segs *sg, int adjoint)
{
    const size_t cap = TV_MAX_POINTS * (size_t)v->na * v->n * v->mz;
    int *start = iwork, *p = start + TV_MAX_POINTS * v->mz + 1, *a = p + cap;
    noise_lists(v, start, p, a, gwork, ops, force, sub, ticks, sg, adjoint);
}

/* The Lb nonzero lists of `bl` at the end of the integer work. */
static int *lb_lists(int *iwork, int n, int m, int na, int mz)
{
    const size_t d = (size_t)n + (size_t)m + 1u;
    return iwork + stsp_tv_iwork_size(n, m, na, mz) - TV_MAX_POINTS * d * d;
}

/* A blend's storage at `at` (zeroed: blend writes only Ar's nonzero pattern) and its Lb lists
 * in the integer work; returns the double work after it (the diffusion's nonzero values). */
static double *blend_at(tv_blend *bl, double *at, int *iwork, int n, int m, int na, int mz)
{
    const size_t d = (size_t)n + (size_t)m + 1u, len = TV_MAX_POINTS * (size_t)n * d;
    size_t e;
    bl->Arl = at;
    bl->Lbl = at + len;
    bl->lb_done = 0;
    bl->lb_at = lb_lists(iwork, n, m, na, mz);
    for (e = 0; e < len; ++e) bl->Arl[e] = 0.0;
    return at + blend_size(n, m);
}

/* The segments of a chunk (tv_segs) checked and bound into *sg: nseg >= 0; with nseg > 0,
 * the operator of one point fits TV_MAX_OPERATOR, the pointers are not NULL, every index is
 * in [0, nseg) and every place w in [0, 1].  nseg = 0: none (the pointers are not read). */
static int segments_ok(int n, int na, long T, int P, int nseg, const double *ops,
                       const double *ends, const int *idx, const double *w, tv_segs *sg)
{
    size_t e;
    sg->nseg = 0; sg->ops = NULL; sg->ends = NULL; sg->idx = NULL; sg->w = NULL;
    sg->gpt = NULL;
    if (nseg < 0) return 0;
    if (nseg == 0) return 1;
    if (!op_fits(n, na) || ops == NULL || ends == NULL || idx == NULL || w == NULL) return 0;
    for (e = 0; e < (size_t)T * (size_t)P; ++e)
        if (idx[e] < 0 || idx[e] >= nseg || !(w[e] >= 0.0 && w[e] <= 1.0)) return 0;
    sg->nseg = nseg; sg->ops = ops; sg->ends = ends; sg->idx = idx; sg->w = w;
    return 1;
}

size_t stsp_tv_zoh_work_size(int n, int m, int q, int na, int mz)
{
    const size_t d = (size_t)n + (size_t)m + 1u, r = (size_t)n + 1u;
    return d * d + d * (size_t)q + (size_t)q * d + r * (r + 1u) / 2u
           + stsp_zoh_update_size(n, m, q) + taylor_size(n, m, na, mz, q) + blend_size(n, m)
           + 4u * TV_MAX_POINTS * (size_t)na * n * mz + ops_size(n, na, mz);
}

/* The T ticks of one chunk of a time-varying stage, backward (as stsp_zoh_stage_ticks): the
 * tick's H from the ADJOINT series started at the value after it, and Hl' = F'N from the
 * MEAN_ADJ series started at [N; 0], both in the backward variable 1 - s (coef); then the
 * Riccati step.  Data of tick t at Ar + t*P*n*d, G + t*P*na*n*mz, Lb + t*P*d*d, or, for a field
 * with same[f] set, one point for every tick. */
TV_CLONES
int stsp_tv_zoh_ticks(int n, int m, int q, long T, int P, int na, int mz, const double *coef,
                      double h, const int *act, const double *Ar, const double *G,
                      const double *Lb, const int *same, const int *ar_nz, int ar_cnt,
                      int nseg, const double *seg_ops, const double *seg_ends,
                      const int *seg_idx, const double *seg_w, double *V, double *N, double *W,
                      double *mv, double *K, double *k0, double *L, double *work,
                      int *iwork, int noise_path, long *bad_tick)
{
    const int d = n + m + 1, r = n + 1;
    double *Y, *U, *Hl, *vp, *up, *tw, *gw;
    tv_blend bl;
    tv_ops ops;
    tv_segs sg;
    long t;
    int a, b, p, l, j, st;
    if (n < 1 || m < 1 || q < 0 || T < 0 || P < 1 || P > TV_MAX_POINTS || na < 0 ||
        na > n + m || mz < 0 || d > TV_MAX_DIM || ar_cnt < 0 || ar_cnt > n * d ||
        noise_path < TV_NOISE_AUTO || noise_path > TV_NOISE_SEGMENTS ||
        !segments_ok(n, na, T, P, nseg, seg_ops, seg_ends, seg_idx, seg_w, &sg))
        return TV_ERR_DIMS;
    Y = work; U = Y + (size_t)d * d; Hl = U + (size_t)d * q; vp = Hl + (size_t)q * d;
    up = vp + (size_t)r * (r + 1) / 2; tw = up + stsp_zoh_update_size(n, m, q);
    gw = blend_at(&bl, tw + taylor_size(n, m, na, mz, q), iwork, n, m, na, mz);
    sg.gpt = ops_at(&ops, gw + 3u * TV_MAX_POINTS * (size_t)na * n * mz, n, na, mz);
#define RS(a) ((a) < n ? (a) : d - 1)
    for (a = 0, p = 0; a < r; ++a)
        for (b = a; b < r; ++b, ++p) vp[p] = 0.5 * (V[a * r + b] + V[b * r + a]);
    for (t = T - 1; t >= 0; --t) {
        tv_tick v = tick_of(n, d, na, mz, P, act, Ar, G, Lb, same, ar_nz, ar_cnt, &sg, t);
        const int sub = sub_steps(&v, coef, h, &bl);
        if (sub == 0) return TV_ERR_SERIES;
        lists_of(&v, iwork, gw, &ops, noise_path, sub, T, &sg, 1);
        for (a = 0; a < d * d; ++a) Y[a] = 0.0;
        for (a = 0, p = 0; a < r; ++a)
            for (b = a; b < r; ++b, ++p) Y[RS(a) * d + RS(b)] = Y[RS(b) * d + RS(a)] = vp[p];
        for (a = 0; a < d * q; ++a) U[a] = a < n * q ? N[a] : 0.0;
        for (j = 0; j < sub; ++j) {
            if (sub > 1) blend(&v, coef, j, sub, &bl);
            st = taylor(TV_ADJOINT, &v, &bl, h / sub, Y, d, NULL, tw);
            if (st == TV_OK) st = taylor(TV_MEAN_ADJ, &v, &bl, h / sub, U, q, NULL, tw);
            if (st) return st;
        }
        for (l = 0; l < q; ++l) {                      /* Hl = (F'N)' + mv in the 1 column */
            for (b = 0; b < d; ++b) Hl[l * d + b] = U[b * q + l];
            Hl[l * d + d - 1] += mv[l];
        }
        if (stsp_zoh_tick_update(n, m, q, Y, NULL, Hl, vp, N, W, mv, K + (size_t)t * m * n,
                                 k0 + (size_t)t * m, L + (size_t)t * m * q, up)) {
            if (bad_tick) *bad_tick = t;
            return TV_ERR_NOT_PD;
        }
    }
    for (a = 0, p = 0; a < r; ++a)
        for (b = a; b < r; ++b, ++p) V[a * r + b] = V[b * r + a] = vp[p];
#undef RS
    return TV_OK;
}

/* The command's moments at the start of a tick: TM = E w y' and Mw = E w w' for w = [x; u; 1]
 * = Tw y, u = -K x - L v - k0 (the x and 1 rows of TM are rows of M); and, when um is not
 * NULL, the command's mean and variance into um, uv. */
static void command_moments(int n, int m, int nl, const double *Kt, const double *Lt,
                            const double *kt, const double *M, double *TM, double *Mw,
                            double *um, double *uv)
{
    const int dy = n + nl + 1, dw = n + m + 1;
    int a, b, c;
    for (a = 0; a < n; ++a)
        for (b = 0; b < dy; ++b) TM[a * dy + b] = M[a * dy + b];
    for (b = 0; b < dy; ++b) TM[(dw - 1) * dy + b] = M[(dy - 1) * dy + b];
    for (a = 0; a < m; ++a)
        for (b = 0; b < dy; ++b) {
            double s = 0.0;
            for (c = 0; c < n; ++c) s -= Kt[a * n + c] * M[c * dy + b];
            for (c = 0; c < nl; ++c) s -= Lt[a * nl + c] * M[(n + c) * dy + b];
            s -= kt[a] * M[(dy - 1) * dy + b];
            TM[(n + a) * dy + b] = s;
        }
    for (a = 0; a < dw; ++a)
        for (b = a; b < dw; ++b) {
            double s;
            if (b < n) {
                s = TM[a * dy + b];
            } else if (b == dw - 1) {
                s = TM[a * dy + dy - 1];
            } else {
                const int u = b - n;
                s = 0.0;
                for (c = 0; c < n; ++c) s -= TM[a * dy + c] * Kt[u * n + c];
                for (c = 0; c < nl; ++c) s -= TM[a * dy + n + c] * Lt[u * nl + c];
                s -= TM[a * dy + dy - 1] * kt[u];
            }
            Mw[a * dw + b] = Mw[b * dw + a] = s;
        }
    if (um != NULL)
        for (a = 0; a < m; ++a) {
            const double mu = Mw[(n + a) * dw + dw - 1];
            um[a] = mu;
            uv[a] = Mw[(n + a) * dw + n + a] - mu * mu;
        }
}

/* After the tick: M's x blocks from Mw (E x+ x+', E x+) and from Xv (E x+ v'); the state's
 * mean and variance into xm, xv when not NULL. */
static void fold_back(int n, int m, int nl, const double *Mw, const double *Xv, double *M,
                      double *xm, double *xv)
{
    const int dy = n + nl + 1, dw = n + m + 1;
    int a, b;
    for (a = 0; a < n; ++a) {
        for (b = 0; b < nl; ++b) M[a * dy + n + b] = M[(n + b) * dy + a] = Xv[a * nl + b];
        for (b = 0; b < n; ++b) M[a * dy + b] = Mw[a * dw + b];
        M[a * dy + dy - 1] = M[(dy - 1) * dy + a] = Mw[a * dw + dw - 1];
    }
    if (xm != NULL)
        for (a = 0; a < n; ++a) {
            const double mu = M[a * dy + dy - 1];
            xm[a] = mu;
            xv[a] = M[a * dy + a] - mu * mu;
        }
}

size_t stsp_tv_oracle_work_size(int n, int m, int n_latch, int na, int mz)
{
    const size_t dw = (size_t)n + (size_t)m + 1u, dy = (size_t)n + (size_t)n_latch + 1u;
    return dw * dy + dw * dw + dw * (size_t)n_latch + taylor_size(n, m, na, mz, n_latch)
           + blend_size(n, m) + 4u * TV_MAX_POINTS * (size_t)na * n * mz + ops_size(n, na, mz);
}

/* The T ticks of one chunk of a time-varying stage, forward (as stsp_oracle_stage_ticks, M
 * the second moment of y = [x; v; 1]), the mean map's constant column (a drift) included:
 * E x+ v' from the MEAN series on E w v'.  xm, xv (T x n): mean and variance of x after each
 * tick; um, uv (T x m): of the command over it (all four NULL: not recorded).  Data as in
 * stsp_tv_zoh_ticks, coef in the forward variable s. */
TV_CLONES
int stsp_tv_oracle_ticks(int n, int m, int n_latch, long T, const double *K, const double *L,
                         const double *k0, int P, int na, int mz, const double *coef,
                         double h, const int *act, const double *Ar, const double *G,
                         const double *Lb, const int *same, const int *ar_nz, int ar_cnt,
                         int nseg, const double *seg_ops, const double *seg_ends,
                         const int *seg_idx, const double *seg_w, double *M, double *J,
                         double *xm,
                         double *xv, double *um, double *uv, double *work, int *iwork,
                         int noise_path)
{
    const int dy = n + n_latch + 1, dw = n + m + 1, nl = n_latch;
    double *TM, *Mw, *Xv, *tw, *gw;
    tv_blend bl;
    tv_ops ops;
    tv_segs sg;
    double acc = *J;
    long t;
    int a, j, st;
    if (n < 1 || m < 1 || n_latch < 0 || T < 0 || P < 1 || P > TV_MAX_POINTS || na < 0 ||
        na > n + m || mz < 0 || dw > TV_MAX_DIM || ar_cnt < 0 || ar_cnt > n * dw ||
        noise_path < TV_NOISE_AUTO || noise_path > TV_NOISE_SEGMENTS ||
        !segments_ok(n, na, T, P, nseg, seg_ops, seg_ends, seg_idx, seg_w, &sg))
        return TV_ERR_DIMS;
    TM = work; Mw = TM + (size_t)dw * dy; Xv = Mw + (size_t)dw * dw;
    tw = Xv + (size_t)dw * nl;
    gw = blend_at(&bl, tw + taylor_size(n, m, na, mz, nl), iwork, n, m, na, mz);
    sg.gpt = ops_at(&ops, gw + 3u * TV_MAX_POINTS * (size_t)na * n * mz, n, na, mz);
    for (t = 0; t < T; ++t) {
        tv_tick v = tick_of(n, dw, na, mz, P, act, Ar, G, Lb, same, ar_nz, ar_cnt, &sg, t);
        int sub;
        command_moments(n, m, nl, K + (size_t)t * m * n, L + (size_t)t * m * nl,
                        k0 + (size_t)t * m, M, TM, Mw, um ? um + t * m : NULL,
                        uv ? uv + t * m : NULL);
        for (a = 0; a < dw; ++a)                       /* E w v' */
            for (j = 0; j < nl; ++j) Xv[a * nl + j] = TM[a * dy + n + j];
        sub = sub_steps(&v, coef, h, &bl);
        if (sub == 0) return TV_ERR_SERIES;
        lists_of(&v, iwork, gw, &ops, noise_path, sub, T, &sg, 0);
        for (j = 0; j < sub; ++j) {
            if (sub > 1) blend(&v, coef, j, sub, &bl);
            st = taylor(TV_FORWARD, &v, &bl, h / sub, Mw, dw, &acc, tw);
            if (st == TV_OK) st = taylor(TV_MEAN, &v, &bl, h / sub, Xv, nl, NULL, tw);
            if (st) return st;
        }
        fold_back(n, m, nl, Mw, Xv, M, xm ? xm + t * n : NULL, xv ? xv + t * n : NULL);
    }
    *J = acc;
    return TV_OK;
}

/* The Monte Carlo harness's plant scheme over T ticks of a time-varying stage (the oracle's
 * "euler" propagator): each of the `sub` steps of a tick takes the data at its midpoint and
 * does Mw <- Ad Mw Ad' + dt sum_pq Mw[p,q] G_p G_q', its running cost dt <Lb, Mw> taken
 * before the step, and E w v' <- Ad E w v'.  Ad = exp(Ahat dt) per step (T*sub x d x d) from
 * the caller; G and Lb per step as in stsp_tv_oracle_ticks with one point (same[1], same[2]:
 * one for all steps). */
int stsp_tv_euler_oracle_ticks(int n, int m, int n_latch, long T, const double *K,
                               const double *L, const double *k0, int sub, int na, int mz,
                               double dt, const int *act, const double *Ad, const double *G,
                               const double *Lb, const int *same, double *M, double *J,
                               double *xm, double *xv, double *um, double *uv, double *work,
                               int *iwork)
{
    const int dy = n + n_latch + 1, dw = n + m + 1, nl = n_latch;
    const size_t D = (size_t)dw * dw;
    double *TM, *Mw, *Mn, *Xv, *T1, *blk, *tmp, *gw;
    double acc = *J;
    long t;
    int a, b, c, i, no_ar = 0;
    size_t e;
    if (n < 1 || m < 1 || n_latch < 0 || T < 0 || sub < 1 || na < 0 || na > n + m || mz < 0 ||
        dw > TV_MAX_DIM)
        return TV_ERR_DIMS;
    TM = work; Mw = TM + (size_t)dw * dy; Mn = Mw + D; Xv = Mn + D; T1 = Xv + (size_t)dw * nl;
    blk = T1 + D; tmp = blk + D; gw = tmp + noise_tmp_size(n, na, mz);
    for (t = 0; t < T; ++t) {
        command_moments(n, m, nl, K + (size_t)t * m * n, L + (size_t)t * m * nl,
                        k0 + (size_t)t * m, M, TM, Mw, um ? um + t * m : NULL,
                        uv ? uv + t * m : NULL);
        for (a = 0; a < dw; ++a)
            for (b = 0; b < nl; ++b) Xv[a * nl + b] = TM[a * dy + n + b];
        for (i = 0; i < sub; ++i) {
            const double *A = Ad + (size_t)(t * sub + i) * D;
            const int same_all[3] = {1, same[1], same[2]};
            tv_tick v = tick_of(n, dw, na, mz, 1, act, Ad, G, Lb, same_all, &no_ar, 0, NULL,
                                t * sub + i);
            double cost = 0.0;
            for (e = 0; e < D; ++e) cost += v.Lb[e] * Mw[e];
            acc += dt * cost;
            for (a = 0; a < dw; ++a)                   /* T1 = Ad Mw (rows >= n: Mw's) */
                for (b = 0; b < dw; ++b) {
                    double s = 0.0;
                    if (a >= n) { T1[a * dw + b] = Mw[a * dw + b]; continue; }
                    for (c = 0; c < dw; ++c) s += A[a * dw + c] * Mw[c * dw + b];
                    T1[a * dw + b] = s;
                }
            for (a = 0; a < dw; ++a)                   /* Mn = T1 Ad' */
                for (b = a; b < dw; ++b) {
                    double s = 0.0;
                    if (b >= n) {
                        s = T1[a * dw + b];
                    } else {
                        for (c = 0; c < dw; ++c) s += T1[a * dw + c] * A[b * dw + c];
                    }
                    Mn[a * dw + b] = Mn[b * dw + a] = s;
                }
            if (na > 0) {                              /* + dt sum Mw[p,q] G_p G_q' */
                lists_of(&v, iwork, gw, NULL, TV_NOISE_AUTO, 1, 1, NULL, 0);
                if (v.path == TV_NOISE_PAIRS) {
                    pair_noise(TV_FORWARD, &v, 0, dt, Mw, Mn);
                } else {
                    point_noise(TV_FORWARD, &v, 0, Mw, blk, tmp);
                    add_noise(TV_FORWARD, &v, dt, blk, Mn);
                }
            }
            for (a = 0; a < n; ++a)                    /* Xv <- Ad Xv (rows >= n constant) */
                for (b = 0; b < nl; ++b) {
                    double s = 0.0;
                    for (c = 0; c < dw; ++c) s += A[a * dw + c] * Xv[c * nl + b];
                    T1[a * nl + b] = s;
                }
            for (a = 0; a < n; ++a)
                for (b = 0; b < nl; ++b) Xv[a * nl + b] = T1[a * nl + b];
            for (e = 0; e < D; ++e) Mw[e] = Mn[e];
        }
        fold_back(n, m, nl, Mw, Xv, M, xm ? xm + t * n : NULL, xv ? xv + t * n : NULL);
    }
    *J = acc;
    return TV_OK;
}

size_t stsp_tv_euler_work_size(int n, int m, int n_latch, int na, int mz)
{
    const size_t dw = (size_t)n + (size_t)m + 1u, dy = (size_t)n + (size_t)n_latch + 1u;
    return dw * dy + 4u * dw * dw + dw * (size_t)n_latch + noise_tmp_size(n, na, mz)
           + 3u * TV_MAX_POINTS * (size_t)na * n * mz;
}
