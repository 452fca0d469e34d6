/* Table A's shape, shared by test_controller.c (float32 gains) and test_fixedpoint.c (the
 * same table in Q15/Q31): nx = 2, nu = 1, n_latch = 2; stage 0 = ticks 0..2 (one multiplier),
 * stage 1 = ticks 3..4 (two). */
#ifndef TABLE_A_H
#define TABLE_A_H

#include <stdint.h>

#define NX 2u
#define NU 1u
#define N_LATCH 2u
#define NT 5u
#define NS 2u

static const uint32_t stage_start[NS + 1u] = {0u, 3u, 5u};
static const uint16_t stage_n_latch[NS] = {1u, 2u};

#endif /* TABLE_A_H */
