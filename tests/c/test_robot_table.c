/* The generated robot tables: header macros agree with the table, init verifies it, and the
 * controller steers the noise-free plant (exact zero-order-hold double integrator) to the
 * planned final state. Built against the generic controller and against the one compiled for
 * the robot's dimensions (STSP_FIXED_NX/NU/N_LATCH = 4/2/4), each also under ASan + UBSan. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "robot_corridor.h"

static void test_header_matches_table(void **state)
{
    (void)state;
    assert_int_equal(robot_corridor_table.format_version, STSP_FORMAT_VERSION);
    assert_int_equal(robot_corridor_table.nx, ROBOT_CORRIDOR_NX);
    assert_int_equal(robot_corridor_table.nu, ROBOT_CORRIDOR_NU);
    assert_int_equal(robot_corridor_table.n_ticks, ROBOT_CORRIDOR_N_TICKS);
    assert_int_equal(robot_corridor_table.tick_hz, ROBOT_CORRIDOR_TICK_HZ);
    assert_int_equal(stsp_table_crc32(&robot_corridor_table), robot_corridor_table.crc32);
}

/* The table carries the problem file's SHA-256; an application built for that problem refuses
 * tables from another one, and the CRC covers the stored hash. */
static void test_init_problem_checks_the_hash(void **state)
{
    static const uint8_t want[32] = ROBOT_CORRIDOR_PROBLEM_SHA256;
    uint8_t other[32];
    stsp_table_t copy = robot_corridor_table;
    stsp_ctrl_t c;
    float x[4] = {-5.0f, 0.0f, 1.0f, 0.0f}, u[2];
    (void)state;
    assert_int_equal(stsp_init_problem(&c, &robot_corridor_table, 4u, 2u, want), STSP_OK);
    assert_int_equal(stsp_step(&c, 0u, x, u), STSP_OK);
    memcpy(other, want, sizeof other);
    other[31] ^= 1u;
    assert_int_equal(stsp_init_problem(&c, &robot_corridor_table, 4u, 2u, other),
                     STSP_ERR_BAD_PROBLEM);
    assert_int_equal(stsp_step(&c, 0u, x, u), STSP_ERR_NOT_INITIALIZED);
    assert_int_equal(stsp_init_problem(&c, &robot_corridor_table, 4u, 2u, NULL), STSP_ERR_NULL);
    assert_int_equal(stsp_init_problem(&c, &robot_corridor_table, 4u, 3u, want),
                     STSP_ERR_BAD_DIMS);
    copy.problem_sha256[0] ^= 0x80u; /* a flipped bit in the stored hash */
    assert_int_equal(stsp_init_problem(&c, &copy, 4u, 2u, want), STSP_ERR_BAD_CRC);
}

static void test_noise_free_closed_loop_reaches_goal(void **state)
{
    stsp_ctrl_t c;
    double x[4] = {-5.0, 0.0, 1.0, 0.0};
    const double h = 1.0 / (double)ROBOT_CORRIDOR_TICK_HZ;
    uint32_t tick;
    (void)state;
    assert_int_equal(stsp_init_expect(&c, &robot_corridor_table, 4u, 2u), STSP_OK);
    assert_int_equal(stsp_verify(&c), STSP_OK);
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
        float u[2] = {1.0f, 1.0f};
        const float xf[4] = {0.0f, 0.0f, 0.0f, 0.0f};
        assert_int_equal(stsp_step(&c, ROBOT_CORRIDOR_N_TICKS, xf, u), STSP_ERR_TICK_RANGE);
        assert_true(u[0] == 0.0f && u[1] == 0.0f);
    }
}

/* The same table with actuator limits (a RAM copy of the header with its CRC recomputed):
 * commands are clamped, the status says so, and the plan still runs to its end. */
static void test_limited_copy_saturates(void **state)
{
    static const float lo[2] = {-1.0f, -1.0f}, hi[2] = {1.0f, 1.0f};
    stsp_table_t t = robot_corridor_table;
    stsp_ctrl_t c;
    const float xf[4] = {-5.0f, 0.0f, 1.0f, 0.0f};
    float u[2];
    uint32_t tick, saturated = 0u;
    (void)state;
    t.u_min = lo;
    t.u_max = hi;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_CRC);
    t.crc32 = stsp_table_crc32(&t);
    assert_int_equal(stsp_init(&c, &t), STSP_OK);
    for (tick = 0u; tick < ROBOT_CORRIDOR_N_TICKS; ++tick) {
        const stsp_status_t st = stsp_step(&c, tick, xf, u);
        assert_true(st == STSP_OK || st == STSP_WARN_SATURATED);
        assert_true(u[0] >= -1.0f && u[0] <= 1.0f && u[1] >= -1.0f && u[1] <= 1.0f);
        if (st == STSP_WARN_SATURATED) {
            assert_true(c.sat_mask != 0u && c.sat_mask < 4u);
            ++saturated;
        }
    }
    assert_true(saturated > 0u);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_header_matches_table),
        cmocka_unit_test(test_init_problem_checks_the_hash),
        cmocka_unit_test(test_noise_free_closed_loop_reaches_goal),
        cmocka_unit_test(test_limited_copy_saturates),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
