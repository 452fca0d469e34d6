/* Harness-only standard normal numbers for the plant (not firmware): see plant.h.
 *
 * Why not numpy's C library (numpy/random/lib/libnpyrandom.a, random_standard_normal on a
 * bitgen_t), which the cffi build can find through numpy.get_include(): per number it takes
 * 9.5 ns on numpy's default PCG64 and 7.4 ns even on this file's xoshiro256++ behind a
 * bitgen_t (a call through a pointer per word, no inlining), against 1.9 ns here
 * (tools/bench/normal_generators.py, docs/evidence/performance.md); the robot draws two a
 * path-tick, the chance-constrained one eight. */
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "plant.h"
#include "ziggurat_tables.h"

/* xoshiro256++ (Blackman & Vigna, "Scrambled linear pseudorandom number generators", ACM
 * TOMS 47(4), 2021): 64 bits per call, period 2^256 - 1. */
static inline uint64_t rotl(uint64_t x, int k)
{
    return (x << k) | (x >> (64 - k));
}

static inline uint64_t next_word(uint64_t *s)
{
    const uint64_t out = rotl(s[0] + s[3], 23) + s[0];
    const uint64_t t = s[1] << 17;
    s[2] ^= s[0];
    s[3] ^= s[1];
    s[1] ^= s[2];
    s[0] ^= s[3];
    s[2] ^= t;
    s[3] = rotl(s[3], 45);
    return out;
}

/* A uniform number in [0, 1) with 53 random bits. */
static inline double next_unit(uint64_t *s)
{
    return (double)(int64_t)(next_word(s) >> 11) * 0x1p-53;
}

/* The ziggurat: one word gives the layer (8 bits), the sign (1 bit) and a 52-bit magnitude;
 * ~99% of draws are accepted inside their layer's core with one multiply (harness_normals,
 * inline). The rest come here with their word r: they test the wedge against the density
 * (layer i spans heights f(x_i) .. f(x_{i+1})), or (layer 0) sample the tail beyond R
 * (Marsaglia 1964), drawing further words from s; a rejected draw starts again. */
#if defined(__GNUC__)
__attribute__((noinline, cold))
#endif
static double slow_normal(uint64_t *s, uint64_t r)
{
    for (;;) {
        const unsigned layer = (unsigned)(r & 0xffu);
        const int negative = (int)((r >> 8) & 1u);
        const uint64_t mag = (r >> 9) & 0x000fffffffffffffULL;
        double x = (double)(int64_t)mag * harness_zig_w[layer];
        if (mag < harness_zig_k[layer]) {
            return negative ? -x : x;
        }
        if (layer == 0u) {
            double xx, yy;
            do {
                xx = -log1p(-next_unit(s)) / HARNESS_ZIG_R;
                yy = -log1p(-next_unit(s));
            } while (yy + yy <= xx * xx);
            x = HARNESS_ZIG_R + xx;
            return negative ? -x : x;
        }
        if (harness_zig_f[layer]
                + next_unit(s) * (harness_zig_f[layer + 1u] - harness_zig_f[layer])
            < exp(-0.5 * x * x)) {
            return negative ? -x : x;
        }
        r = next_word(s);
    }
}

/* The generator's state in four locals (registers: the array's address is taken only on the
 * rare draws, which copy it), next_word written out in the loop, and the sign applied as a
 * flip of the sign bit (what negation does) instead of a branch on a random bit: 1.9 ns a
 * number instead of 5.3 (tools/bench/normal_generators.py), the same numbers
 * (tests/python/sim/test_normals.py checks them against the algorithm written plainly). */
void harness_normals(uint64_t *state, double *out, size_t count)
{
    uint64_t s0 = state[0], s1 = state[1], s2 = state[2], s3 = state[3];
    size_t i;
    for (i = 0; i < count; ++i) {
        const uint64_t r = rotl(s0 + s3, 23) + s0;
        const uint64_t t = s1 << 17;
        const unsigned layer = (unsigned)(r & 0xffu);
        const uint64_t mag = (r >> 9) & 0x000fffffffffffffULL;
        s2 ^= s0;
        s3 ^= s1;
        s1 ^= s2;
        s0 ^= s3;
        s2 ^= t;
        s3 = rotl(s3, 45);
        if (mag < harness_zig_k[layer]) {
            double x = (double)(int64_t)mag * harness_zig_w[layer];
            uint64_t bits;
            memcpy(&bits, &x, sizeof bits);
            bits ^= (r & 0x100u) << 55;
            memcpy(&x, &bits, sizeof x);
            out[i] = x;
        } else {
            uint64_t s[4];
            s[0] = s0; s[1] = s1; s[2] = s2; s[3] = s3;
            out[i] = slow_normal(s, r);
            s0 = s[0]; s1 = s[1]; s2 = s[2]; s3 = s[3];
        }
    }
    state[0] = s0; state[1] = s1; state[2] = s2; state[3] = s3;
}
