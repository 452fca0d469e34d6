/* Host-side kernel of the fixed-point spline fit (stospline.table.spline.fixed_point): a stage's integer
 * cubic B-splines evaluated at every tick exactly as the firmware evaluates them, and their
 * worst error against the values fitted.  Not firmware: it runs on the design host, called
 * from Python through cffi (stospline.table.kernels), once per span length the fit tries.
 *
 * Entry e of a stage of T ticks in spans of D = 2^k ticks has coefficients C[e][0 .. nb-1]
 * (int64 here, int16/int32 in the table) and scale shift[e].  At tick t (sigma = t >> k,
 * d = t & (D - 1)):
 *
 *     P0 = (D - d)^3     P1 = 4 D^3 - 3 d^2 (2 D - d)     P3 = d^3     P2 = 6 D^3 - P0 - P1 - P3
 *     acc = C[sigma] P0 + C[sigma+1] P1 + C[sigma+2] P2 + C[sigma+3] P3           (int64)
 *     G[e][t] = floor((acc + 2^(3k + shift - 1)) / 2^(3k + shift))              (round half up)
 *
 * and err[e] = max over t of |G[e][t] - YT[e][t]| (double; NaN if a value is NaN).  Every
 * operation is exact in integers, so the bits are those of the numpy reference
 * (qspline._stage_gains) and of the firmware.  Caller-owned arrays, nothing allocated.
 *
 * allowed (E doubles, or NULL): stop after the first entry whose err exceeds allowed[e] (or
 * either is NaN) and return 1 (G and err of the later entries are then not computed): a span
 * length the fit tries in vain is given up at its first entry that misses.
 *
 * Returns 0 (every value within allowed, or allowed NULL), 1 (a miss), or -1 for arguments it
 * does not take: k outside [0, 9], T < 1, E < 0, too few coefficients (nb < sigma_max + 4),
 * a shift outside [1, 30] or 3k + shift > 62, or a coefficient beyond int32
 * (|acc| < 6 D^3 2^31 <= 2^61 then holds).
 */
#include <math.h>
#include <stddef.h>
#include <stdint.h>

static int64_t floor_shift(int64_t q, int s)
{
    /* floor(q / 2^s), branch-free, without right-shifting a negative number (which C leaves
     * to the implementation): for q < 0, floor(q / 2^s) = ~(~q >> s) with ~q >= 0. */
    const uint64_t neg = (uint64_t)0 - ((uint64_t)q >> 63);
    return (int64_t)((((uint64_t)q ^ neg) >> s) ^ neg);
}

int stsp_qspline_stage(int k, long T, long E, long nb, const int64_t *C, const int64_t *shift,
                       const double *YT, const double *allowed, int64_t *G, double *err)
{
    long e, t, i;
    int64_t D, D3;

    if (k < 0 || k > 9 || T < 1 || E < 0 || nb < ((T - 1) >> k) + 4) {
        return -1;
    }
    for (e = 0; e < E; ++e) {
        if (shift[e] < 1 || shift[e] > 30 || 3 * k + shift[e] > 62) {
            return -1;
        }
        for (i = 0; i < nb; ++i) {
            if (C[e * nb + i] < INT32_MIN || C[e * nb + i] > INT32_MAX) {
                return -1;
            }
        }
    }
    D = (int64_t)1 << k;
    D3 = D * D * D;
    for (e = 0; e < E; ++e) {
        const int s = 3 * k + (int)shift[e];
        const int64_t half = (int64_t)1 << (s - 1);
        const int64_t *c = C + e * nb;
        const double *y = YT + e * T;
        const double limit = allowed != NULL ? allowed[e] : INFINITY;
        int64_t *g = G + e * T;
        double worst = 0.0;
        int nan = 0;
        for (t = 0; t < T; ++t) {
            const long sigma = t >> k;
            const int64_t d = (int64_t)t & (D - 1);
            const int64_t P0 = (D - d) * (D - d) * (D - d);
            const int64_t P1 = 4 * D3 - 3 * d * d * (2 * D - d);
            const int64_t P3 = d * d * d;
            const int64_t P2 = 6 * D3 - P0 - P1 - P3;
            const int64_t acc = c[sigma] * P0 + c[sigma + 1] * P1 + c[sigma + 2] * P2
                                + c[sigma + 3] * P3;
            const int64_t q = floor_shift(acc + half, s);
            const double diff = fabs((double)q - y[t]);
            g[t] = q;
            worst = diff > worst ? diff : worst;
            nan |= diff != diff;
        }
        if (nan ? allowed != NULL : !(worst <= limit)) {
            return 1;                 /* NaN is within no allowance, nor anything within NaN */
        }
        err[e] = nan ? NAN : worst;
    }
    return 0;
}
