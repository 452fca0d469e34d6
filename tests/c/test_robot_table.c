/* The generated robot tables: header macros agree with the table, init verifies it, and the
 * controller steers the noise-free plant (exact zero-order-hold double integrator) to the
 * planned final state. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>

#include <cmocka.h>

#include "robot_corridor.h"

static void test_header_matches_table(void **state)
{
    (void)state;
    assert_int_equal(robot_corridor_table.nx, ROBOT_CORRIDOR_NX);
    assert_int_equal(robot_corridor_table.nu, ROBOT_CORRIDOR_NU);
    assert_int_equal(robot_corridor_table.n_ticks, ROBOT_CORRIDOR_N_TICKS);
    assert_int_equal(robot_corridor_table.tick_hz, ROBOT_CORRIDOR_TICK_HZ);
    assert_int_equal(stsp_table_crc32(&robot_corridor_table), robot_corridor_table.crc32);
}

static void test_noise_free_closed_loop_reaches_goal(void **state)
{
    stsp_ctrl_t c;
    double x[4] = {-5.0, 0.0, 1.0, 0.0};
    const double h = 1.0 / (double)ROBOT_CORRIDOR_TICK_HZ;
    uint32_t tick;
    (void)state;
    assert_int_equal(stsp_init(&c, &robot_corridor_table), STSP_OK);
    for (tick = 0u; tick < ROBOT_CORRIDOR_N_TICKS; ++tick) {
        float xf[4], u[2];
        int i;
        for (i = 0; i < 4; ++i) {
            xf[i] = (float)x[i];
        }
        assert_int_equal(stsp_step(&c, tick, xf, u), STSP_OK);
        /* Exact ZOH step of x'' = u per axis. */
        x[0] += h * x[1] + 0.5 * h * h * u[0];
        x[1] += h * u[0];
        x[2] += h * x[3] + 0.5 * h * h * u[1];
        x[3] += h * u[1];
        if (tick + 1u == 3000u) {
            assert_true(fabs(x[0] + x[2]) < 1e-5); /* E{x + y} = 0 at t = 3 */
        }
    }
    /* Final constraint E{X(6)} = (-1, 0, 5, 0). The tables are the exact zero-order-hold
     * design, so without noise only float32 rounding remains (measured: about 1e-7). */
    assert_true(fabs(x[0] + 1.0) < 1e-5);
    assert_true(fabs(x[1]) < 1e-5);
    assert_true(fabs(x[2] - 5.0) < 1e-5);
    assert_true(fabs(x[3]) < 1e-5);
    {
        float u[2];
        const float xf[4] = {0.0f, 0.0f, 0.0f, 0.0f};
        assert_int_equal(stsp_step(&c, ROBOT_CORRIDOR_N_TICKS, xf, u), STSP_ERR_TICK_RANGE);
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_header_matches_table),
        cmocka_unit_test(test_noise_free_closed_loop_reaches_goal),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
