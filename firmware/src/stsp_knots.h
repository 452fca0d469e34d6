/* The clamped knot vector of a float32 spline, checked at init by the controller's spline
 * tables (stsp_spline.c) and the estimator's gain spline (stsp_estimator.c). Private. */
#ifndef STSP_KNOTS_H
#define STSP_KNOTS_H

#include "stospline/stsp_types.h"

/* 1 when the knots k[0..len) (len >= 8) are a clamped knot vector for `ticks` abscissae
 * (< 2^24, so every integer up to it is a binary32): four 0, then strictly increasing
 * integers in (0, ticks), then four times `ticks`. NaN fails every comparison. */
static inline int stsp_knots_ok(const stsp_f32_t *k, uint32_t len, uint32_t ticks)
{
    const stsp_f32_t end = (stsp_f32_t)ticks;
    uint32_t i;
    for (i = 0u; i < 4u; ++i) {
        if (!(k[i] == 0.0f) || !(k[len - 4u + i] == end)) {
            return 0;
        }
    }
    for (i = 4u; i < (len - 4u); ++i) {
        /* 0 < k[i] < ticks < 2^24 here, so the conversion is defined. */
        if (!(k[i] > k[i - 1u]) || !(k[i] < end) ||
            ((stsp_f32_t)(uint32_t)k[i] != k[i])) {
            return 0;
        }
    }
    return 1;
}

#endif /* STSP_KNOTS_H */
