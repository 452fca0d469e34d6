/* Table Q of the fixed-point spline tests (tests/c/test_qspline.c: the gains alone,
 * tests/c/test_qspline_ctrl.c: the controller), with its gains at every tick from
 * tests/c/qspline_reference.py (exact rationals, independent of the firmware and the host).
 * Included by each test once (static storage: each test file has its own copy). */
#ifndef QSPLINE_TABLE_Q_H
#define QSPLINE_TABLE_Q_H

#include <stdint.h>

#include "stospline/stsp_controller.h"

/* Table Q: nu = 2, z = [x0, x1, 1, v0] (nz = 4); stage 0: 10 ticks in spans of 4, stage 1:
 * 7 ticks in spans of 1. Must match tests/c/qspline_reference.py. */
#define NU 2u
#define NZ 4u
#define NS 2u
#define N_TICKS 17u
static const uint32_t stage_start[NS + 1u] = {0u, 10u, 17u};
static const uint8_t span_log2[NS] = {2u, 0u};
static uint16_t row_start[(NS * NU) + 1u] = {0u, 2u, 3u, 4u, 6u};
static uint8_t col[6] = {0u, 2u, 3u, 1u, 0u, 3u};
static uint8_t shift[6] = {3u, 1u, 1u, 5u, 30u, 2u};
static uint32_t coef_start[NS + 1u] = {0u, 18u, 48u};
static const stsp_scalar_t coef[48] = {
    100, -200, 300, 32767, -32768, 7,
    5, 5, 5, 5, 5, 5,
    -1, 2, -3, 4, -5, 6,
    1000, 2000, -3000, 4000, -5000, 6000, 7000, 8000, 9000, -10000,
    3, -3, 3, -3, 3, -3, 3, -3, 3, -3,
    -7, 70, -700, 7000, -21000, 21000, 0, 1, -1, 2};

/* .venv/bin/python tests/c/qspline_reference.py */
#define QSPLINE_EXPECTED { \
    {-50, 0, 15, 0, 0, 0, 0, 2}, \
    {48, 0, 15, 0, 0, 0, 0, 1}, \
    {549, 0, 15, 0, 0, 0, 0, -1}, \
    {1819, 0, 15, 0, 0, 0, 0, -3}, \
    {4221, 0, 15, 0, 0, 0, 0, -3}, \
    {7807, 0, 15, 0, 0, 0, 0, -1}, \
    {11368, 0, 15, 0, 0, 0, 0, 1}, \
    {13382, 0, 15, 0, 0, 0, 0, 3}, \
    {12325, 0, 15, 0, 0, 0, 0, 4}, \
    {7311, 0, 15, 0, 0, 0, 0, 2}, \
    {0, 188, 0, 0, 0, 0, 0, -107}, \
    {0, -187, 0, 0, 0, 0, 0, 1068}, \
    {0, 250, 0, 0, 0, 0, 0, 1575}, \
    {0, -312, 0, 0, 0, 0, 0, -14000}, \
    {0, 813, 0, 0, 0, 0, 0, 15750}, \
    {0, 1313, 0, 0, 0, 0, 0, 5250}, \
    {0, 1500, 0, 0, 0, 0, 0, 1}, \
}
#define QSPLINE_EXTREME_Q15 {INT64_C(32766), INT64_C(32765), INT64_C(190), INT64_C(-32768), INT64_C(-32769), INT64_C(32765), INT64_C(0), INT64_C(0), INT64_C(0), INT64_C(0), INT64_C(0), INT64_C(0)}
#define QSPLINE_EXTREME_Q31 {INT64_C(2147483646), INT64_C(2147434558), INT64_C(12582846), INT64_C(-2147434561), INT64_C(-2147483649), INT64_C(2147434558), INT64_C(4), INT64_C(4), INT64_C(0), INT64_C(-4), INT64_C(-4), INT64_C(4)}

static inline stsp_qspline_t table_q(void)
{
    stsp_qspline_t q;
    q.n_entries = 6u;
    q.n_coef = 48u;
    q.span_log2 = span_log2;
    q.row_start = row_start;
    q.col = col;
    q.shift = shift;
    q.coef_start = coef_start;
    q.coef = coef;
    q.ops = &stsp_spline_ops;
    return q;
}

#endif /* QSPLINE_TABLE_Q_H */
