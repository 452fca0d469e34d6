/* A program that links the controller but not the band solver (nothing here refers to
 * stsp_bandqp_solve or stsp_bandqp_solve_f32, and the link adds no --undefined for them): the
 * controller's weak reference stays unresolved, stsp_init() refuses a table with a band dual
 * (STSP_ERR_BAD_DIMS) and accepts the same table without one. Built for the generic and the
 * 2/1/2 controllers (the table is 2 states, 1 input, 2 multipliers). Exit status 0 on success. */
#include <stdio.h>

#include "stospline/stsp_controller.h"

/* Weak here too, so that this check does not link the solver itself. */
extern stsp_bandqp_status_t stsp_bandqp_solve_f32(const stsp_bandqp_t *qp, const float *x0,
                                                  float *v) __attribute__((weak));

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
static const double Nt[2] = {1.0, 0.0};
static const double mt[1] = {0.0};
static const double W[1] = {1.0};
static const double lo[1] = {-1.0};
static const double hi[1] = {1.0};
static const stsp_bandqp_t band = {1u, 2u, Nt, mt, W, lo, hi, NULL};

static stsp_table_t table_with(const stsp_bandqp_t *b)
{
    stsp_table_t t = {STSP_TABLE_MAGIC, STSP_FORMAT_VERSION, STSP_SCALAR_KIND, 2u, 1u, 2u, 1u,
                      4u, 100u, stage_start, stage_n_latch, K, k0, L, Lambda, lambda0,
                      u_min, u_max, u_hold, b, NULL, 0u, {0u}};
    t.crc32 = stsp_table_crc32(&t);
    return t;
}

int main(void)
{
    const stsp_table_t with_band = table_with(&band);
    const stsp_table_t without_band = table_with(NULL);
    const float x[2] = {1.0f, 2.0f};
    float u[1] = {0.0f};
    stsp_ctrl_t c;
    stsp_status_t st;
    int failures = 0;
    if (&stsp_bandqp_solve_f32 != NULL) {
        printf("FAIL: the band solver is linked into a program without a band table\n");
        ++failures;
    }
    st = stsp_init(&c, &with_band);
    if (st != STSP_ERR_BAD_DIMS) {
        printf("FAIL: init of a band table without the solver returned %d, not %d\n", (int)st,
               (int)STSP_ERR_BAD_DIMS);
        ++failures;
    }
    st = stsp_step(&c, 0u, x, u);
    if (st != STSP_ERR_NOT_INITIALIZED) {
        printf("FAIL: step after the refused init returned %d\n", (int)st);
        ++failures;
    }
    st = stsp_init(&c, &without_band);
    if (st != STSP_OK) {
        printf("FAIL: init of the table without a band dual returned %d\n", (int)st);
        ++failures;
    }
    st = stsp_step(&c, 0u, x, u);
    /* u = -(K x + k0 + L v), v = Lambda x + lambda0 = 0.75: -(1 + 1 + 0.75) */
    if ((st != STSP_OK) || (u[0] != -2.75f)) {
        printf("FAIL: step of the table without a band dual: status %d, u %g\n", (int)st,
               (double)u[0]);
        ++failures;
    }
    if (failures == 0) {
        printf("no band solver linked: band table refused, table without one works\n");
    }
    return (failures == 0) ? 0 : 1;
}
