/* The estimator controller with its update gains as a spline (stsp_est_init_spline(),
 * stsp_estimator.h) on the shipped gains/robot_position_sensor_spline.* tables: bit for bit
 * the instance that runs the same plan on a per-tick table holding the gains the host
 * evaluates from the spline (estimator_spline_expected.h, from
 * tests/c/estimator_spline_reference.py), readings missing and ticks skipped included; and
 * every bad input's status: NULL pointers, magic, layout (gain not NULL, start arrays,
 * knots, entries), CRC, a spline of another table, non-finite coefficients, a changed spline
 * after init (verify). Built against the generic float32 controller and under ASan + UBSan. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "estimator_spline_expected.h"
#include "robot_position_sensor_spline.h"

#define P(x) ROBOT_POSITION_SENSOR_SPLINE_##x
#define NX P(NX)
#define NY P(NY)
#define EVERY P(EVERY)
#define N_TICKS P(N_TICKS)
#define N_SAMPLES ((N_TICKS + EVERY - 1u) / EVERY)

static const stsp_table_t *const T = &robot_position_sensor_spline_table;
static const stsp_est_table_t *const E = &robot_position_sensor_spline_estimator;
static const stsp_est_gain_spline_t *const G = &robot_position_sensor_spline_est_gain_spline;

static float per_tick_gain[N_SAMPLES * NX * NY];
static float coef_copy[4096];
static uint8_t entry_copy[64];
static float knot_copy[256];

static uint32_t bits_of(float v)
{
    uint32_t b;
    v = v + 0.0f;
    memcpy(&b, &v, sizeof b);
    return b;
}

/* The per-tick twin of E: the host's evaluation of the spline as its gain table. */
static stsp_est_table_t per_tick_twin(void)
{
    stsp_est_table_t c = *E;
    memcpy(per_tick_gain, est_spline_gain_bits, sizeof per_tick_gain);
    c.gain = per_tick_gain;
    c.crc32 = stsp_est_table_crc32(&c);
    return c;
}

/* A reading from a fixed LCG, uniform in [-4096, 4096] per output: innovations large enough
 * that a gain one unit in the last place off changes the estimate's bits. */
static void reading(uint32_t *state, float y[NY])
{
    uint32_t i;
    for (i = 0u; i < NY; ++i) {
        *state = (*state * 1664525u) + 1013904223u;
        y[i] = ((float)(*state >> 8) / 16777216.0f) * 8192.0f - 4096.0f;
    }
}

static void test_crc_and_header(void **state)
{
    (void)state;
    assert_null(E->gain);
    assert_int_equal(stsp_est_table_crc32(E), E->crc32);
    assert_int_equal(G->est_crc32, E->crc32);
    assert_int_equal(stsp_est_gain_spline_crc32(G, E), G->crc32);
    assert_int_equal(G->crc32, EST_SPLINE_CRC32); /* else: rerun estimator_spline_reference.py */
    assert_true(G->n_coef <= (sizeof coef_copy / sizeof coef_copy[0]));
    assert_true(G->n_entries <= sizeof entry_copy);
    assert_true(G->n_knots <= (sizeof knot_copy / sizeof knot_copy[0]));
}

/* The whole plan on both instances: every command and prediction the same bits; a sampling
 * tick without its reading and a skip of 23 ticks on the way. */
static void test_bit_for_bit_against_the_per_tick_gains(void **state)
{
    stsp_est_table_t twin = per_tick_twin();
    stsp_est_t a;
    stsp_est_t b;
    float u_a[2];
    float u_b[2];
    float y[NY];
    uint32_t lcg = 20261129u;
    uint32_t j;
    uint32_t r;
    (void)state;
    assert_int_equal(stsp_est_init(&a, T, &twin), STSP_OK);
    assert_int_equal(stsp_est_init_spline(&b, T, E, G), STSP_OK);
    for (j = 0u; j < N_TICKS; ++j) {
        const float *yj = NULL;
        stsp_status_t sa;
        if ((j >= 22u) && (j < 45u)) {
            continue; /* skipped: predicted over with the last command held */
        }
        if (((j % EVERY) == 0u) && (j != 1000u)) {
            reading(&lcg, y);
            yj = y;
        }
        sa = stsp_est_step(&a, j, yj, u_a);
        assert_int_equal(stsp_est_step(&b, j, yj, u_b), sa);
        assert_true(sa >= STSP_OK);
        assert_int_equal(bits_of(u_a[0]), bits_of(u_b[0]));
        assert_int_equal(bits_of(u_a[1]), bits_of(u_b[1]));
        for (r = 0u; r < NX; ++r) {
            assert_int_equal(bits_of(a.xhat[r]), bits_of(b.xhat[r]));
        }
    }
    assert_int_equal(stsp_est_verify(&b), STSP_OK);
    assert_int_equal(stsp_est_reset(&b), STSP_OK);
}

static stsp_status_t init_with(const stsp_est_gain_spline_t *g)
{
    stsp_est_t e;
    const stsp_status_t st = stsp_est_init_spline(&e, T, E, g);
    if (st != STSP_OK) {
        assert_int_not_equal(e.ready, 0x45005300u); /* not ready */
    }
    return st;
}

/* A spline whose CRC is right for what it holds now. */
static stsp_est_gain_spline_t resealed(stsp_est_gain_spline_t g)
{
    g.crc32 = stsp_est_gain_spline_crc32(&g, E);
    return g;
}

static void test_bad_inputs_are_refused(void **state)
{
    static const uint32_t bad_starts[3] = {0u, 5u, 0u};
    stsp_est_table_t twin = per_tick_twin();
    stsp_est_gain_spline_t g;
    stsp_est_t e;
    (void)state;
    assert_int_equal(stsp_est_init_spline(NULL, T, E, G), STSP_ERR_NULL);
    assert_int_equal(stsp_est_init_spline(&e, T, NULL, G), STSP_ERR_NULL);
    assert_int_equal(stsp_est_init_spline(&e, T, E, NULL), STSP_ERR_NULL);
    assert_int_equal(stsp_est_init(&e, T, E), STSP_ERR_NULL); /* no gains at all */
    assert_int_equal(stsp_est_init_spline(&e, T, &twin, G), STSP_ERR_BAD_DIMS); /* both */
    g = *G; g.coef = NULL;
    assert_int_equal(init_with(&g), STSP_ERR_NULL);
    g = *G; g.entry = NULL;
    assert_int_equal(init_with(&g), STSP_ERR_NULL);
    g = *G; g.magic ^= 1u;
    assert_int_equal(init_with(&g), STSP_ERR_BAD_MAGIC);
    g = *G; g.n_coef -= 1u;
    assert_int_equal(init_with(&g), STSP_ERR_BAD_DIMS);
    g = *G; g.knot_start = bad_starts;
    assert_int_equal(init_with(&g), STSP_ERR_BAD_DIMS);
    /* entries not increasing; an entry beyond nx ny */
    memcpy(entry_copy, G->entry, G->n_entries);
    entry_copy[1] = entry_copy[0];
    g = *G; g.entry = entry_copy;
    assert_int_equal(init_with(&g), STSP_ERR_BAD_DIMS);
    entry_copy[1] = (uint8_t)(NX * NY);
    assert_int_equal(init_with(&g), STSP_ERR_BAD_DIMS);
    /* a knot not an integer, a knot out of order */
    memcpy(knot_copy, G->knot, G->n_knots * sizeof knot_copy[0]);
    knot_copy[5] += 0.5f;
    g = *G; g.knot = knot_copy;
    assert_int_equal(init_with(&g), STSP_ERR_BAD_DIMS);
    knot_copy[5] = knot_copy[6];
    assert_int_equal(init_with(&g), STSP_ERR_BAD_DIMS);
    /* one flipped coefficient: the CRC; resealed NaN: the values */
    memcpy(coef_copy, G->coef, G->n_coef * sizeof coef_copy[0]);
    coef_copy[17] = -coef_copy[17];
    g = *G; g.coef = coef_copy;
    assert_int_equal(init_with(&g), STSP_ERR_BAD_CRC);
    coef_copy[17] = NAN;
    g = resealed(g);
    assert_int_equal(init_with(&g), STSP_ERR_BAD_VALUES);
    coef_copy[17] = INFINITY;
    g = resealed(g);
    assert_int_equal(init_with(&g), STSP_ERR_BAD_VALUES);
    /* a spline of another estimator table (its CRC right): the pair */
    g = *G; g.est_crc32 ^= 1u;
    g = resealed(g);
    assert_int_equal(init_with(&g), STSP_ERR_BAD_PROBLEM);
    g.crc32 ^= 1u;
    assert_int_equal(init_with(&g), STSP_ERR_BAD_CRC);
}

static void test_verify_stops_on_a_changed_spline(void **state)
{
    stsp_est_gain_spline_t g = *G;
    stsp_est_t e;
    float u[2];
    (void)state;
    memcpy(coef_copy, G->coef, G->n_coef * sizeof coef_copy[0]);
    g.coef = coef_copy;
    assert_int_equal(stsp_est_init_spline(&e, T, E, &g), STSP_OK);
    assert_int_equal(stsp_est_verify(&e), STSP_OK);
    assert_int_equal(stsp_est_step(&e, 0u, NULL, u), STSP_WARN_NO_MEASUREMENT);
    coef_copy[3] = -coef_copy[3]; /* the data: the CRC */
    assert_int_equal(stsp_est_verify(&e), STSP_ERR_BAD_CRC);
    assert_int_equal(stsp_est_step(&e, 1u, NULL, u), STSP_ERR_NOT_INITIALIZED);
    assert_true((u[0] == T->u_hold[0]) && (u[1] == T->u_hold[1]));
    coef_copy[3] = G->coef[3];
    assert_int_equal(stsp_est_init_spline(&e, T, E, &g), STSP_OK);
    g.n_knots += 1u; /* the header: changed, no array read through it */
    assert_int_equal(stsp_est_verify(&e), STSP_ERR_TABLE_CHANGED);
    assert_int_equal(stsp_est_reset(&e), STSP_ERR_NOT_INITIALIZED);
}

/* A spline changed after init (before verify notices): a stage layout beyond the arrays
 * gives no update (F = 0), never an access outside them (the ASan build). */
static void test_changed_layout_reads_within_bounds(void **state)
{
    static uint32_t starts[3];
    stsp_est_gain_spline_t g = *G;
    stsp_est_t e;
    float u[2];
    float y[NY] = {0.5f, -0.5f};
    (void)state;
    memcpy(starts, G->entry_start, sizeof starts);
    g.entry_start = starts;
    assert_int_equal(stsp_est_init_spline(&e, T, E, &g), STSP_OK);
    starts[1] = 200u; /* beyond n_entries */
    assert_true(stsp_est_step(&e, 0u, y, u) >= STSP_OK);
    assert_int_equal(stsp_est_verify(&e), STSP_ERR_BAD_CRC);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_crc_and_header),
        cmocka_unit_test(test_bit_for_bit_against_the_per_tick_gains),
        cmocka_unit_test(test_bad_inputs_are_refused),
        cmocka_unit_test(test_verify_stops_on_a_changed_spline),
        cmocka_unit_test(test_changed_layout_reads_within_bounds),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
