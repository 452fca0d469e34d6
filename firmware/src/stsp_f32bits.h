/* Private: the finiteness test of a binary32 by its bit pattern, shared by the controller
 * (stsp_internal.h) and the band solver (stsp_bandqp.c). Not installed. */
#ifndef STSP_F32BITS_H
#define STSP_F32BITS_H

#include <stdint.h>
#include <string.h>

/* 1 when the binary32 value is finite, else 0: its exponent bits are all ones for NaN and
 * +-Inf. Reads the bit pattern (memcpy: MISRA deviation D2), so it holds under any
 * floating-point optimisation flags, unlike a comparison. */
static inline int stsp_isfinite_f32(float value)
{
    const uint32_t exp_mask = 0x7F800000u; /* the exponent field */
    uint32_t bits;
    (void)memcpy(&bits, &value, sizeof bits);
    return ((bits & exp_mask) != exp_mask) ? 1 : 0;
}

#endif /* STSP_F32BITS_H */
