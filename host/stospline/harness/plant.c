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
#define PLANT_CAP (HARNESS_N < 64 ? HARNESS_N : 64)
#else
#define PLANT_N (pl->n)
#define PLANT_M (pl->m)
#define PLANT_CAP 64
#endif

/* Noise entry e's term w * g * dZ, added to component g_index[3e+1] of xn. With compile-time
 * dimensions the component and the multiplier w are picked by comparing against every index
 * instead of indexing with them, so xs and xn stay in registers (an index known only at run
 * time would keep them in memory, each add a store and a reload). Adding +0.0 to the other
 * components leaves them as they are (the sums start at +0.0, so none is -0.0), and the
 * terms reach each component in the same order: the same bits. */
static inline void plant_noise(const harness_plant_t *pl, size_t n, const double *xs,
                               const double *u, const double *dzs, double *xn)
{
    size_t k, i;
    for (k = 0; k < pl->g_count; ++k) {
        const size_t *e = pl->g_index + 3u * k;
#if defined(HARNESS_N) && defined(HARNESS_M)
        double w = 0.0, term;
        for (i = 0; i < PLANT_N; ++i) w = (e[0] == i) ? xs[i] : w;
        for (i = 0; i < PLANT_M; ++i) w = (e[0] == PLANT_N + i) ? u[i] : w;
        term = w * pl->g_value[k] * (dzs[e[2]] * pl->dz_scale);
        for (i = 0; i < PLANT_N; ++i) xn[i] += (e[1] == i) ? term : 0.0;
        (void)n;
#else
        const double w = (e[0] < n) ? xs[e[0]] : u[e[0] - n];
        (void)i;
        xn[e[1]] += w * pl->g_value[k] * (dzs[e[2]] * pl->dz_scale);
#endif
    }
}

/* The body of harness_plant_path, inlined where the harness's tick loop is compiled with
 * it (harness/controller.py includes this file), so the compiler schedules it with the loop. */
#if defined(__GNUC__)
__attribute__((always_inline))
#endif
static inline double plant_path(const harness_plant_t *pl, const double *u, const double *dz,
                                double *x)
{
    const size_t n = PLANT_N, m = PLANT_M, mz = pl->mz;
    double xs[PLANT_CAP], xn[PLANT_CAP];
    double c = 0.0, uru = 0.0;
    size_t s, i, j;
    if (n > (size_t)PLANT_CAP || m > 32u || n != pl->n || m != pl->m) {
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
        plant_noise(pl, n, xs, u, dzs, xn);
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
