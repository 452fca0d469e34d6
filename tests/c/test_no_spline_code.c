/* A program that links the controller but not the spline code (nothing here refers to
 * stsp_spline_code, and the link adds no --undefined for it): the controller's weak references
 * to stsp_spline.c stay unresolved, stsp_init() refuses a spline table (STSP_ERR_BAD_DIMS,
 * after the checks of the header's own dimensions and arrays) and accepts a per-tick table.
 * Built for the generic and the 2/1/2 controllers (2 states, 1 input, 2 multipliers). Exit
 * status 0 on success. */
#include <stdio.h>

#include "stospline/stsp_controller.h"

/* Weak here too, so that this check does not link the spline code itself. */
extern const uint32_t stsp_spline_code __attribute__((weak));

static const uint32_t stage_start[2] = {0u, 4u};
static const uint16_t stage_n_latch[1] = {1u};
static const float K[8] = {1.0f, 0.5f, 1.0f, 0.5f, 1.0f, 0.5f, 1.0f, 0.5f};
static const float k0[4] = {0.0f, 0.0f, 0.0f, 0.0f};
static const float L[8] = {1.0f, 0.0f, 1.0f, 0.0f, 1.0f, 0.0f, 1.0f, 0.0f};
static const float Lambda[2] = {0.25f, 0.0f};
static const float lambda0[2] = {0.5f, 0.0f};
static const float u_min[1] = {-3.4028235e+38f};
static const float u_max[1] = {3.4028235e+38f};
static const float u_hold[1] = {0.0f};
/* The same gains as one cubic span: K00 = 1, K01 = 0.5, L00 = 1 (constant splines). */
static const uint32_t knot_start[2] = {0u, 8u};
static const float knot[8] = {0.0f, 0.0f, 0.0f, 0.0f, 4.0f, 4.0f, 4.0f, 4.0f};
static const uint16_t row_start[2] = {0u, 3u};
static const uint8_t col[3] = {0u, 1u, 3u};
static const uint32_t coef_start[2] = {0u, 12u};
static const float coef[12] = {1.0f, 1.0f, 1.0f, 1.0f, 0.5f, 0.5f,
                               0.5f, 0.5f, 1.0f, 1.0f, 1.0f, 1.0f};
static const stsp_spline_t spline = {8u, 3u, 12u, knot_start, knot, row_start,
                                     col, coef_start, coef, NULL};

static stsp_table_t table_with(const stsp_spline_t *sp)
{
    stsp_table_t t = {STSP_TABLE_MAGIC, STSP_FORMAT_VERSION, STSP_SCALAR_KIND, 2u, 1u, 2u, 1u,
                      4u, 100u, stage_start, stage_n_latch, K, k0, L, Lambda, lambda0,
                      u_min, u_max, u_hold, NULL, sp, 0u, {0u}};
    if (sp != NULL) {
        t.K = NULL;
        t.k0 = NULL;
        t.L = NULL;
    }
    t.crc32 = stsp_table_crc32(&t);
    return t;
}

int main(void)
{
    const stsp_table_t with_spline = table_with(&spline);
    const stsp_table_t per_tick = table_with(NULL);
    const float x[2] = {1.0f, 2.0f};
    float u[1] = {0.0f};
    stsp_ctrl_t c;
    stsp_status_t st;
    int failures = 0;
    if (&stsp_spline_code != NULL) {
        printf("FAIL: the spline code is linked into a program without a spline table\n");
        ++failures;
    }
    st = stsp_init(&c, &with_spline);
    if (st != STSP_ERR_BAD_DIMS) {
        printf("FAIL: init of a spline table without the spline code returned %d, not %d\n",
               (int)st, (int)STSP_ERR_BAD_DIMS);
        ++failures;
    }
    st = stsp_step(&c, 0u, x, u);
    if (st != STSP_ERR_NOT_INITIALIZED) {
        printf("FAIL: step after the refused init returned %d\n", (int)st);
        ++failures;
    }
    st = stsp_init(&c, &per_tick);
    if (st != STSP_OK) {
        printf("FAIL: init of the per-tick table returned %d\n", (int)st);
        ++failures;
    }
    st = stsp_step(&c, 0u, x, u);
    /* u = -(K x + k0 + L v), v = Lambda x + lambda0 = 0.75: -(1 + 1 + 0.75) */
    if ((st != STSP_OK) || (u[0] != -2.75f)) {
        printf("FAIL: step of the per-tick table: status %d, u %g\n", (int)st, (double)u[0]);
        ++failures;
    }
    if (failures == 0) {
        printf("no spline code linked: spline table refused, per-tick table works\n");
    }
    return (failures == 0) ? 0 : 1;
}
