/* Harness-only plant integrator (not firmware): see plant.h. */
#include <stddef.h>
#include <stdint.h>

#include "plant.h"

/* The harness builds one module per table, so the dimensions are known at compile time:
 * HARNESS_N/HARNESS_M (the table's nx/nu) let the compiler unroll every loop, which makes the
 * step several times faster for small systems. Without them, the run-time ones. */
#if defined(HARNESS_N) && defined(HARNESS_M)
#define PLANT_N ((size_t)HARNESS_N)
#define PLANT_M ((size_t)HARNESS_M)
#else
#define PLANT_N (pl->n)
#define PLANT_M (pl->m)
#endif

/* The body of harness_plant_path, inlined where the harness's tick loop is compiled with
 * it (sim/controller.py includes this file), so the compiler schedules it with the loop. */
#if defined(__GNUC__)
__attribute__((always_inline))
#endif
static inline double plant_path(const harness_plant_t *pl, const double *u, const double *dz,
                                double *x)
{
    const size_t n = PLANT_N, m = PLANT_M, mz = pl->mz;
    double xs[64], xn[64];
    double c = 0.0, uru = 0.0;
    size_t s, i, j, k;
    if (n > 64u || m > 32u || n != pl->n || m != pl->m) {
        return 0.0;
    }
    for (i = 0; i < m; ++i) {
        double acc = 2.0 * pl->r[i];
        for (j = 0; j < m; ++j) {
            acc += pl->R[i * m + j] * u[j];
        }
        uru += acc * u[i];
    }
    c += pl->dt * (double)pl->substeps * (uru + pl->rho);
    for (i = 0; i < n; ++i) {
        xs[i] = x[i];
    }
    for (s = 0; s < pl->substeps; ++s) {
        const double *dzs = dz + s * mz;
        if (pl->state_cost) {
            double lx = 0.0;
            for (i = 0; i < n; ++i) {
                double acc = 2.0 * pl->q[i];
                for (j = 0; j < n; ++j) {
                    acc += pl->Q[i * n + j] * xs[j];
                }
                for (j = 0; j < m; ++j) {
                    acc += 2.0 * pl->S[i * m + j] * u[j];
                }
                lx += acc * xs[i];
            }
            c += pl->dt * lx;
        }
        for (i = 0; i < n; ++i) {
            double acc = 0.0;
            for (j = 0; j < n; ++j) {
                acc += pl->Ad[i * n + j] * xs[j];
            }
            for (j = 0; j < m; ++j) {
                acc += pl->Bd[i * m + j] * u[j];
            }
            if (pl->fd != NULL) {
                acc += pl->fd[i];
            }
            xn[i] = acc;
        }
        for (k = 0; k < pl->g_count; ++k) {
            const size_t *e = pl->g_index + 3u * k;
            const double w = (e[0] < n) ? xs[e[0]] : u[e[0] - n];
            xn[e[1]] += w * pl->g_value[k] * (dzs[e[2]] * pl->dz_scale);
        }
        for (i = 0; i < n; ++i) {
            xs[i] = xn[i];
        }
    }
    for (i = 0; i < n; ++i) {
        x[i] = xs[i];
    }
    return c;
}

double harness_plant_path(const harness_plant_t *pl, const double *u, const double *dz,
                          double *x)
{
    return plant_path(pl, u, dz, x);
}

void harness_plant_tick(const harness_plant_t *pl, size_t paths, const double *dZ,
                        const float *U, double *X, double *cost)
{
    double u[32];
    size_t p, j;
    if (pl->m > 32u) {
        return;
    }
    for (p = 0; p < paths; ++p) {
        for (j = 0; j < pl->m; ++j) {
            u[j] = (double)U[p * pl->m + j];
        }
        cost[p] += harness_plant_path(pl, u, dZ + p * pl->substeps * pl->mz, X + p * pl->n);
    }
}
