/* The Q15 half of the two-arithmetic consumer (two_arith.c, q15_main.c): the robot corridor's
 * Q15 table on the Q15 controller. No stospline type in this interface, so that the float32
 * translation units that call it include no Q15 header and need no Q15 definition. */
#ifndef Q15_ROBOT_H
#define Q15_ROBOT_H

#include <stdint.h>
#include <stdio.h>

/* Binds the Q15 table (stsp_init_problem); returns its status (0: ok). */
int q15_robot_init(void);

/* Ticks in the Q15 table's plan. */
uint32_t q15_robot_ticks(void);

/* One tick of the noise-free robot under the Q15 controller; writes one line to out: tick,
 * the status of the state conversion and of stsp_step, the Q15 command, the state (hex floats).
 * Returns the step's status. */
int q15_robot_tick(uint32_t tick, FILE *out);

#endif /* Q15_ROBOT_H */
