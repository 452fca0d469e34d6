/* Shared by the libFuzzer targets of the companion tables (fuzz_estimator.c, fuzz_params.c):
 * the statuses an init may return, a step's tick and its float inputs, and the words of a
 * copied array the fuzzer changes. Include after fuzz_input.h and the tables' header. */
#ifndef FUZZ_TABLES_H
#define FUZZ_TABLES_H

#include <string.h>

#include "fuzz_input.h"

/* A status stsp_est_init / stsp_param_init may return. */
static int fuzz_init_status_ok(stsp_status_t st)
{
    return (st == STSP_OK) || (st == STSP_ERR_NULL) || (st == STSP_ERR_BAD_MAGIC) ||
           (st == STSP_ERR_BAD_VERSION) || (st == STSP_ERR_BAD_DIMS) ||
           (st == STSP_ERR_BAD_CRC) || (st == STSP_ERR_BAD_PROBLEM) ||
           (st == STSP_ERR_BAD_VALUES);
}

/* The tick of a step after `next` (the tick in order), by the operation's low two bits. */
static uint32_t fuzz_tick(fuzz_in_t *in, uint32_t op, uint32_t next)
{
    switch (op & 3u) {
    case 0: return next;                              /* in order */
    case 1: return next + (fuzz_u8(in) % 50u);        /* a skip */
    case 2: return next - 1u - (fuzz_u8(in) % 3u);    /* repeat, backwards, wrap */
    default: return fuzz_u32(in);
    }
}

/* n floats of any bit pattern (NaN, Inf, huge); with `moderate`, mostly of magnitude about 1
 * (the exponent of 1.0f, any sign and mantissa). */
static inline void fuzz_floats(fuzz_in_t *in, float *x, uint32_t n, int moderate)
{
    uint32_t j;
    for (j = 0u; j < n; ++j) {
        uint32_t bits = fuzz_u32(in);
        if (moderate != 0) {
            bits = 0x3F800000u ^ (bits & 0x807FFFFFu);
        }
        memcpy(&x[j], &bits, sizeof bits);
    }
}

/* 1 + (v % 4) words of a[0..n-1], each of any bit pattern at a place the fuzzer chooses. */
static inline void fuzz_words(fuzz_in_t *in, float *a, uint32_t n, uint32_t v)
{
    uint32_t k;
    for (k = 0u; k < 1u + (v % 4u); ++k) {
        const uint32_t bits = fuzz_u32(in);
        memcpy(&a[fuzz_u32(in) % n], &bits, sizeof bits);
    }
}

#endif /* FUZZ_TABLES_H */
