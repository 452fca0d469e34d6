/* The band table (format 3): the t0 latch re-solves the band dual from the measured state
 * (stsp_bandqp_solve), falls back to the design's affine map when it has no optimal active set,
 * and init checks the band dual; the solver's candidate bound. Table D: nx = 2, nu = 1,
 * n_latch = 2, the shape of the controller_fixed_2_1_2 builds. */
#include <float.h>
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "stospline/stsp_bandqp.h"
#include "stospline/stsp_controller.h"
#include "test_support.h"

static const float no_min[1] = {-FLT_MAX}, no_max[1] = {FLT_MAX}, zero_hold[1] = {0.0f};

/* Table D: a joint band table, nx = 2, nu = 1, n_latch = 2; stage 0 = ticks 0..1 latches both
 * multipliers through the band dual, stage 1 = ticks 2..3 keeps them. Dual: e = x0, W =
 * [[2, 0.5], [0.5, 1]], row 0 an equality (0.5), row 1 a band [-1, 1]. Solutions by hand:
 * x0 = (1.5, 0.25): row 1 inactive, lam = ((1.5 - 0.5) / 2, 0) = (0.5, 0);
 * x0 = (0.5, 3):    row 1 at its upper bound, W lam = (0, 2): lam = (-1, 4) / 1.75. */
static const uint32_t d_start[3] = {0u, 2u, 4u};
static const uint16_t d_stage_n_latch[2] = {2u, 0u};
static const float d_K[4 * 2] = {0.25f, 0.25f, 0.25f, 0.25f, 0.25f, 0.25f, 0.25f, 0.25f};
static const float d_k0[4] = {0.0f, 0.0f, 0.0f, 0.0f};
static const float d_L[4 * 2] = {1.0f, 10.0f, 1.0f, 10.0f, 1.0f, 10.0f, 1.0f, 10.0f};
static const float d_Lambda[2 * 2 * 2] = {1.0f, 0.0f, 0.0f, 1.0f, 0.0f, 0.0f, 0.0f, 0.0f};
static const float d_lambda0[2 * 2] = {0.125f, -0.25f, 0.0f, 0.0f};
static const double d_Nt[2 * 2] = {1.0, 0.0, 0.0, 1.0};
static const double d_mt[2] = {0.0, 0.0};
static const double d_W[2 * 2] = {2.0, 0.5, 0.5, 1.0};
static const double d_lo[2] = {0.5, -1.0};
static const double d_hi[2] = {0.5, 1.0};
/* CRC-32 of table D as host/stospline/table/format.py table_crc32 computes it
 * (tests/python/firmware/test_band_relatch.py builds the same table). */
#define TABLE_D_CRC32 0x7395DA83u

static stsp_table_t make_table_d(const stsp_bandqp_t *qp)
{
    stsp_table_t t = table_header(2u, 1u, 2u, 2u, 4u, 1u);
    t.stage_start = d_start; t.stage_n_latch = d_stage_n_latch;
    t.K = d_K; t.k0 = d_k0; t.L = d_L; t.Lambda = d_Lambda; t.lambda0 = d_lambda0;
    t.u_min = no_min; t.u_max = no_max; t.u_hold = zero_hold;
    t.band_qp = qp;
    t.crc32 = stsp_table_crc32(&t);
    return t;
}

static stsp_bandqp_t make_band_d(void)
{
    stsp_bandqp_t b = {2u, 2u, d_Nt, d_mt, d_W, d_lo, d_hi, stsp_bandqp_solve_f32};
    return b;
}

static void test_band_latch_solves_the_dual(void **state)
{
    const stsp_bandqp_t qp = make_band_d();
    const stsp_table_t t = make_table_d(&qp);
    const float inside[2] = {1.5f, 0.25f}, upper[2] = {0.5f, 3.0f}, later[2] = {9.0f, -9.0f};
    stsp_ctrl_t c;
    float u[1];
    uint32_t tick;
    (void)state;
    assert_int_equal(t.crc32, TABLE_D_CRC32);
    assert_int_equal(stsp_init(&c, &t), STSP_OK);

    assert_int_equal(stsp_step(&c, 0u, inside, u), STSP_OK);
    assert_true(fabs(c.v[0] - 0.5) < 1e-7 && c.v[1] == 0.0f);
    assert_true(fabs(u[0] - (-(0.25 * (1.5 + 0.25)) - 0.5)) < 1e-6);

    assert_int_equal(stsp_reset(&c), STSP_OK);
    assert_int_equal(stsp_step(&c, 0u, upper, u), STSP_OK);
    assert_true(c.v[0] == (float)(-1.0 / 1.75));
    assert_true(c.v[1] == (float)(4.0 / 1.75));
    /* The multipliers stay for the rest of the plan: stage 1 (stage_n_latch 0) does not relatch. */
    for (tick = 1u; tick < 4u; ++tick) {
        assert_int_equal(stsp_step(&c, tick, later, u), STSP_OK);
        assert_true(fabs(u[0] - (-(0.25 * 0.0) - (-1.0 / 1.75) - 10.0 * (4.0 / 1.75))) < 1e-5);
    }
}

static void test_band_fallback_and_nonfinite(void **state)
{
    static const double not_pd[2 * 2] = {-1.0, 0.0, 0.0, -1.0};
    static const double tiny[2 * 2] = {1e-300, 0.0, 0.0, 1e-300};
    static const double huge[2 * 2] = {1e300, 0.0, 0.0, 1e300};
    const float far[2] = {0.0f, 1e30f};
    stsp_bandqp_t qp = make_band_d();
    stsp_table_t t;
    stsp_ctrl_t c;
    const float x[2] = {0.5f, 3.0f}, bad[2] = {NAN, 0.0f};
    float u[1] = {1.0f};
    (void)state;
    qp.W = not_pd; /* no active set meets the conditions: latch the design's affine map */
    t = make_table_d(&qp);
    assert_int_equal(stsp_init(&c, &t), STSP_OK);
    assert_int_equal(stsp_step(&c, 0u, x, u), STSP_WARN_BAND_FALLBACK);
    assert_true(c.v[0] == 0.5f + 0.125f);
    assert_true(c.v[1] == 3.0f - 0.25f);
    assert_true(fabs(u[0] - (-(0.25 * 3.5) - 0.625 - 10.0 * 2.75)) < 1e-5);

    /* Multipliers beyond FLT_MAX (W = 1e-300 I: lam_0 = 1e300) have no float value. */
    qp = make_band_d();
    qp.W = tiny;
    t = make_table_d(&qp);
    assert_int_equal(stsp_init(&c, &t), STSP_OK);
    assert_int_equal(stsp_step(&c, 0u, x, u), STSP_WARN_BAND_FALLBACK);
    assert_true(c.v[0] == 0.5f + 0.125f);
    /* Nt x0 overflows a double although both are finite: nothing to solve. */
    qp = make_band_d();
    qp.Nt = huge;
    t = make_table_d(&qp);
    assert_int_equal(stsp_init(&c, &t), STSP_OK);
    assert_int_equal(stsp_step(&c, 0u, far, u), STSP_WARN_BAND_FALLBACK);
    assert_true(c.v[1] == 1e30f - 0.25f);

    qp = make_band_d();
    t = make_table_d(&qp);
    assert_int_equal(stsp_init(&c, &t), STSP_OK);
    assert_int_equal(stsp_step(&c, 0u, bad, u), STSP_ERR_NONFINITE_STATE);
    assert_true(u[0] == 0.0f && c.latched == 0u);
}

static void test_band_tables_are_checked(void **state)
{
    static const double nan_W[2 * 2] = {2.0, 0.5, 0.5, NAN};
    static const double swapped_lo[2] = {0.5, 2.0};
    /* Ordered bands whose magnitudes are not (|lo| > |hi|), and signed zeros: accepted. */
    static const double wide_lo[2] = {-0.0, -2.0};
    static const double wide_hi[2] = {0.0, -1.5};
    static const double W_changed[2 * 2] = {2.0, 0.5, 0.5, 1.0000000000000002};
    static const uint16_t np_later[2] = {2u, 1u};
    static const uint16_t np_one[2] = {1u, 0u};
    const stsp_bandqp_t good = make_band_d();
    stsp_bandqp_t qp;
    stsp_table_t t;
    stsp_ctrl_t c;
    (void)state;

    qp = good; qp.W = NULL; t = make_table_d(&good); t.band_qp = &qp;
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_NULL);
    qp = good; qp.q = 1u; t = make_table_d(&qp);           /* q != stage_n_latch[0] */
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_DIMS);
    qp = good; qp.nx = 3u; t = make_table_d(&qp);          /* another state size */
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_DIMS);
    qp = good; qp.q = (uint16_t)(STSP_BANDQP_MAX + 1u); t = make_table_d(&qp);
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_DIMS);
    qp = good; t = make_table_d(&qp); t.stage_n_latch = np_later; /* a second latch */
    t.crc32 = stsp_table_crc32(&t);
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_DIMS);
    qp = good; t = make_table_d(&qp); t.stage_n_latch = np_one;
    t.crc32 = stsp_table_crc32(&t);
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_DIMS);
    qp = good; qp.W = nan_W; t = make_table_d(&qp);
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_VALUES);
    qp = good; qp.lo = swapped_lo; t = make_table_d(&qp);  /* lo > hi on row 1 */
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_VALUES);
    qp = good; qp.lo = wide_lo; qp.hi = wide_hi; t = make_table_d(&qp);
    assert_int_equal(stsp_init(&c, &t), STSP_OK);
    qp = good; qp.lo = wide_hi; qp.hi = wide_lo; t = make_table_d(&qp); /* -1.5 > -2 */
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_VALUES);
    qp = good; t = make_table_d(&qp); qp.W = W_changed;    /* one ulp after the CRC */
    assert_int_equal(stsp_init(&c, &t), STSP_ERR_BAD_CRC);
}

/* The band dual's header (a struct of its own) changed after init: the stage-0 latch solves
 * the dual init validated (its copy of q, nx and the array addresses), and verify reports
 * STSP_ERR_TABLE_CHANGED. The band arrays and x are exact heap blocks: under ASan a solve
 * through the changed header (more rows, a longer state, a shorter array) aborts. */
static void test_band_header_change_after_init(void **state)
{
    const float upper[2] = {0.5f, 3.0f};
    int which;
    (void)state;
    for (which = 0; which < 4; ++which) {
        stsp_bandqp_t qp = {2u, 2u, heap_copy(d_Nt, sizeof d_Nt), heap_copy(d_mt, sizeof d_mt),
                            heap_copy(d_W, sizeof d_W), heap_copy(d_lo, sizeof d_lo),
                            heap_copy(d_hi, sizeof d_hi), stsp_bandqp_solve_f32};
        const stsp_bandqp_t heap = qp, ref_qp = make_band_d();
        const stsp_table_t t = make_table_d(&qp), tr = make_table_d(&ref_qp);
        float *x = heap_copy(upper, sizeof upper);
        stsp_ctrl_t c, r;
        float u[1], u_ref[1];
        assert_int_equal(stsp_init(&c, &t), STSP_OK);
        assert_int_equal(stsp_init(&r, &tr), STSP_OK);
        switch (which) {
        case 0: qp.q = 3u; break;
        case 1: qp.nx = 3u; break;
        case 2: qp.Nt = qp.mt; break;           /* 2 doubles where 4 were */
        default: qp.q = 1u; break;
        }
        assert_int_equal(stsp_step(&c, 0u, x, u), stsp_step(&r, 0u, upper, u_ref));
        assert_int_equal(f32_bits(u[0]), f32_bits(u_ref[0]));
        assert_memory_equal(c.v, r.v, sizeof c.v);
        assert_int_equal(stsp_verify(&c), STSP_ERR_TABLE_CHANGED);
        assert_int_equal(stsp_verify(&r), STSP_OK);
        free(x);
        free((void *)heap.Nt);
        free((void *)heap.mt);
        free((void *)heap.W);
        free((void *)heap.lo);
        free((void *)heap.hi);
    }
}

/* The solver's proven bound, 3^(band rows) candidate active sets, pinned on its worst cases.
 * W = I, e = Nt x0 + mt = 2 + i/8 on row i, bands [-1, 0.5 + i/16]: every row is above its
 * band, so the only optimal active set has every row at its upper bound, lam = e - hi > 0,
 * the last candidate of the enumeration (digits 0, -1, +1 per band row); the solver must try
 * exactly 3^8 = 6561 sets. With rows 2 and 5 equality rows (always active, not enumerated)
 * the bound is 3^6 = 729. With W = -I no set but the empty one factors and the empty one
 * leaves every row outside its band: infeasible after exactly 3^8 sets (3^6 with the two
 * equality rows), lam all zeros. */
static void test_bandqp_candidate_bound(void **state)
{
    double Nt[STSP_BANDQP_MAX * 1u], mt[STSP_BANDQP_MAX], W[STSP_BANDQP_MAX * STSP_BANDQP_MAX];
    double neg_W[STSP_BANDQP_MAX * STSP_BANDQP_MAX], lo[STSP_BANDQP_MAX], hi[STSP_BANDQP_MAX];
    double lam[STSP_BANDQP_MAX];
    const float x0[1] = {1.0f};
    stsp_bandqp_t qp = {(uint16_t)STSP_BANDQP_MAX, 1u, Nt, mt, W, lo, hi, stsp_bandqp_solve_f32};
    stsp_bandqp_work_t work;
    uint32_t i, j, cand = 0u;
    (void)state;
    assert_int_equal(STSP_BANDQP_MAX, 8u);
    for (i = 0u; i < STSP_BANDQP_MAX; ++i) {
        Nt[i] = 1.0;
        mt[i] = 1.0 + (double)i / 8.0;
        lo[i] = -1.0;
        hi[i] = 0.5 + (double)i / 16.0;
        for (j = 0u; j < STSP_BANDQP_MAX; ++j) {
            W[i * STSP_BANDQP_MAX + j] = (i == j) ? 1.0 : 0.0;
            neg_W[i * STSP_BANDQP_MAX + j] = (i == j) ? -1.0 : 0.0;
        }
    }
    assert_int_equal(stsp_bandqp_solve(&qp, x0, lam, &work, &cand), STSP_BANDQP_OK);
    assert_int_equal(cand, 6561u);
    for (i = 0u; i < STSP_BANDQP_MAX; ++i) {
        assert_true(lam[i] == (2.0 + (double)i / 8.0) - (0.5 + (double)i / 16.0));
    }

    lo[2] = hi[2];  /* equality rows: lam there is e - b as well, the rest unchanged */
    lo[5] = hi[5];
    assert_int_equal(stsp_bandqp_solve(&qp, x0, lam, &work, &cand), STSP_BANDQP_OK);
    assert_int_equal(cand, 729u);
    for (i = 0u; i < STSP_BANDQP_MAX; ++i) {
        assert_true(lam[i] == (2.0 + (double)i / 8.0) - (0.5 + (double)i / 16.0));
    }

    lo[2] = -1.0;
    lo[5] = -1.0;
    qp.W = neg_W;
    lam[0] = 1.0;
    assert_int_equal(stsp_bandqp_solve(&qp, x0, lam, &work, &cand),
                     STSP_BANDQP_ERR_INFEASIBLE);
    assert_int_equal(cand, 6561u);
    for (i = 0u; i < STSP_BANDQP_MAX; ++i) {
        assert_true(lam[i] == 0.0);
    }
    lo[2] = hi[2];  /* and infeasible with equality rows: 3^6 sets, not more */
    lo[5] = hi[5];
    assert_int_equal(stsp_bandqp_solve(&qp, x0, lam, &work, &cand),
                     STSP_BANDQP_ERR_INFEASIBLE);
    assert_int_equal(cand, 729u);
}

/* ---- Non-symmetric W (a spline table's dual): Gaussian elimination with partial pivoting. */

/* Independent check of a solution: y = e - W lam (computed here) meets the conditions, with
 * active rows at their bound to 1e-12. For a P-matrix W the solution is unique, so a lam
 * that meets them is the solution (stsp_bandqp.h). Counts the band rows at an upper / lower
 * bound into up/down. */
static void check_lcp(const stsp_bandqp_t *qp, const float *x0, const double *lam, uint32_t *up,
                      uint32_t *down)
{
    uint32_t i, j;
    for (i = 0u; i < qp->q; ++i) {
        double y = qp->mt[i];
        for (j = 0u; j < qp->nx; ++j) {
            y += qp->Nt[i * qp->nx + j] * (double)x0[j];
        }
        for (j = 0u; j < qp->q; ++j) {
            y -= qp->W[i * qp->q + j] * lam[j];
        }
        if (qp->lo[i] == qp->hi[i]) {
            assert_true(fabs(y - qp->hi[i]) <= 1e-12);
        } else if (lam[i] > 0.0) {
            assert_true(fabs(y - qp->hi[i]) <= 1e-12);
            ++*up;
        } else if (lam[i] < 0.0) {
            assert_true(fabs(y - qp->lo[i]) <= 1e-12);
            ++*down;
        } else {
            assert_true((y <= qp->hi[i] + 1e-12) && (y >= qp->lo[i] - 1e-12));
        }
    }
}

/* A non-symmetric, strictly row-diagonally dominant W with a positive diagonal (so every
 * principal submatrix is too: a P-matrix); row 0 an equality, rows 1-3 bands. On a lattice
 * of 81 start states the solver's multipliers meet the conditions (checked independently,
 * check_lcp), with upper and lower bounds both reached somewhere. */
static void test_bandqp_nonsymmetric_p_matrix(void **state)
{
    static const double Nt[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    static const double mt[4] = {0.0, 0.125, -0.25, 0.5};
    static const double W[16] = {2.0,  0.7,  -0.3, 0.2,  0.4, 1.5,  0.5, -0.1,
                                 -0.2, 0.3,  1.8,  0.6,  0.1, -0.4, 0.2, 1.2};
    static const double lo[4] = {0.5, -1.0, -0.5, 0.0};
    static const double hi[4] = {0.5, 1.0, 0.25, 2.0};
    const stsp_bandqp_t qp = {4u, 4u, Nt, mt, W, lo, hi, stsp_bandqp_solve_f32};
    static const float grid[3] = {-3.0f, 0.5f, 3.5f};
    stsp_bandqp_work_t work;
    double lam[4];
    float x0[4];
    uint32_t a, up = 0u, down = 0u, cand;
    (void)state;
    for (a = 0u; a < 81u; ++a) {
        x0[0] = grid[a % 3u];
        x0[1] = grid[(a / 3u) % 3u];
        x0[2] = grid[(a / 9u) % 3u];
        x0[3] = grid[(a / 27u) % 3u];
        assert_int_equal(stsp_bandqp_solve(&qp, x0, lam, &work, &cand), STSP_BANDQP_OK);
        assert_true((cand >= 1u) && (cand <= 27u));
        check_lcp(&qp, x0, lam, &up, &down);
    }
    assert_true((up > 0u) && (down > 0u));
}

/* Partial pivoting: W = [[0, 1], [2, 0]] (both rows equalities) has a zero leading pivot;
 * W lam = e - b = (2, 3) gives lam = (1.5, 2) exactly. */
static void test_bandqp_nonsymmetric_pivoting(void **state)
{
    static const double Nt[4] = {1, 0, 0, 1};
    static const double mt[2] = {0.0, 0.0};
    static const double W[4] = {0.0, 1.0, 2.0, 0.0};
    static const double b[2] = {1.0, 2.0};
    const stsp_bandqp_t qp = {2u, 2u, Nt, mt, W, b, b, stsp_bandqp_solve_f32};
    const float x0[2] = {3.0f, 5.0f};
    stsp_bandqp_work_t work;
    double lam[2];
    uint32_t cand;
    (void)state;
    assert_int_equal(stsp_bandqp_solve(&qp, x0, lam, &work, &cand), STSP_BANDQP_OK);
    assert_int_equal(cand, 1u);
    assert_true((lam[0] == 1.5) && (lam[1] == 2.0));
}

/* Defined statuses of a non-symmetric W with no solution in double precision: a singular
 * W_AA ([[2, 4], [1, 2]]: a zero pivot) and one whose solution overflows ([[1e-300, 0], [1,
 * 1]], e - b = (1e10, 0): lam[0] = 1e310): STSP_BANDQP_ERR_INFEASIBLE, lam all zeros. */
static void test_bandqp_nonsymmetric_singular_and_overflow(void **state)
{
    static const double Nt[4] = {1, 0, 0, 1};
    static const double mt[2] = {0.0, 0.0};
    static const double singular[4] = {2.0, 4.0, 1.0, 2.0};
    static const double tiny[4] = {1e-300, 0.0, 1.0, 1.0};
    static const double b[2] = {0.0, 0.0};
    stsp_bandqp_t qp = {2u, 2u, Nt, mt, singular, b, b, stsp_bandqp_solve_f32};
    const float x0[2] = {1.0f, 1.0f}, big[2] = {1e10f, 0.0f};
    stsp_bandqp_work_t work;
    double lam[2] = {7.0, 7.0};
    float v[2] = {7.0f, 7.0f};
    uint32_t cand;
    (void)state;
    assert_int_equal(stsp_bandqp_solve(&qp, x0, lam, &work, &cand), STSP_BANDQP_ERR_INFEASIBLE);
    assert_int_equal(cand, 1u);
    assert_true((lam[0] == 0.0) && (lam[1] == 0.0));
    qp.W = tiny;
    lam[0] = 7.0;
    assert_int_equal(stsp_bandqp_solve(&qp, big, lam, &work, &cand), STSP_BANDQP_ERR_INFEASIBLE);
    assert_true((lam[0] == 0.0) && (lam[1] == 0.0));
    assert_int_equal(stsp_bandqp_solve_f32(&qp, big, v), STSP_BANDQP_ERR_INFEASIBLE);
    assert_true((v[0] == 7.0f) && (v[1] == 7.0f));
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_band_latch_solves_the_dual),
        cmocka_unit_test(test_band_fallback_and_nonfinite),
        cmocka_unit_test(test_band_tables_are_checked),
        cmocka_unit_test(test_band_header_change_after_init),
        cmocka_unit_test(test_bandqp_candidate_bound),
        cmocka_unit_test(test_bandqp_nonsymmetric_p_matrix),
        cmocka_unit_test(test_bandqp_nonsymmetric_pivoting),
        cmocka_unit_test(test_bandqp_nonsymmetric_singular_and_overflow),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
