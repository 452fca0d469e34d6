/* The robot's position-sensor tables of the build's arithmetic, for the estimator's C tests,
 * its fuzz target and its M4F bench (tools/arm/estimator_bench_main.c): the float32 tables
 * (gains/robot_position_sensor.*) or, with STSP_ARITH_Q15, the Q15 ones
 * (gains/robot_position_sensor_q15.*), with STSP_ARITH_Q31 the Q31 ones
 * (gains/robot_position_sensor_q31.*), or with STSP_EST_SPLINE the spline ones
 * (gains/robot_position_sensor_spline.*: EST_GAIN_SPLINE the filter's gain spline), under one
 * set of names; and the FNV-1a word hash the expected-value headers use. */
#ifndef ESTIMATOR_TABLES_H
#define ESTIMATOR_TABLES_H

#include <stdint.h>

#ifdef STSP_ARITH_Q15
#include "robot_position_sensor_q15.h"
#define SENSOR(x) ROBOT_POSITION_SENSOR_Q15_##x
#define TABLE robot_position_sensor_q15_table
#define ESTIMATOR robot_position_sensor_q15_estimator
#elif defined(STSP_ARITH_Q31)
#include "robot_position_sensor_q31.h"
#define SENSOR(x) ROBOT_POSITION_SENSOR_Q31_##x
#define TABLE robot_position_sensor_q31_table
#define ESTIMATOR robot_position_sensor_q31_estimator
#elif defined(STSP_EST_SPLINE)
#include "robot_position_sensor_spline.h"
#define SENSOR(x) ROBOT_POSITION_SENSOR_SPLINE_##x
#define TABLE robot_position_sensor_spline_table
#define ESTIMATOR robot_position_sensor_spline_estimator
#define EST_GAIN_SPLINE robot_position_sensor_spline_est_gain_spline
#else
#include "robot_position_sensor.h"
#define SENSOR(x) ROBOT_POSITION_SENSOR_##x
#define TABLE robot_position_sensor_table
#define ESTIMATOR robot_position_sensor_estimator
#endif

/* FNV-1a over a 32-bit word, byte by byte, little-endian (a Q value as its two's complement). */
static inline uint32_t est_fnv1a(uint32_t h, uint32_t w)
{
    uint32_t i;
    for (i = 0u; i < 4u; ++i) {
        h = (h ^ ((w >> (8u * i)) & 0xFFu)) * 0x01000193u;
    }
    return h;
}

#endif /* ESTIMATOR_TABLES_H */
