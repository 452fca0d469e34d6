/* The Q15 half of the two-arithmetic consumer (q15_robot.h): compiled with STSP_ARITH_Q15, so
 * stospline's names here are the Q15 controller's (stsp_step is stsp_step_q15). */
#include "q15_robot.h"

#include "robot_corridor_q15.h" /* generated; includes stospline/stsp_controller.h */

#define NX ROBOT_CORRIDOR_Q15_NX
#define NU ROBOT_CORRIDOR_Q15_NU

static stsp_ctrl_t q15_controller;
static double q15_x[NX] = {-5.0, 0.0, 1.0, 0.0}; /* x0 of examples/robot_corridor.toml */

int q15_robot_init(void)
{
    static const uint8_t problem_sha256[32] = ROBOT_CORRIDOR_Q15_PROBLEM_SHA256;
    return (int)stsp_init_problem(&q15_controller, &robot_corridor_q15_table, NX, NU,
                                  problem_sha256);
}

uint32_t q15_robot_ticks(void)
{
    return ROBOT_CORRIDOR_Q15_N_TICKS;
}

int q15_robot_tick(uint32_t tick, FILE *out)
{
    const double h = 1.0 / (double)ROBOT_CORRIDOR_Q15_TICK_HZ;
    float x[NX];
    stsp_q15_t x_q[NX];
    stsp_q15_t u_q[NU] = {0, 0};
    float u[NU] = {0.0f, 0.0f};
    stsp_status_t conversion;
    stsp_status_t status;
    uint32_t j;
    for (j = 0u; j < NX; ++j) {
        x[j] = (float)q15_x[j];
    }
    conversion = stsp_state_to_q(&q15_controller, x, x_q);
    status = stsp_step(&q15_controller, tick, x_q, u_q);
    (void)stsp_command_to_f32(&q15_controller, u_q, u);
    for (j = 0u; j < 2u; ++j) { /* the double integrator of main.c, x = (x, xdot, y, ydot) */
        q15_x[2u * j] += q15_x[2u * j + 1u] * h + 0.5 * (double)u[j] * h * h;
        q15_x[2u * j + 1u] += (double)u[j] * h;
    }
    fprintf(out, "%lu %d %d %d %d %a %a %a %a\n", (unsigned long)tick, (int)conversion,
            (int)status, (int)u_q[0], (int)u_q[1], (double)x[0], (double)x[1], (double)x[2],
            (double)x[3]);
    return (int)status;
}
