/* A float32 and a Q15 controller in one program: this translation unit is float32 (the robot
 * corridor's float32 table, stsp_step is stsp_step_f32), q15_robot.c is Q15 (stsp_step_q15).
 * Both instances step the same ticks, interleaved. The float32 lines go to stdout in main.c's
 * format (compare_harness.py checks them against the cffi harness bit for bit), the Q15 lines
 * to the file argv[1] (run.sh compares them with q15_main.c's, the Q15 controller alone). */
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "q15_robot.h"
#include "robot_corridor.h" /* generated; includes stospline/stsp_controller.h */

#define NX ROBOT_CORRIDOR_NX
#define NU ROBOT_CORRIDOR_NU

static stsp_ctrl_t controller;
static double plant_x[NX] = {-5.0, 0.0, 1.0, 0.0}; /* x0 of examples/robot_corridor.toml */

/* The bits of v, printed as main.c prints them. */
static unsigned long float_bits(float v)
{
    uint32_t bits;
    memcpy(&bits, &v, sizeof bits);
    return (unsigned long)bits;
}

/* One float32 tick of main.c: measure, step, apply (double integrator), print. */
static stsp_status_t f32_tick(uint32_t tick)
{
    const double h = 1.0 / (double)ROBOT_CORRIDOR_TICK_HZ;
    float x[NX];
    float u[NU] = {0.0f, 0.0f};
    stsp_status_t status;
    uint32_t j;
    for (j = 0u; j < NX; ++j) {
        x[j] = (float)plant_x[j];
    }
    status = stsp_step(&controller, tick, x, u);
    for (j = 0u; j < 2u; ++j) {
        plant_x[2u * j] += plant_x[2u * j + 1u] * h + 0.5 * (double)u[j] * h * h;
        plant_x[2u * j + 1u] += (double)u[j] * h;
    }
    printf("%lu %d %08lx %08lx %08lx %08lx %08lx %08lx\n", (unsigned long)tick, (int)status,
           float_bits(x[0]), float_bits(x[1]), float_bits(x[2]), float_bits(x[3]),
           float_bits(u[0]), float_bits(u[1]));
    return status;
}

int main(int argc, char **argv)
{
    static const uint8_t problem_sha256[32] = ROBOT_CORRIDOR_PROBLEM_SHA256;
    FILE *q15_out;
    uint32_t tick;
    int failed = 0;
    if (argc != 2) {
        fprintf(stderr, "usage: robot_two_arith Q15_OUTPUT\n");
        return 2;
    }
    if ((stsp_init_problem(&controller, &robot_corridor_table, NX, NU, problem_sha256) !=
         STSP_OK) ||
        (q15_robot_init() != 0)) {
        fprintf(stderr, "robot_two_arith: init refused a table\n");
        return 1;
    }
    q15_out = fopen(argv[1], "w");
    if (q15_out == NULL) {
        return 1;
    }
    for (tick = 0u; (tick < ROBOT_CORRIDOR_N_TICKS) && (failed == 0); ++tick) {
        failed = (f32_tick(tick) < 0) ? 1 : 0;
        if ((tick < q15_robot_ticks()) && (q15_robot_tick(tick, q15_out) < 0)) {
            failed = 1;
        }
    }
    return ((fclose(q15_out) == 0) && (failed == 0)) ? 0 : 1;
}
