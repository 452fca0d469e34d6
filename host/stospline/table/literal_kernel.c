/* Host-side kernel of the C text of a table (stospline.table.codegen): the shortest decimal of
 * each binary32 that reads back as the same binary32, written as numpy writes it with
 * format_float_scientific(x, unique=True, trim="0", exp_digits=2) plus the suffix f:
 * "-1.2573022e-01f", "1.0e+00f", "0.0e+00f".  Not firmware.
 *
 * Exact integer arithmetic.  x = M 2^E (M < 2^24).  With p significant digits and x's decimal
 * exponent e, the nearest p-digit decimal is q 10^k, k = e - p + 1, q = round(x / 10^k), and
 * x / 10^k = num / den with num, den integers (powers of 2 and 5 times M).  The decimal reads
 * back as x when it lies inside x's rounding interval, x +- 2^(E-1) (symmetric where M is not
 * a power of two): |q - num/den| < num / (2 M den), i.e. 2 M |q den - num| < num.  The p-digit
 * decimals of one decade are multiples of 10^k and the (p+1)-digit ones include them, so the
 * nearest (p+1)-digit decimal is at least as near: reading back is monotone in p, and a
 * search down from p = 8 finds the least (9 digits always read back for binary32; a table's
 * gains mostly need 7 or 8, so that order tries fewer p than a bisection).  Of the p-digit
 * decimals inside a symmetric interval the nearest is the one numpy's Dragon4 writes.
 *
 * The values where that argument does not hold, or the integers would not fit 128 bits, are
 * flagged instead of written, for numpy to write: a power
 * of two (its interval below is half as wide), |x| outside [2^-60, 2^22) (above, a midpoint
 * between two binary32 has at most 9 significant digits and may be a candidate; below, 5^k
 * outgrows the integers), and a candidate exactly halfway between two p-digit decimals.
 *
 * stsp_f32_array_text writes a whole array's body, as codegen lays it out.
 */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define STSP_LITERAL_SLOT 16  /* "-1.23456789e-38f": 16 characters, no NUL when full */

#ifdef __SIZEOF_INT128__
__extension__ typedef unsigned __int128 stsp_u128;

typedef struct {
    uint64_t q;   /* the p-digit decimal's digits, q 10^k */
    int inside;   /* it reads back as x */
    int tie;      /* x is halfway between two p-digit decimals */
} stsp_candidate;

static uint64_t pow5(int a)   /* 5^a, 0 <= a <= 27 (5^27 < 2^63) */
{
    static const uint64_t table[28] = {
        1u, 5u, 25u, 125u, 625u, 3125u, 15625u, 78125u, 390625u, 1953125u, 9765625u,
        48828125u, 244140625u, 1220703125u, 6103515625u, 30517578125u, 152587890625u,
        762939453125u, 3814697265625u, 19073486328125u, 95367431640625u, 476837158203125u,
        2384185791015625u, 11920928955078125u, 59604644775390625u, 298023223876953125u,
        1490116119384765625u, 7450580596923828125u};
    return table[a];
}

/* The nearest decimal q 10^k to x = M 2^E, k given; -27 <= k <= 6 and -84 <= E <= -2 here. */
static stsp_candidate nearest(uint32_t M, int E, int k)
{
    stsp_u128 num = M, den = 1, q, r, diff;
    stsp_candidate c;
    if (k < 0) {
        num *= pow5(-k);
    } else {
        den *= pow5(k);
    }
    if (E - k >= 0) {
        num <<= (unsigned)(E - k);
    } else {
        den <<= (unsigned)(k - E);
    }
    if (k <= 0) {          /* den a power of two (most gains): a shift, not a 128-bit division */
        const unsigned s = E - k >= 0 ? 0u : (unsigned)(k - E);
        q = num >> s;
        r = num - (q << s);
    } else {
        q = num / den;
        r = num - q * den;
    }
    c.tie = (2u * r == den);
    if (2u * r > den) {
        ++q;
    }
    diff = q * den > num ? q * den - num : num - q * den;
    c.inside = 2u * (stsp_u128)M * diff < num;
    c.q = (uint64_t)q;
    return c;
}

/* floor(log10 x) from log10, then checked exactly: x's 9-digit decimal has 9 digits (or is
 * 10^9, x rounded up to the next decade).  *nine is that 9-digit decimal at the exponent
 * returned. */
static int decimal_exponent(uint32_t M, int E, float ax, stsp_candidate *nine)
{
    int e = (int)floor(log10((double)ax));
    *nine = nearest(M, E, e - 8);
    if (nine->q < 100000000u) {
        *nine = nearest(M, E, --e - 8);
    } else if (nine->q > 1000000000u) {
        *nine = nearest(M, E, ++e - 8);
    }
    return e;
}

/* Writes the literal of a finite, nonzero x into slot; 0 when x is one to flag instead. */
static int write_literal(float x, char *slot)
{
    const float ax = fabsf(x);
    int E2, e, p = 9, n = 0, ndig, i;
    uint32_t M;
    uint64_t q;
    char digits[24];
    stsp_candidate c, best;
    const float m = frexpf(ax, &E2);   /* ax = m 2^E2, m in [1/2, 1) */
    if (m == 0.5f || ax < 8.67361738e-19f /* 2^-60 */ || ax >= 4194304.0f /* 2^22 */) {
        return 0;
    }
    M = (uint32_t)ldexpf(m, 24);
    E2 -= 24;
    e = decimal_exponent(M, E2, ax, &best);
    for (i = 8; i >= 1; --i) {                  /* the least p: down until i digits fail */
        c = nearest(M, E2, e - i + 1);
        if (c.tie) {
            return 0;
        }
        if (!c.inside) {
            break;
        }
        best = c;
        p = i;
    }
    if (best.tie || !best.inside) {
        return 0;
    }
    q = best.q;
    for (ndig = 0; q > 0; q /= 10u) {          /* the digits, last first */
        digits[ndig++] = (char)('0' + (int)(q % 10u));
    }
    e += ndig - p;                              /* q rounded up to 10^p: one more digit */
    while (ndig > 1 && digits[0] == '0') {      /* trailing zeros: "1.0", never "1.00" */
        memmove(digits, digits + 1, (size_t)--ndig);
    }
    if (x < 0.0f) {
        slot[n++] = '-';
    }
    slot[n++] = digits[ndig - 1];
    slot[n++] = '.';
    if (ndig == 1) {
        slot[n++] = '0';
    }
    for (i = ndig - 2; i >= 0; --i) {
        slot[n++] = digits[i];
    }
    slot[n++] = 'e';
    slot[n++] = e < 0 ? '-' : '+';
    slot[n++] = (char)('0' + abs(e) / 10);
    slot[n++] = (char)('0' + abs(e) % 10);
    slot[n] = 'f';
    return 1;
}

#else
static int write_literal(float x, char *slot)
{
    (void)x; (void)slot;
    return 0;   /* no 128-bit integers: numpy writes every literal */
}
#endif

/* The body of a C array of the N binary32 x: lines of per_line literals, each line "    a, b,
 * ...," and the lines joined by newlines (stospline.table.codegen._array).  A value to flag
 * is written as the single character '?' and its index appended to flagged; *n_flagged says
 * how many.  Returns the length written, or -1 for N < 1, per_line < 1, a non-finite value
 * or cap too small (N (STSP_LITERAL_SLOT + 2) + 4 (N / per_line + 1) + 8 always suffices:
 * a literal and its comma, a space or a newline and 4 spaces before it). */
long stsp_f32_array_text(long N, const float *x, long per_line, char *out, long cap,
                         long *flagged, long *n_flagged)
{
    long i, n = 0;
    *n_flagged = 0;
    if (N < 1 || per_line < 1) {
        return -1;
    }
    for (i = 0; i < N; ++i) {
        char slot[STSP_LITERAL_SLOT];
        long len = 0;
        if (cap - n < STSP_LITERAL_SLOT + 6) {
            return -1;
        }
        if (!isfinite(x[i])) {
            return -1;
        }
        if (i % per_line == 0) {
            if (i > 0) {
                out[n++] = '\n';
            }
            memcpy(out + n, "    ", 4);
            n += 4;
        } else {
            out[n++] = ' ';
        }
        memset(slot, 0, sizeof slot);
        if (x[i] == 0.0f) {               /* -0 as +0: stospline.table.format.positive_zeros */
            memcpy(slot, "0.0e+00f", 8);
        } else if (!write_literal(x[i], slot)) {
            slot[0] = '?';
            flagged[(*n_flagged)++] = i;
        }
        while (len < STSP_LITERAL_SLOT && slot[len] != '\0') {
            out[n++] = slot[len++];
        }
        out[n++] = ',';
    }
    return n;
}
