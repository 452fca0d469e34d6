/* Shared by the libFuzzer targets (fuzz_step.c, fuzz_verify.c): reading the fuzzer's bytes
 * (an exhausted input reads as zeros, so every input is a complete run) and the invariant
 * check, which aborts with the broken line (libFuzzer then keeps the input as a finding). */
#ifndef FUZZ_INPUT_H
#define FUZZ_INPUT_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>

typedef struct {
    const uint8_t *p;
    size_t n;
} fuzz_in_t;

static uint32_t fuzz_u8(fuzz_in_t *in)
{
    uint32_t v = 0u;
    if (in->n > 0u) {
        v = in->p[0];
        ++in->p;
        --in->n;
    }
    return v;
}

/* Four bytes, little-endian. */
static uint32_t fuzz_u32(fuzz_in_t *in)
{
    uint32_t v = fuzz_u8(in);
    v |= fuzz_u8(in) << 8;
    v |= fuzz_u8(in) << 16;
    v |= fuzz_u8(in) << 24;
    return v;
}

static void fuzz_check_at(int ok, const char *file, int line)
{
    if (!ok) {
        (void)fprintf(stderr, "fuzz: invariant broken at %s:%d\n", file, line);
        abort();
    }
}
#define fuzz_check(ok) fuzz_check_at((ok), __FILE__, __LINE__)

#endif /* FUZZ_INPUT_H */
