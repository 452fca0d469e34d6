/* Host-side kernel of the fourth-moment oracle (stospline.oracle.tails.evaluate_tails): the
 * step's linear map on symmetric tensors, and the tick loop of one time-invariant stage.
 * Not firmware: it runs on the design host, in double precision, called through cffi
 * (stospline.oracle.tails_kernel), and equals the numpy loop of evaluate_tails to rounding.
 *
 * Notation (tails.py): n states, m inputs, P latched multipliers, y = [x; v; 1] (d_y =
 * n+P+1) the loop's state between ticks, q = [x; u; v; 1] (d_q = n+m+P+1) over a tick, with
 * u = Tu y, Tu = [-K_j, -L_j, -k0_j].  Symmetric tensors of order o on R^d are kept on the
 * multisets of indices ("compressed", numbered as itertools.combinations_with_replacement);
 * of_full maps a full index (row-major, d^o entries) to its multiset's number.
 *
 * Row-major, caller-owned arrays; nothing allocated.  Both return 0, or -2 for dimensions
 * out of range.
 */
#include <stddef.h>
#include <stdint.h>

/* Rows `row0 .. row0+rows-1` of the map T -> sum_w w M_w^(x)o T on compressed tensors of
 * order o (<= 4) on R^d, added into out (rows x size): for the multiset (i_1..i_o) of a row,
 * the products M[i_1, j_1] ... M[i_o, j_o] over every full index j (zeros skipped) are summed
 * into j's multiset in increasing order of j, as numpy's collapse does, then times the node's
 * weight.  idx (size x o) the multisets, M (nodes x d x d), w (nodes), of_full (d^o).
 * work: size + d*d doubles; iwork: 2 size + d + d*d int64 (zero on entry, left zero). */
int stsp_tails_operator(int d, int o, long size, long row0, long rows, const int64_t *idx,
                        long nodes, const double *M, const double *w, const int64_t *of_full,
                        double *out, double *work, int64_t *iwork)
{
    double *acc = work, *val = work + size;
    int64_t *mark = iwork, *hit = mark + size, *nz = hit + size, *col = nz + d;
    long node, r, s, stride[4];
    int a, t, cnt[4];
    if (d < 1 || o < 1 || o > 4 || size < 1 || row0 < 0 || rows < 0 || row0 + rows > size
        || nodes < 0) {
        return -2;
    }
    stride[o - 1] = 1;
    for (t = o - 2; t >= 0; --t) {
        stride[t] = stride[t + 1] * d;
    }
    for (s = 0; s < size; ++s) {
        acc[s] = 0.0;
    }
    for (node = 0; node < nodes; ++node) {
        const double *Mn = M + node * d * d;
        for (a = 0; a < d; ++a) {                  /* each row's nonzeros, columns ascending */
            int b, k = 0;
            for (b = 0; b < d; ++b) {
                if (Mn[a * d + b] != 0.0) {
                    col[a * d + k] = b;
                    val[a * d + k] = Mn[a * d + b];
                    ++k;
                }
            }
            nz[a] = k;
        }
        for (r = row0; r < row0 + rows; ++r) {
            const int64_t *i = idx + r * o;
            long nh = 0, h;
            int empty = 0;
            for (t = 0; t < o; ++t) {
                cnt[t] = 0;
                empty |= nz[i[t]] == 0;
            }
            while (!empty) {                       /* odometer over the rows' nonzeros */
                double p = val[i[0] * d + cnt[0]];
                long f = (long)col[i[0] * d + cnt[0]] * stride[0];
                for (t = 1; t < o; ++t) {
                    p *= val[i[t] * d + cnt[t]];
                    f += (long)col[i[t] * d + cnt[t]] * stride[t];
                }
                s = (long)of_full[f];
                if (!mark[s]) {
                    mark[s] = 1;
                    hit[nh++] = s;
                }
                acc[s] += p;
                for (t = o - 1; t >= 0; --t) {
                    if (++cnt[t] < nz[i[t]]) {
                        break;
                    }
                    cnt[t] = 0;
                }
                if (t < 0) {
                    break;
                }
            }
            for (h = 0; h < nh; ++h) {
                s = (long)hit[h];
                out[(r - row0) * size + s] += w[node] * acc[s];
                acc[s] = 0.0;
                mark[s] = 0;
            }
        }
    }
    return 0;
}

/* C(dy + s - 1, s): the multisets of s indices out of dy. */
static long tails_multisets(int dy, int s)
{
    long c = 1;
    int i;
    for (i = 1; i <= s; ++i) {
        c = c * (dy + i - 1) / i;
    }
    return c;
}

/* Where the insertion table of multisets of size s starts in `ins` (sizes 1, 2, ... in turn,
 * each dy x C(dy + s - 2, s - 1)). */
static long tails_ins_offset(int dy, int s)
{
    long off = 0;
    int r;
    for (r = 1; r < s; ++r) {
        off += (long)dy * tails_multisets(dy, r - 1);
    }
    return off;
}

/* The staged contraction of a symmetric tensor W_0 of order o on R^{d_y} (compressed) with
 * the command's rows: W_k[a_1..a_k][t] = sum_j Tu[a_k, j] W_{k-1}[a_1..a_{k-1}][{j} + t] over
 * the multisets t of o-k indices, the levels one after another in buf (W_0 first, then m
 * blocks of the next size, m^2 of the next, ...): every moment of q is an entry of some level
 * (`src`).  ins[s]: the number of the multiset {j} + t of size s, per j and t of size s-1. */
static void tails_levels(double *buf, const double *Tu, const int64_t *ins, int m, int dy,
                         int o)
{
    double *prev = buf, *next = buf + tails_multisets(dy, o);
    long blocks = 1, A, t;
    int k, a, j;
    for (k = 1; k <= o; ++k) {
        const long cp = tails_multisets(dy, o - k + 1), cn = tails_multisets(dy, o - k);
        const int64_t *tab = ins + tails_ins_offset(dy, o - k + 1);
        for (A = 0; A < blocks; ++A) {
            const double *src = prev + A * cp;
            for (a = 0; a < m; ++a) {
                double *dst = next + (A * m + a) * cn;
                const double *row = Tu + a * dy;
                for (t = 0; t < cn; ++t) {
                    dst[t] = 0.0;
                }
                for (j = 0; j < dy; ++j) {
                    const double c = row[j];
                    const int64_t *put = tab + (long)j * cn;
                    for (t = 0; t < cn; ++t) {
                        dst[t] += c * src[put[t]];
                    }
                }
            }
        }
        prev = next;
        blocks *= m;
        next += blocks * cn;
    }
}

static long tails_level_size(int m, int dy, int o)
{
    long total = 0, mk = 1;
    int k;
    for (k = 0; k <= o; ++k) {
        total += mk * tails_multisets(dy, o - k);
        mk *= m;
    }
    return total;
}

size_t stsp_tails_ticks_work(int m, int dy, long D4, long D2)
{
    return (size_t)tails_level_size(m, dy, 4) + (size_t)tails_level_size(m, dy, 2)
           + 2u * ((size_t)D4 + (size_t)D2 + 1u) + (size_t)m * (size_t)dy;
}

/* The ticks of one stage: per tick j, Tu from the gains, the moments of q gathered from the
 * levels of E y^(x)4 and E J y y' (src4, src2 into the levels of order 4 and 2), the step's
 * map (CSR: rowptr, colidx, val; D4 + D2 + 1 square, on [E q^(x)4; E J q q'; E J^2]
 * compressed) applied `substeps` times, and y's moments gathered back (back4, back2: the
 * numbers of y's multisets among q's).  ins: the insertion tables of `tails_levels` for sizes
 * 1 to 4.  K (T x m x n), L (T x m x P), k0 (T x m); Y4 (C(d_y + 3, 4)), Y2 (C(d_y + 1, 2)),
 * compressed, and J2 in/out; work: stsp_tails_ticks_work doubles. */
int stsp_tails_ticks(int n, int m, int P, long T, const double *K, const double *L,
                     const double *k0, long D4, long D2, const int64_t *rowptr,
                     const int64_t *colidx, const double *val, int substeps,
                     const int64_t *ins, const int64_t *src4, const int64_t *src2,
                     const int64_t *back4, const int64_t *back2, double *Y4, double *Y2,
                     double *J2, double *work)
{
    const int dy = n + P + 1;
    const long c2 = tails_multisets(dy, 2), c4 = tails_multisets(dy, 4), D = D4 + D2 + 1;
    double *b4 = work, *b2 = b4 + tails_level_size(m, dy, 4);
    double *V = b2 + tails_level_size(m, dy, 2), *Vn = V + D, *Tu = Vn + D;
    long j, r, i;
    int a, b, step;
    if (n < 1 || m < 1 || P < 0 || T < 0 || D4 < 1 || D2 < 1 || substeps < 1) {
        return -2;
    }
    for (i = 0; i < c4; ++i) {
        b4[i] = Y4[i];
    }
    for (i = 0; i < c2; ++i) {
        b2[i] = Y2[i];
    }
    V[D - 1] = *J2;
    for (j = 0; j < T; ++j) {
        for (a = 0; a < m; ++a) {
            double *row = Tu + a * dy;
            for (b = 0; b < n; ++b) {
                row[b] = -K[(j * m + a) * n + b];
            }
            for (b = 0; b < P; ++b) {
                row[n + b] = -L[(j * m + a) * P + b];
            }
            row[dy - 1] = -k0[j * m + a];
        }
        tails_levels(b4, Tu, ins, m, dy, 4);
        tails_levels(b2, Tu, ins, m, dy, 2);
        for (r = 0; r < D4; ++r) {
            V[r] = b4[src4[r]];
        }
        for (r = 0; r < D2; ++r) {
            V[D4 + r] = b2[src2[r]];
        }
        for (step = 0; step < substeps; ++step) {
            double *swap;
            for (r = 0; r < D; ++r) {
                double s = 0.0;
                for (i = rowptr[r]; i < rowptr[r + 1]; ++i) {
                    s += val[i] * V[colidx[i]];
                }
                Vn[r] = s;
            }
            swap = V;
            V = Vn;
            Vn = swap;
        }
        for (i = 0; i < c4; ++i) {
            b4[i] = V[back4[i]];
        }
        for (i = 0; i < c2; ++i) {
            b2[i] = V[D4 + back2[i]];
        }
    }
    for (i = 0; i < c4; ++i) {
        Y4[i] = b4[i];
    }
    for (i = 0; i < c2; ++i) {
        Y2[i] = b2[i];
    }
    *J2 = V[D - 1];
    return 0;
}
