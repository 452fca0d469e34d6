/* The generated band table (examples/robot_bands.toml, joint design at 100 Hz): the controller
 * re-solves the band dual from the measured start state at the t0 latch. Without noise the
 * closed loop follows the expected path exactly (the mean obeys the noise-free dynamics,
 * because the law is affine and the noise has zero mean), so the state at t = 3 is E{X(3)}.
 * From the design's start and from a moved one the bands hold; the same table with the band
 * dual removed (the design's affine latch map) misses E{y} <= 1.5 from the moved start. Built
 * against the generic controller and the one fixed to the table's shape, each also under ASan
 * + UBSan; with ROBOT_BANDS_SPLINE defined, the same tests on the spline table
 * (gains/robot_bands_spline.*). */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>

#include <cmocka.h>

#ifdef ROBOT_BANDS_SPLINE
/* The spline table of the same design (gains/robot_bands_spline.*): its band dual re-solved for
 * the spline's gains (W non-symmetric, the solver's Gaussian-elimination path), the same plan. */
#include "robot_bands_spline.h"
#define robot_bands_table robot_bands_spline_table
#define ROBOT_BANDS_TICK_HZ ROBOT_BANDS_SPLINE_TICK_HZ
#define ROBOT_BANDS_N_TICKS ROBOT_BANDS_SPLINE_N_TICKS
#define ROBOT_BANDS_BAND_ROWS ROBOT_BANDS_SPLINE_BAND_ROWS
#define ROBOT_BANDS_N_LATCH ROBOT_BANDS_SPLINE_N_LATCH
#else
#include "robot_bands.h"
#endif

/* Noise-free closed loop from x0 (exact ZOH of x'' = u per axis) over the whole plan; returns
 * the state at the first knot (t = 3) in at3 and the final state in x. */
static void run(const stsp_table_t *t, const double x0[4], double at3[4], double x[4],
                stsp_status_t first_status)
{
    const double h = 1.0 / (double)ROBOT_BANDS_TICK_HZ;
    const uint32_t knot = 3u * ROBOT_BANDS_TICK_HZ;
    stsp_ctrl_t c;
    uint32_t tick;
    int i;
    assert_int_equal(stsp_init_expect(&c, t, 4u, 2u), STSP_OK);
    for (i = 0; i < 4; ++i) {
        x[i] = x0[i];
    }
    for (tick = 0u; tick < ROBOT_BANDS_N_TICKS; ++tick) {
        float xf[4], u[2];
        for (i = 0; i < 4; ++i) {
            xf[i] = (float)x[i];
        }
        assert_int_equal(stsp_step(&c, tick, xf, u), (tick == 0u) ? first_status : STSP_OK);
        x[0] += h * x[1] + 0.5 * h * h * u[0];
        x[1] += h * u[0];
        x[2] += h * x[3] + 0.5 * h * h * u[1];
        x[3] += h * u[1];
        if (tick + 1u == knot) {
            for (i = 0; i < 4; ++i) {
                at3[i] = x[i];
            }
        }
    }
}

/* Bands -0.1 <= x + y <= 0.1 and 0.5 <= y <= 1.5 at t = 3, the goal (-1, 0, 5, 0) at t = 6;
 * float32 tables: 1e-4 slack. */
static void assert_plan_met(const double at3[4], const double x[4])
{
    const double tol = 1e-4;
    assert_true(at3[0] + at3[2] >= -0.1 - tol && at3[0] + at3[2] <= 0.1 + tol);
    assert_true(at3[2] >= 0.5 - tol && at3[2] <= 1.5 + tol);
    assert_true(fabs(x[0] + 1.0) < tol && fabs(x[1]) < tol);
    assert_true(fabs(x[2] - 5.0) < tol && fabs(x[3]) < tol);
}

static void test_header_and_band_dual(void **state)
{
    (void)state;
    assert_int_equal(robot_bands_table.format_version, STSP_FORMAT_VERSION);
    assert_non_null(robot_bands_table.band_qp);
    assert_int_equal(robot_bands_table.band_qp->q, ROBOT_BANDS_BAND_ROWS);
    assert_int_equal(robot_bands_table.stage_n_latch[0], ROBOT_BANDS_BAND_ROWS);
    assert_int_equal(robot_bands_table.n_latch, ROBOT_BANDS_N_LATCH);
    assert_int_equal(stsp_table_crc32(&robot_bands_table), robot_bands_table.crc32);
#ifdef ROBOT_BANDS_SPLINE
    {
        /* A spline table, and its W is not symmetric (what the host re-solved). */
        const stsp_bandqp_t *b = robot_bands_table.band_qp;
        uint32_t i, j, asym = 0u;
        assert_non_null(robot_bands_table.spline);
        assert_null(robot_bands_table.K);
        for (i = 0u; i < b->q; ++i) {
            for (j = 0u; j < b->q; ++j) {
                asym += (b->W[i * b->q + j] != b->W[j * b->q + i]) ? 1u : 0u;
            }
        }
        assert_true(asym > 0u);
    }
#endif
}

static void test_design_start_meets_bands(void **state)
{
    const double x0[4] = {-5.0, 0.0, 1.0, 0.0};
    double at3[4], x[4];
    (void)state;
    run(&robot_bands_table, x0, at3, x, STSP_OK);
    assert_plan_met(at3, x);
    /* At the design's start the bound x + y >= -0.1 is active (the summary's active set). */
    assert_true(fabs(at3[0] + at3[2] + 0.1) < 1e-4);
}

static void test_moved_start_is_replanned(void **state)
{
    const double x0[4] = {-5.4, 0.1, 2.0, 0.4};
    stsp_table_t affine = robot_bands_table;
    double at3[4], x[4];
    (void)state;
    run(&robot_bands_table, x0, at3, x, STSP_OK);
    assert_plan_met(at3, x);
    assert_true(fabs(at3[2] - 1.5) < 1e-4); /* y now at its upper bound */
    /* Without the dual the latch is the design's affine map: y ends 0.07 above the band. */
    affine.band_qp = NULL;
    affine.crc32 = stsp_table_crc32(&affine);
    run(&affine, x0, at3, x, STSP_OK);
    assert_true(at3[2] > 1.5 + 0.05);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_header_and_band_dual),
        cmocka_unit_test(test_design_start_meets_bands),
        cmocka_unit_test(test_moved_start_is_replanned),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
