/* Host-side kernel of the table layer (stospline.table.spline.latch): the composition of a
 * stage's affine tick maps under a law as implemented.  Not firmware: it runs on the design
 * host, in double precision, called from Python through cffi (stospline.table.kernels).
 *
 * Each tick's block P[t] = [A_t | C_t] (n x d, row-major; A_t is n x n) is the map
 * [m; c] -> [A_t m + C_t c; c] (c the constants [v; 1]).  The stage's block is
 * P[T-1] o ... o P[0], composed tick by tick:
 *
 *     M = P[0];   M <- [A_t M_A | A_t M_C + C_t]   for t = 1 .. T-1
 *
 * each entry summed left to right over j = 0 .. n-1, then C_t added (no BLAS: the same bits
 * on every machine).  Caller-owned arrays, nothing allocated; work holds 2 n d doubles.
 * Returns 0, or -1 for dimensions it does not take (n < 1, d < n, T < 1).
 * stsp_affine_compose_gains (below) forms each P[t] from the law's gains itself.
 */
#include <stddef.h>
#include <stdint.h>
#include <string.h>

/* Row i of [A | C] o M: out[c] = row[0] M[0][c] + row[1] M[1][c] + ... (left to right), plus
 * row[c] for the constant columns c >= n; the row's entries `stride` apart.  Column c
 * innermost: the same sum per entry as looping over j innermost, and the columns' sums
 * independent, which the compiler vectorises. */
static void compose_row(const double *row, size_t stride, const double *cur, size_t un,
                        size_t ud, double *out)
{
    size_t j, c;

    for (c = 0; c < ud; ++c) {
        out[c] = row[0] * cur[c];
    }
    for (j = 1; j < un; ++j) {
        const double r = row[j * stride];
        const double *m = cur + j * ud;
        for (c = 0; c < ud; ++c) {
            out[c] += r * m[c];
        }
    }
    for (c = un; c < ud; ++c) {
        out[c] += row[c * stride];
    }
}

/* next = B o cur, B's row i at rows + i * row_step, its entries entry_step apart. */
static void apply_block(const double *rows, size_t row_step, size_t entry_step,
                        const double *cur, double *next, size_t un, size_t ud)
{
    size_t i;

    for (i = 0; i < un; ++i) {
        compose_row(rows + i * row_step, entry_step, cur, un, ud, next + i * ud);
    }
}

int stsp_affine_compose(int n, int d, long T, const double *P, double *out, double *work)
{
    size_t nd, un, ud;
    long t;
    double *cur, *next, *swap;

    if (n < 1 || d < n || T < 1) {
        return -1;
    }
    un = (size_t)n;
    ud = (size_t)d;
    nd = un * ud;
    cur = work;
    next = work + nd;
    memcpy(cur, P, nd * sizeof(double));
    for (t = 1; t < T; ++t) {
        apply_block(P + (size_t)t * nd, ud, 1, cur, next, un, ud);
        swap = cur;
        cur = next;
        next = swap;
    }
    memcpy(out, cur, nd * sizeof(double));
    return 0;
}

/* The composition of a stage's tick maps under a law given by its gains (spline_latch's
 * _stage_map), without forming the blocks: tick t's block is
 *
 *     P[t] = base;   P[t][r][col[k]] += g[t][k] * vec[k][r]   for k = 0 .. K-1, in turn
 *
 * (base = [Ad | 0 | fd], n x d; vec[k] = -Bd[:, input of gain k], n; col[k] its column in
 * [x | v | 1]; g (T x K) the tick's gains), each a product then a sum (no fused multiply-add
 * in ISO C: the bits of the numpy reference, spline_latch._tick_blocks), then composed as
 * stsp_affine_compose does.  work holds 4 n d doubles.  Returns 0, or -1 for dimensions or
 * columns it does not take (n < 1, d < n, T < 1, K < 0, a column outside [0, d)).
 */
static void tick_block(size_t un, size_t ud, long K, const double *g, const int64_t *col,
                       const double *vec, const double *baseT, double *PT)
{
    /* The block transposed (PT[c][r] = P[r][c]): a gain's n terms land side by side. */
    long k;
    size_t r;

    memcpy(PT, baseT, un * ud * sizeof(double));
    for (k = 0; k < K; ++k) {
        const double *v = vec + (size_t)k * un;
        double *column = PT + (size_t)col[k] * un;
        for (r = 0; r < un; ++r) {
            column[r] += g[k] * v[r];
        }
    }
}

int stsp_affine_compose_gains(int n, int d, long T, long K, const double *g, const int64_t *col,
                              const double *vec, const double *base, double *out,
                              double *work)
{
    size_t nd, i, c, un, ud;
    long t, k;
    double *cur, *next, *PT, *baseT, *swap;

    if (n < 1 || d < n || T < 1 || K < 0) {
        return -1;
    }
    for (k = 0; k < K; ++k) {
        if (col[k] < 0 || col[k] >= d) {
            return -1;
        }
    }
    un = (size_t)n;
    ud = (size_t)d;
    nd = un * ud;
    cur = work;
    next = work + nd;
    PT = work + 2 * nd;
    baseT = work + 3 * nd;
    for (i = 0; i < un; ++i) {
        for (c = 0; c < ud; ++c) {
            baseT[c * un + i] = base[i * ud + c];
        }
    }
    tick_block(un, ud, K, g, col, vec, baseT, PT);
    for (i = 0; i < un; ++i) {
        for (c = 0; c < ud; ++c) {
            cur[i * ud + c] = PT[c * un + i];
        }
    }
    for (t = 1; t < T; ++t) {
        tick_block(un, ud, K, g + (size_t)t * (size_t)K, col, vec, baseT, PT);
        apply_block(PT, 1, un, cur, next, un, ud);
        swap = cur;
        cur = next;
        next = swap;
    }
    memcpy(out, cur, nd * sizeof(double));
    return 0;
}
