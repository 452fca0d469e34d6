/* Shapes test for the Cortex-M4F generic float32 build (tools/arm/run_replay.sh, QEMU
 * mps2-an386): the replay covers only the robot's shape (nx 4, nu 2, n_latch 4), whose rows the
 * generic law evaluates as one pair of rows and whole groups of four columns. Here every shape
 * with nx 1..9, nu 1..5 and n_latch 0..6 (odd nu: a last row alone; nx, n_latch not multiples
 * of 4: the columns one at a time after the groups of four; n_latch 0: no L, passed as NULL)
 * steps a one-stage table of random gains through the latch (tick 0, cold path), two ordinary
 * ticks (ticks 1 and 2: on the rows the cold path, then the ordinary tick, moved on to), a
 * repeat (tick 2 again, cold path), an ordinary tick after it (tick 3, the table's last) and
 * tick 4 (past the end: STSP_ERR_TICK_RANGE, u_hold), without limits and with limits that are
 * never reached, and compares every command bit for bit with the law written out here in the
 * documented order (stsp_controller.h), compiled with -ffp-contract=off like the firmware:
 *     v[c] = lambda0[c] + Lambda[c][0] x0[0] + ...,
 *     u[i] = (((-(K[i][0] x[0]) - k0[i]) - K[i][1] x[1]) - ...) - L[i][0] v[0] - ...
 * Prints "shapes: PASS" and exits 0 only if every command and status matched. */
#include <float.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "stospline/stsp_controller.h"

#define SHAPES_MAX_NX 9u
#define SHAPES_MAX_NU 5u
#define SHAPES_MAX_LATCH 6u
#define SHAPES_TICKS 4u

static uint32_t rng_state = 12345u;

/* A value in (-4, 4) with a random mantissa: products and sums that round. */
static float rnd(void)
{
    rng_state = (rng_state * 1664525u) + 1013904223u;
    return ((float)(int32_t)(rng_state >> 8) / 8388608.0f) * 2.0f - 0.999f;
}

static float K[SHAPES_TICKS * SHAPES_MAX_NU * SHAPES_MAX_NX];
static float k0[SHAPES_TICKS * SHAPES_MAX_NU];
static float L[SHAPES_TICKS * SHAPES_MAX_NU * SHAPES_MAX_LATCH];
static float Lambda[SHAPES_MAX_LATCH * SHAPES_MAX_NX];
static float lambda0[SHAPES_MAX_LATCH];
static float u_min[SHAPES_MAX_NU];
static float u_max[SHAPES_MAX_NU];
static float u_hold[SHAPES_MAX_NU];
static const uint32_t stage_start[2] = {0u, SHAPES_TICKS};
static uint16_t stage_n_latch[1];

/* The documented law at `tick` with multipliers v. */
static void reference(uint32_t nx, uint32_t nu, uint32_t nl, uint32_t tick, const float *x,
                      const float *v, float *u)
{
    uint32_t i;
    uint32_t j;
    for (i = 0u; i < nu; ++i) {
        const float *Ki = &K[(tick * nu + i) * nx];
        const float *Li = &L[(tick * nu + i) * nl];
        float acc = (-(Ki[0] * x[0])) - k0[tick * nu + i];
        for (j = 1u; j < nx; ++j) {
            acc = acc - Ki[j] * x[j];
        }
        for (j = 0u; j < nl; ++j) {
            acc = acc - Li[j] * v[j];
        }
        u[i] = acc;
    }
}

static int check(const char *what, uint32_t nx, uint32_t nu, uint32_t nl, int limited,
                 stsp_status_t st, stsp_status_t want, const float *u, const float *ref)
{
    uint32_t i;
    if (st != want) {
        printf("shapes: nx %lu nu %lu n_latch %lu limits %d %s: status %d, expected %d\n",
               (unsigned long)nx, (unsigned long)nu, (unsigned long)nl, limited, what, (int)st,
               (int)want);
        return 1;
    }
    for (i = 0u; i < nu; ++i) {
        uint32_t a;
        uint32_t b;
        (void)memcpy(&a, &u[i], sizeof a);
        (void)memcpy(&b, &ref[i], sizeof b);
        if (a != b) {
            printf("shapes: nx %lu nu %lu n_latch %lu limits %d %s: u[%lu] 0x%08lx, expected "
                   "0x%08lx\n",
                   (unsigned long)nx, (unsigned long)nu, (unsigned long)nl, limited, what,
                   (unsigned long)i, (unsigned long)a, (unsigned long)b);
            return 1;
        }
    }
    return 0;
}

int main(void)
{
    static stsp_ctrl_t ctrl;
    static stsp_table_t t;
    uint32_t nx;
    uint32_t nu;
    uint32_t nl;
    uint32_t shapes = 0u;
    uint32_t failures = 0u;
    int limited;
    for (nx = 1u; nx <= SHAPES_MAX_NX; ++nx) {
        for (nu = 1u; nu <= SHAPES_MAX_NU; ++nu) {
            for (nl = 0u; nl <= SHAPES_MAX_LATCH; ++nl) {
                for (limited = 0; limited <= 1; ++limited) {
                    float x0[SHAPES_MAX_NX];
                    float x1[SHAPES_MAX_NX];
                    float x2[SHAPES_MAX_NX];
                    float v[SHAPES_MAX_LATCH];
                    float u[SHAPES_MAX_NU];
                    float ref[SHAPES_MAX_NU];
                    uint32_t i;
                    uint32_t j;
                    stsp_status_t st;
                    for (i = 0u; i < SHAPES_TICKS * nu * nx; ++i) {
                        K[i] = rnd();
                    }
                    for (i = 0u; i < SHAPES_TICKS * nu; ++i) {
                        k0[i] = rnd();
                    }
                    for (i = 0u; i < SHAPES_TICKS * nu * nl; ++i) {
                        L[i] = rnd();
                    }
                    for (i = 0u; i < nl * nx; ++i) {
                        Lambda[i] = rnd();
                    }
                    for (i = 0u; i < nl; ++i) {
                        lambda0[i] = rnd();
                    }
                    for (i = 0u; i < nu; ++i) {
                        u_min[i] = (limited != 0) ? -1.0e6f : -FLT_MAX;
                        u_max[i] = (limited != 0) ? 1.0e6f : FLT_MAX;
                        u_hold[i] = 0.25f;
                    }
                    for (j = 0u; j < nx; ++j) {
                        x0[j] = rnd();
                        x1[j] = rnd();
                        x2[j] = rnd();
                    }
                    stage_n_latch[0] = (uint16_t)nl;
                    (void)memset(&t, 0, sizeof t);
                    t.magic = STSP_TABLE_MAGIC;
                    t.format_version = (uint16_t)STSP_FORMAT_VERSION;
                    t.scalar_kind = (uint16_t)STSP_SCALAR_KIND;
                    t.nx = (uint16_t)nx;
                    t.nu = (uint16_t)nu;
                    t.n_latch = (uint16_t)nl;
                    t.n_stages = 1u;
                    t.n_ticks = SHAPES_TICKS;
                    t.tick_hz = 100u;
                    t.stage_start = stage_start;
                    t.stage_n_latch = stage_n_latch;
                    t.K = K;
                    t.k0 = k0;
                    t.L = (nl > 0u) ? L : NULL;
                    t.Lambda = (nl > 0u) ? Lambda : NULL;
                    t.lambda0 = (nl > 0u) ? lambda0 : NULL;
                    t.u_min = u_min;
                    t.u_max = u_max;
                    t.u_hold = u_hold;
                    t.crc32 = stsp_table_crc32(&t);
                    st = stsp_init(&ctrl, &t);
                    if (st != STSP_OK) {
                        printf("shapes: nx %lu nu %lu n_latch %lu: init %d\n", (unsigned long)nx,
                               (unsigned long)nu, (unsigned long)nl, (int)st);
                        ++failures;
                        continue;
                    }
                    for (i = 0u; i < nl; ++i) {
                        float acc = lambda0[i];
                        for (j = 0u; j < nx; ++j) {
                            acc += Lambda[i * nx + j] * x0[j];
                        }
                        v[i] = acc;
                    }
                    /* Tick 0: the latch (cold path); ticks 1, 2: ordinary; tick 2 again: a
                     * repeat (cold path); tick 3: ordinary; tick 4: past the end. */
                    st = stsp_step(&ctrl, 0u, x0, u);
                    reference(nx, nu, nl, 0u, x0, v, ref);
                    failures += (uint32_t)check("latch", nx, nu, nl, limited, st, STSP_OK, u, ref);
                    st = stsp_step(&ctrl, 1u, x1, u);
                    reference(nx, nu, nl, 1u, x1, v, ref);
                    failures +=
                        (uint32_t)check("ordinary", nx, nu, nl, limited, st, STSP_OK, u, ref);
                    st = stsp_step(&ctrl, 2u, x2, u);
                    reference(nx, nu, nl, 2u, x2, v, ref);
                    failures +=
                        (uint32_t)check("ordinary 2", nx, nu, nl, limited, st, STSP_OK, u, ref);
                    st = stsp_step(&ctrl, 2u, x0, u);
                    reference(nx, nu, nl, 2u, x0, v, ref);
                    failures += (uint32_t)check("repeat", nx, nu, nl, limited, st,
                                                STSP_WARN_TICK_REPEATED, u, ref);
                    st = stsp_step(&ctrl, 3u, x1, u);
                    reference(nx, nu, nl, 3u, x1, v, ref);
                    failures +=
                        (uint32_t)check("ordinary 3", nx, nu, nl, limited, st, STSP_OK, u, ref);
                    st = stsp_step(&ctrl, 4u, x2, u);
                    for (i = 0u; i < nu; ++i) {
                        ref[i] = u_hold[i];
                    }
                    failures += (uint32_t)check("past the end", nx, nu, nl, limited, st,
                                                STSP_ERR_TICK_RANGE, u, ref);
                    ++shapes;
                }
            }
        }
    }
    printf("shapes: %lu tables (nx 1..%lu, nu 1..%lu, n_latch 0..%lu, with and without limits), "
           "%lu mismatches\n",
           (unsigned long)shapes, (unsigned long)SHAPES_MAX_NX, (unsigned long)SHAPES_MAX_NU,
           (unsigned long)SHAPES_MAX_LATCH, (unsigned long)failures);
    printf("shapes: %s\n", (failures == 0u) ? "PASS" : "FAIL");
    return (failures == 0u) ? 0 : 1;
}
