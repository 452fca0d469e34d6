/* Harness-only plant integrator (not firmware): see plant.h. */
#include <math.h>
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
 * it (harness/controller_c.py's loop includes this file), so the compiler schedules it with
 * the loop. */
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

/* What the tick loop reads once per call rather than per path: the scalars of the step and,
 * in a module built for one problem (HARNESS_PLANT_SPEC, plant_spec.py), the coefficients of
 * its compiled step, in a local the paths' stores cannot alias. */
typedef struct plant_prep plant_prep_t;
#ifdef HARNESS_PLANT_SPEC
#define PLANT_SPEC_ZERO 0u       /* coefficient kinds, as plant_spec.py writes them */
#define PLANT_SPEC_ONE 1u
#define PLANT_SPEC_VALUE 2u
#define PLANT_SPEC_PLUS_ZERO 3u
#include "plant_spec.h"          /* its constants (the step follows, after plant_prep) */
#else
#define PLANT_SPEC_VALUES 1u
#endif
struct plant_prep {
    int spec;                    /* 1: pl fits the compiled step, which runs */
    size_t substeps;
    double dt, dz_scale, rho;
    double v[PLANT_SPEC_VALUES];
};
#ifdef HARNESS_PLANT_SPEC
#define PLANT_SPEC_STEP
#include "plant_spec.h"          /* its step, plant_spec_path */
#endif

#ifdef HARNESS_PLANT_SPEC
/* Checks `count` coefficients a (NULL: zeros) times `scale` against their kinds, from
 * *kind on, and appends the VALUE ones to pp->v; 0 when one does not fit its kind. */
static int plant_spec_take(plant_prep_t *pp, size_t *used, const unsigned char **kind,
                           const double *a, size_t count, double scale)
{
    size_t i;
    for (i = 0; i < count; ++i) {
        const double c = a == NULL ? 0.0 : scale * a[i];
        const unsigned char k = *(*kind)++;
        if (k == PLANT_SPEC_VALUE) {
            if (*used >= PLANT_SPEC_VALUES) return 0;
            pp->v[(*used)++] = c;
        } else if (k == PLANT_SPEC_ONE ? c != 1.0
                   : c != 0.0 || (k == PLANT_SPEC_PLUS_ZERO && signbit(c))) {
            return 0;
        }
    }
    return 1;
}
#endif

static void plant_prepare(const harness_plant_t *pl, plant_prep_t *pp)
{
    pp->spec = 0;
    pp->substeps = pl->substeps;
    pp->dt = pl->dt;
    pp->dz_scale = pl->dz_scale;
    pp->rho = pl->rho;
#ifdef HARNESS_PLANT_SPEC
    {
        const size_t n = PLANT_N, m = PLANT_M;
        const unsigned char *kind = plant_spec_kind;
        size_t used = 0;
        int fits = pl->n == n && pl->m == m && pl->mz == PLANT_SPEC_MZ
                   && pl->g_count == PLANT_SPEC_G && pl->state_cost == PLANT_SPEC_STATE_COST;
#if PLANT_SPEC_G > 0  /* a noise-free plant has no entries (and k < 0u would warn) */
        {
            size_t k;
            for (k = 0; fits && k < 3u * PLANT_SPEC_G; ++k) {
                fits = pl->g_index[k] == plant_spec_g_index[k];
            }
        }
#endif
        fits = fits && plant_spec_take(pp, &used, &kind, pl->R, m * m, 1.0)
               && plant_spec_take(pp, &used, &kind, pl->r, m, 2.0);
        if (PLANT_SPEC_STATE_COST) {
            fits = fits && plant_spec_take(pp, &used, &kind, pl->Q, n * n, 1.0)
                   && plant_spec_take(pp, &used, &kind, pl->S, n * m, 2.0)
                   && plant_spec_take(pp, &used, &kind, pl->q, n, 2.0);
        }
        fits = fits && plant_spec_take(pp, &used, &kind, pl->Ad, n * n, 1.0)
               && plant_spec_take(pp, &used, &kind, pl->Bd, n * m, 1.0)
               && plant_spec_take(pp, &used, &kind, pl->fd, n, 1.0)
               && plant_spec_take(pp, &used, &kind, pl->g_value, PLANT_SPEC_G, 1.0);
        pp->spec = fits;
    }
#endif
}

#if defined(HARNESS_PLANT_SPEC) && CORRIDOR_SPEC_COUNT > 0
/* Whether corridor c (n states) is compiled corridor k: the same outputs and walls. */
static inline int corridor_spec_fits(const harness_corridor_t *c, size_t k, size_t n)
{
    const harness_corridor_t *s = &corridor_spec[k];
    size_t i, walls;
    if (k >= CORRIDOR_SPEC_COUNT || c->p != s->p || c->n_poly != s->n_poly) return 0;
    for (i = 0; i <= s->n_poly; ++i) if (c->row_start[i] != s->row_start[i]) return 0;
    walls = s->row_start[s->n_poly];
    for (i = 0; i < s->p * n; ++i) if (c->C[i] != s->C[i]) return 0;
    for (i = 0; i < walls * s->p; ++i) if (c->A[i] != s->A[i]) return 0;
    for (i = 0; i < walls; ++i) if (c->b[i] != s->b[i]) return 0;
    return 1;
}
#endif

/* One path's tick: the compiled step when pl fits it, else the generic one. */
#if defined(__GNUC__)
__attribute__((always_inline))
#endif
static inline double plant_step(const harness_plant_t *pl, const plant_prep_t *pp,
                                const double *u, const double *dz, double *x)
{
#ifdef HARNESS_PLANT_SPEC
    if (pp->spec) return plant_spec_path(pp, u, dz, x);
#else
    (void)pp;
#endif
    return plant_path(pl, u, dz, x);
}

double harness_plant_path(const harness_plant_t *pl, const double *u, const double *dz,
                          double *x)
{
    plant_prep_t pp;
    plant_prepare(pl, &pp);
    return plant_step(pl, &pp, u, dz, x);
}

int harness_plant_compiled(const harness_plant_t *pl)
{
    plant_prep_t pp;
    plant_prepare(pl, &pp);
    return pp.spec;
}

void harness_plant_tick(const harness_plant_t *pl, size_t paths, const double *dZ,
                        const float *U, double *X, double *cost)
{
    double u[32];
    plant_prep_t pp;
    size_t p, j;
    if (pl->m > 32u) {
        return;
    }
    plant_prepare(pl, &pp);
    for (p = 0; p < paths; ++p) {
        for (j = 0; j < pl->m; ++j) {
            u[j] = (double)U[p * pl->m + j];
        }
        cost[p] += plant_step(pl, &pp, u, dZ + p * pl->substeps * pl->mz, X + p * pl->n);
    }
}
