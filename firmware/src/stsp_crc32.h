/* Private: CRC-32 (IEEE 802.3, reflected polynomial 0xEDB88320, as zlib) over values fed as
 * little-endian bytes, so the result does not depend on the target's byte order. */
#ifndef STSP_CRC32_H
#define STSP_CRC32_H

#include <stdint.h>

#include "stospline/stsp_controller.h"

/* Named per arithmetic (STSP_NAME), as every external symbol of the controller. */
#define stsp_crc32_begin STSP_NAME(stsp_crc32_begin)
#define stsp_crc32_u32 STSP_NAME(stsp_crc32_u32)
#define stsp_crc32_scalars STSP_NAME(stsp_crc32_scalars)
#define stsp_crc32_u32s STSP_NAME(stsp_crc32_u32s)
#define stsp_crc32_f64s STSP_NAME(stsp_crc32_f64s)
#define stsp_crc32_bytes STSP_NAME(stsp_crc32_bytes)
#define stsp_crc32_end STSP_NAME(stsp_crc32_end)

uint32_t stsp_crc32_begin(void);
uint32_t stsp_crc32_u32(uint32_t crc, uint32_t value);
/* Feed `count` table entries of the build's variant (stsp_table_crc32's serialization):
 * binary32 bit patterns, or Q15/Q31 integers as little-endian two's complement. */
uint32_t stsp_crc32_scalars(uint32_t crc, const stsp_scalar_t *values, uint32_t count);
/* Feed `count` u32 values (spline tables). */
uint32_t stsp_crc32_u32s(uint32_t crc, const uint32_t *values, uint32_t count);
#ifndef STSP_ARITH_FIXED_POINT
/* cppcheck-suppress misra-c2012-2.5 ; deviation D7: used by stsp_spline.c's float32 code */
#define stsp_crc32_f32s STSP_NAME(stsp_crc32_f32s)
/* Feed `count` binary32 values by their bit patterns (spline tables). */
uint32_t stsp_crc32_f32s(uint32_t crc, const stsp_f32_t *values, uint32_t count);
#endif
/* Feed `count` binary64 values by their bit patterns (low word first: little-endian bytes). */
uint32_t stsp_crc32_f64s(uint32_t crc, const double *values, uint32_t count);
/* Feed `count` bytes. */
uint32_t stsp_crc32_bytes(uint32_t crc, const uint8_t *values, uint32_t count);
uint32_t stsp_crc32_end(uint32_t crc);
#ifdef STSP_ARITH_FIXED_POINT
#define stsp_crc32_i8s STSP_NAME(stsp_crc32_i8s)
/* Feed `count` signed bytes (the scale exponents) as two's complement. */
uint32_t stsp_crc32_i8s(uint32_t crc, const int8_t *values, uint32_t count);
#endif

#endif /* STSP_CRC32_H */
