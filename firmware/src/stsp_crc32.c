/* CRC-32 with a 16-entry nibble table: 64 bytes of flash, two lookups per byte. */
#include "stsp_crc32.h"

#include <string.h>

static inline uint32_t stsp_crc32_byte(uint32_t crc, uint32_t byte)
{
    static const uint32_t stsp_crc_nibble[16] = {
        0x00000000u, 0x1DB71064u, 0x3B6E20C8u, 0x26D930ACu, 0x76DC4190u, 0x6B6B51F4u,
        0x4DB26158u, 0x5005713Cu, 0xEDB88320u, 0xF00F9344u, 0xD6D6A3E8u, 0xCB61B38Cu,
        0x9B64C2B0u, 0x86D3D2D4u, 0xA00AE278u, 0xBDBDF21Cu};
    uint32_t c = crc ^ (byte & 0xFFu);
    c = (c >> 4) ^ stsp_crc_nibble[c & 0x0Fu];
    c = (c >> 4) ^ stsp_crc_nibble[c & 0x0Fu];
    return c;
}

uint32_t stsp_crc32_begin(void)
{
    return 0xFFFFFFFFu;
}

uint32_t stsp_crc32_u32(uint32_t crc, uint32_t value)
{
    uint32_t c = stsp_crc32_byte(crc, value);
    c = stsp_crc32_byte(c, value >> 8);
    c = stsp_crc32_byte(c, value >> 16);
    return stsp_crc32_byte(c, value >> 24);
}

/* One table entry of the build's variant, little-endian: the binary32 bit pattern, or the
 * Q15/Q31 integer's two's complement (2 or 4 bytes). */
static inline uint32_t stsp_crc32_scalar(uint32_t crc, stsp_scalar_t value)
{
#if defined(STSP_ARITH_Q15)
    const uint32_t bits = (uint32_t)(uint16_t)value;
    return stsp_crc32_byte(stsp_crc32_byte(crc, bits), bits >> 8);
#elif defined(STSP_ARITH_Q31)
    return stsp_crc32_u32(crc, (uint32_t)value);
#else
    uint32_t bits;
    (void)memcpy(&bits, &value, sizeof bits);
    return stsp_crc32_u32(crc, bits);
#endif
}

uint32_t stsp_crc32_scalars(uint32_t crc, const stsp_scalar_t *values, uint32_t count)
{
    uint32_t c = crc;
    uint32_t i;
    for (i = 0u; i < count; ++i) {
        c = stsp_crc32_scalar(c, values[i]);
    }
    return c;
}

uint32_t stsp_crc32_u32s(uint32_t crc, const uint32_t *values, uint32_t count)
{
    uint32_t c = crc;
    uint32_t i;
    for (i = 0u; i < count; ++i) {
        c = stsp_crc32_u32(c, values[i]);
    }
    return c;
}

#ifndef STSP_ARITH_FIXED_POINT

uint32_t stsp_crc32_f32s(uint32_t crc, const stsp_f32_t *values, uint32_t count)
{
    uint32_t c = crc;
    uint32_t i;
    for (i = 0u; i < count; ++i) {
        uint32_t bits;
        (void)memcpy(&bits, &values[i], sizeof bits);
        c = stsp_crc32_u32(c, bits);
    }
    return c;
}
#endif

uint32_t stsp_crc32_bytes(uint32_t crc, const uint8_t *values, uint32_t count)
{
    uint32_t c = crc;
    uint32_t i;
    for (i = 0u; i < count; ++i) {
        c = stsp_crc32_byte(c, (uint32_t)values[i]);
    }
    return c;
}

uint32_t stsp_crc32_f64s(uint32_t crc, const double *values, uint32_t count)
{
    uint32_t c = crc;
    uint32_t i;
    for (i = 0u; i < count; ++i) {
        uint64_t bits;
        (void)memcpy(&bits, &values[i], sizeof bits);
        c = stsp_crc32_u32(c, (uint32_t)(bits & 0xFFFFFFFFu));
        c = stsp_crc32_u32(c, (uint32_t)(bits >> 32));
    }
    return c;
}

#ifdef STSP_ARITH_FIXED_POINT
uint32_t stsp_crc32_i8s(uint32_t crc, const int8_t *values, uint32_t count)
{
    uint32_t c = crc;
    uint32_t i;
    for (i = 0u; i < count; ++i) {
        c = stsp_crc32_byte(c, (uint32_t)(uint8_t)values[i]);
    }
    return c;
}
#endif

uint32_t stsp_crc32_end(uint32_t crc)
{
    return crc ^ 0xFFFFFFFFu;
}
