/* The robot example's tables in the build's arithmetic (STSP_ARITH_Q15, STSP_ARITH_Q31 or
 * float32; ROBOT_SPLINE: its spline table in that arithmetic; ROBOT_BANDS_SPLINE: the float32
 * spline table of examples/robot_bands.toml, with its band dual), for the Cortex-M test and
 * bench images:
 * ROBOT_TABLE, ROBOT_NX, ROBOT_NU. */
#ifndef STSP_ROBOT_VARIANT_H
#define STSP_ROBOT_VARIANT_H

#include "stospline/stsp_controller.h"

#if defined(ROBOT_BANDS_SPLINE)
#ifdef STSP_ARITH_FIXED_POINT
#error "ROBOT_BANDS_SPLINE: band tables are float32 only"
#endif
#include "robot_bands_spline.h"
#define ROBOT_TABLE robot_bands_spline_table
#define ROBOT_NX ROBOT_BANDS_SPLINE_NX
#define ROBOT_NU ROBOT_BANDS_SPLINE_NU
#elif defined(ROBOT_SPLINE) && defined(STSP_ARITH_Q15)
#include "robot_corridor_q15_spline.h"
#define ROBOT_TABLE robot_corridor_q15_spline_table
#define ROBOT_NX ROBOT_CORRIDOR_Q15_SPLINE_NX
#define ROBOT_NU ROBOT_CORRIDOR_Q15_SPLINE_NU
#elif defined(ROBOT_SPLINE) && defined(STSP_ARITH_Q31)
#include "robot_corridor_q31_spline.h"
#define ROBOT_TABLE robot_corridor_q31_spline_table
#define ROBOT_NX ROBOT_CORRIDOR_Q31_SPLINE_NX
#define ROBOT_NU ROBOT_CORRIDOR_Q31_SPLINE_NU
#elif defined(ROBOT_SPLINE)
#include "robot_corridor_spline.h"
#define ROBOT_TABLE robot_corridor_spline_table
#define ROBOT_NX ROBOT_CORRIDOR_SPLINE_NX
#define ROBOT_NU ROBOT_CORRIDOR_SPLINE_NU
#elif defined(STSP_ARITH_Q15)
#include "robot_corridor_q15.h"
#define ROBOT_TABLE robot_corridor_q15_table
#define ROBOT_NX ROBOT_CORRIDOR_Q15_NX
#define ROBOT_NU ROBOT_CORRIDOR_Q15_NU
#elif defined(STSP_ARITH_Q31)
#include "robot_corridor_q31.h"
#define ROBOT_TABLE robot_corridor_q31_table
#define ROBOT_NX ROBOT_CORRIDOR_Q31_NX
#define ROBOT_NU ROBOT_CORRIDOR_Q31_NU
#else
#include "robot_corridor.h"
#define ROBOT_TABLE robot_corridor_table
#define ROBOT_NX ROBOT_CORRIDOR_NX
#define ROBOT_NU ROBOT_CORRIDOR_NU
#endif

#endif /* STSP_ROBOT_VARIANT_H */
