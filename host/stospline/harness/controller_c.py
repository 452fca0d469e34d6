"""The C text of a controller module (`controller.build_controller`): the declarations cffi
sees (`controller_cdef`) and the harness's loops over the instances (`BATCH`: every path's
controller, plant, corridor watch and statistics in one call), and the arithmetic variants."""
from __future__ import annotations

import numpy as np

from stospline.harness.build import BATCH_CDEF, PLANT_CDEF

__all__ = ["BATCH", "VARIANTS", "controller_cdef"]

CDEF = """%(plant)s
typedef float stsp_f32_t;
typedef %(scalar)s stsp_scalar_t;
typedef int... stsp_status_t;
typedef struct {
    uint16_t q; uint16_t nx; const double *Nt; const double *mt; const double *W;
    const double *lo; const double *hi; ...;
} stsp_bandqp_t;
typedef struct { ...; } %(spline_t)s;
typedef struct {
    uint32_t magic; uint16_t format_version; uint16_t scalar_kind;
    uint16_t nx; uint16_t nu; uint16_t n_latch; uint16_t n_stages;
    uint32_t n_ticks; uint32_t tick_hz;
    const uint32_t *stage_start; const uint16_t *stage_n_latch;
    const stsp_scalar_t *K; const stsp_scalar_t *k0; const stsp_scalar_t *L;
    const stsp_scalar_t *Lambda; const stsp_scalar_t *lambda0;
    const stsp_scalar_t *u_min; const stsp_scalar_t *u_max; const stsp_scalar_t *u_hold;%(exps)s
    const stsp_bandqp_t *band_qp; const %(spline_t)s *spline;
    uint32_t crc32; uint8_t problem_sha256[32];
} stsp_table_t;
typedef struct {
    const stsp_table_t *table; uint32_t next_tick; uint16_t stage; uint16_t latched;
    uint16_t sat_mask; ...;
} stsp_ctrl_t;
uint32_t stsp_table_crc32(const stsp_table_t *table);
stsp_status_t stsp_init(stsp_ctrl_t *ctrl, const stsp_table_t *table);
stsp_status_t stsp_init_expect(stsp_ctrl_t *ctrl, const stsp_table_t *table, uint32_t nx,
                               uint32_t nu);
stsp_status_t stsp_reset(stsp_ctrl_t *ctrl);
stsp_status_t stsp_verify(stsp_ctrl_t *ctrl);
stsp_status_t stsp_step(stsp_ctrl_t *ctrl, uint32_t tick, const stsp_scalar_t *x,
                        stsp_scalar_t *u);
const char *stsp_status_str(stsp_status_t status);%(conv)s
const stsp_table_t *harness_table(void);
%(batch)s"""

# Harness-only C: loops over instances so one Python call serves every Monte Carlo path.
BATCH = """
#include <math.h>
/* The plant in this translation unit, so that its step inlines into the tick loop. */
#include "plant.c"
#include "batch.h"
/* One tick of every path, float32 tables only (else STSP_ERR_BAD_DIMS, nothing touched):
 * the controller of path p steps with x = (float)X[p], the plant advances X[p] with the
 * command held (dZ[p]: substeps x mz), and the run's statistics accumulate: saturated ticks
 * per path, the smallest and largest command per input; x_sum is set to the sum of the new
 * states (for the mean path) and u_rec (n_rec x m) to the commands of the first n_rec paths.
 * With faults f (plant.h; NULL: none) the controller measures X[p] + noise, rounded, is not
 * run on a missed tick, and the actuator applies held[p] (the last command, or with a delay
 * the one before it) plus noise; with feed_held (a table designed for the delay) the
 * controller measures [x; held[p]], the command being applied; the statistics count the commands the controllers computed,
 * u_rec the applied ones. Returns the worst status. Inlined into both entry points, so the
 * fault-free one compiles without the fault branches. */
/* 1 when corridor c (n states), the run's corridor k, is tested by the compiled one. */
int harness_corridor_compiled(const harness_corridor_t *c, size_t k, size_t n) {
#if defined(HARNESS_PLANT_SPEC) && CORRIDOR_SPEC_COUNT > 0
    return k < CORRIDOR_SPEC_COUNT && corridor_spec_fits(c, k, n);
#else
    (void)c; (void)k; (void)n;
    return 0;
#endif
}
#ifndef STSP_ARITH_FIXED_POINT
/* The corridor's outputs y = C x (c->p of them) of a state x (n). */
static inline void corridor_outputs(const harness_corridor_t *c, size_t n, const double *x,
                                    double *y) {
    size_t i, j;
    for (i = 0; i < c->p; ++i) {
        double s = 0.0;
        for (j = 0; j < n; ++j) s += c->C[i * n + j] * x[j];
        y[i] = s;
    }
}
/* Whether x (n) is inside corridor c by corridor_wall's rule (a polygon whose largest
 * a y - b is not > 0), without branches on the data: the outcome varies from path to path,
 * and mispredicted branches cost more than the few rows. */
#if defined(__GNUC__)
__attribute__((always_inline))
#endif
static inline int corridor_inside(const harness_corridor_t *c, size_t n, const double *x) {
    double y[32];
    size_t i, j, k, r;
    int inside = 0;
    if (c->p == 2u) {          /* planar corridors: straight-line code, the same sums */
        const double *A = c->A, *b = c->b;
        double y0 = 0.0, y1 = 0.0;
        for (j = 0; j < n; ++j) y0 += c->C[j] * x[j];
        for (j = 0; j < n; ++j) y1 += c->C[n + j] * x[j];
        for (k = 0; k < c->n_poly; ++k) {
            double worst = 0.0;
            for (r = c->row_start[k]; r < c->row_start[k + 1]; ++r) {
                const double e = (-b[r] + A[2u * r] * y0) + A[2u * r + 1u] * y1;
                worst = (r == c->row_start[k] || e > worst) ? e : worst;
            }
            inside |= !(worst > 0.0);
        }
        return inside;
    }
    corridor_outputs(c, n, x, y);
    for (k = 0; k < c->n_poly; ++k) {
        double worst = 0.0;
        for (r = c->row_start[k]; r < c->row_start[k + 1]; ++r) {
            double e = -c->b[r];
            for (i = 0; i < c->p; ++i) e += c->A[r * c->p + i] * y[i];
            worst = (r == c->row_start[k] || e > worst) ? e : worst;
        }
        inside |= !(worst > 0.0);
    }
    return inside;
}
/* corridor_inside, by the corridor compiled into the module when bit i of `fit` says it is
 * corridor i (plant_spec.py: the same outcome). */
#if defined(__GNUC__)
__attribute__((always_inline))
#endif
static inline int corridor_test(uint32_t fit, size_t i, const harness_corridor_t *c, size_t n,
                                const double *x) {
#if defined(HARNESS_PLANT_SPEC) && CORRIDOR_SPEC_COUNT > 0
    if (i < 32u && (fit >> i & 1u) != 0u) return corridor_spec_inside(i, x);
#else
    (void)fit; (void)i;
#endif
    return corridor_inside(c, n, x);
}
/* The wall a state x (n) leaves corridor c through, -1 inside (plant.h's rule). */
static int corridor_wall(const harness_corridor_t *c, size_t n, const double *x) {
    double y[32], best = 0.0;
    size_t i, k, r;
    int wall = -1;
    corridor_outputs(c, n, x, y);
    for (k = 0; k < c->n_poly; ++k) {
        double worst = 0.0;
        int at = -1;
        for (r = c->row_start[k]; r < c->row_start[k + 1]; ++r) {
            double e = -c->b[r];
            for (i = 0; i < c->p; ++i) e += c->A[r * c->p + i] * y[i];
            if (at < 0 || e > worst) { worst = e; at = (int)r; }
        }
        if (!(worst > 0.0)) return -1;             /* inside polygon k */
        if (wall < 0 || worst < best) { best = worst; wall = at; }
    }
    return wall;
}
#endif
#if defined(__GNUC__)
__attribute__((always_inline))
#endif
static inline int tick_paths(stsp_ctrl_t *ctrls, size_t count, uint32_t tick,
                             const harness_plant_t *pl, const double *dZ, double *X,
                             double *cost, int64_t *saturated, double *u_low, double *u_high,
                             double *x_sum, float *u_rec, size_t n_rec,
                             const harness_faults_t *f, const double *sensor_z,
                             const double *actuator_z, const double *miss_u, double *held,
                             const harness_corridor_t *cor, size_t n_cor) {
#ifdef STSP_ARITH_FIXED_POINT
    (void)ctrls; (void)count; (void)tick; (void)pl; (void)dZ; (void)X; (void)cost;
    (void)saturated; (void)u_low; (void)u_high; (void)x_sum; (void)u_rec; (void)n_rec; (void)f;
    (void)sensor_z; (void)actuator_z; (void)miss_u; (void)held; (void)cor; (void)n_cor;
    return (int)STSP_ERR_BAD_DIMS;
#else
    const size_t n = PLANT_N, m = PLANT_M, dz_stride = pl->substeps * pl->mz;
    float xf[STSP_MAX_NX], uf[STSP_MAX_NU];
    /* the statistics in locals (the same sums in the same order): stores through x_sum,
     * u_low and u_high could alias the states, so the compiler would reload them per path */
    double ud[STSP_MAX_NU], sum[STSP_MAX_NX], lo[STSP_MAX_NU], hi[STSP_MAX_NU];
    plant_prep_t pp;
    uint32_t cor_fit = 0u;     /* bit i: corridor i is the module's compiled corridor i */
    size_t p, i;
    int worst = 0;
    if (n + (f != NULL && f->feed_held ? m : 0u) > STSP_MAX_NX || m > STSP_MAX_NU
        || n != pl->n || m != pl->m) {
        return (int)STSP_ERR_BAD_DIMS;
    }
    for (i = 0; i < n_cor; ++i) if (cor[i].p > 32u) return (int)STSP_ERR_BAD_DIMS;
    for (i = 0; i < n; ++i) sum[i] = 0.0;
    for (i = 0; i < m; ++i) { lo[i] = u_low[i]; hi[i] = u_high[i]; }
    plant_prepare(pl, &pp);
#if defined(HARNESS_PLANT_SPEC) && CORRIDOR_SPEC_COUNT > 0
    for (i = 0; i < n_cor && i < CORRIDOR_SPEC_COUNT; ++i) {
        if (corridor_spec_fits(&cor[i], i, n)) cor_fit |= (uint32_t)1u << i;
    }
#endif
    for (p = 0; p < count; ++p) {
        double *x = X + p * n;
        const int run = f == NULL || !(miss_u != NULL && miss_u[p] < f->miss_probability);
        for (i = 0; i < n; ++i) {
            double xm = x[i];
            if (f != NULL && f->sensor_std != NULL) xm += f->sensor_std[i] * sensor_z[p * n + i];
            if (f != NULL && f->quantum != NULL && f->quantum[i] > 0.0) {
                xm = f->quantum[i] * floor(xm / f->quantum[i] + 0.5);
            }
            xf[i] = (float)xm;
        }
        if (f != NULL && f->feed_held) {           /* a table designed for the delay */
            for (i = 0; i < m; ++i) xf[n + i] = (float)held[p * m + i];
        }
        if (f != NULL) for (i = 0; i < m; ++i) ud[i] = held[p * m + i];   /* delayed, missed */
        if (run) {
            const int st = (int)stsp_step(&ctrls[p], tick, xf, uf);
            if (st < worst) worst = st;
            if (st == (int)STSP_WARN_SATURATED) ++saturated[p];
            for (i = 0; i < m; ++i) {
                const double c = (double)uf[i];
                if (c < lo[i]) lo[i] = c;
                if (c > hi[i]) hi[i] = c;
                if (f != NULL) held[p * m + i] = c;
                if (f == NULL || f->delay_ticks == 0) ud[i] = c;
            }
        }
        if (f != NULL && f->actuator_std != NULL) {
            for (i = 0; i < m; ++i) ud[i] += f->actuator_std[i] * actuator_z[p * m + i];
        }
        if (p < n_rec) for (i = 0; i < m; ++i) u_rec[p * m + i] = (float)ud[i];
        cost[p] += plant_step(pl, &pp, ud, dZ + p * dz_stride, x);
        for (i = 0; i < n; ++i) sum[i] += x[i];
        for (i = 0; i < n_cor; ++i) {             /* the state after the tick: tick + 1 */
            const harness_corridor_t *c = &cor[i];
            if (tick + 1u >= c->first && tick + 1u <= c->last && c->exit_tick[p] < 0
                    && !corridor_test(cor_fit, i, c, n, x)) {
                const int w = corridor_wall(c, n, x);
                if (w >= 0) { c->exit_tick[p] = (int32_t)(tick + 1u); c->exit_wall[p] = w; }
            }
        }
    }
    for (i = 0; i < n; ++i) x_sum[i] = sum[i];
    for (i = 0; i < m; ++i) { u_low[i] = lo[i]; u_high[i] = hi[i]; }
    return worst;
#endif
}
int harness_tick(stsp_ctrl_t *ctrls, size_t count, uint32_t tick, const harness_plant_t *pl,
                 const double *dZ, double *X, double *cost, int64_t *saturated,
                 double *u_low, double *u_high, double *x_sum, float *u_rec, size_t n_rec) {
    return tick_paths(ctrls, count, tick, pl, dZ, X, cost, saturated, u_low, u_high, x_sum,
                      u_rec, n_rec, NULL, NULL, NULL, NULL, NULL, NULL, 0u);
}
int harness_tick_faults(stsp_ctrl_t *ctrls, size_t count, uint32_t tick,
                        const harness_plant_t *pl, const double *dZ, double *X, double *cost,
                        int64_t *saturated, double *u_low, double *u_high, double *x_sum,
                        float *u_rec, size_t n_rec, const harness_faults_t *f,
                        const double *sensor_z, const double *actuator_z, const double *miss_u,
                        double *held) {
    if (f == NULL || held == NULL) return (int)STSP_ERR_NULL;
    return tick_paths(ctrls, count, tick, pl, dZ, X, cost, saturated, u_low, u_high, x_sum,
                      u_rec, n_rec, f, sensor_z, actuator_z, miss_u, held, NULL, 0u);
}
/* harness_tick (f NULL) or harness_tick_faults, watching n_cor corridors (plant.h). */
int harness_tick_watch(stsp_ctrl_t *ctrls, size_t count, uint32_t tick,
                       const harness_plant_t *pl, const double *dZ, double *X, double *cost,
                       int64_t *saturated, double *u_low, double *u_high, double *x_sum,
                       float *u_rec, size_t n_rec, const harness_faults_t *f,
                       const double *sensor_z, const double *actuator_z, const double *miss_u,
                       double *held, const harness_corridor_t *cor, size_t n_cor) {
    if ((f != NULL && held == NULL) || (cor == NULL && n_cor > 0u)) return (int)STSP_ERR_NULL;
    if (f == NULL) {            /* its own inlined copy, without the fault branches */
        return tick_paths(ctrls, count, tick, pl, dZ, X, cost, saturated, u_low, u_high, x_sum,
                          u_rec, n_rec, NULL, NULL, NULL, NULL, NULL, cor, n_cor);
    }
    return tick_paths(ctrls, count, tick, pl, dZ, X, cost, saturated, u_low, u_high, x_sum,
                      u_rec, n_rec, f, sensor_z, actuator_z, miss_u, held, cor, n_cor);
}
/* Ticks j0 .. j1 - 1 of `count` paths in one call, without faults: per tick the plant's
 * standard normal numbers into dZ (count x substeps x mz) from the generator `rng`
 * (harness_normals), then harness_tick_watch's work, which leaves the sum of the states in
 * row j + 1 of x_sum ((ticks + 1) x n) and the first n_rec (>= 1) paths' commands in u_rec.
 * Path 0's state and command go to row j + 1 of sample_x and row j of sample_u, and the
 * first n_keep (<= n_rec) paths' states (float) to row j + 1 of rec_x ((ticks + 1) x n_keep
 * x n) and their commands to row j of rec_u (ticks x n_keep x m). Returns the worst status. */
int harness_run_ticks(stsp_ctrl_t *ctrls, size_t count, uint32_t j0, uint32_t j1,
                      const harness_plant_t *pl, uint64_t *rng, double *dZ, double *X,
                      double *cost, int64_t *saturated, double *u_low, double *u_high,
                      double *x_sum, float *u_rec, size_t n_rec,
                      const harness_corridor_t *cor, size_t n_cor, double *sample_x,
                      double *sample_u, float *rec_x, float *rec_u, size_t n_keep) {
    const size_t n = pl->n, m = pl->m, draws = count * pl->substeps * pl->mz;
    uint32_t j;
    size_t i;
    int worst = 0;
    if ((cor == NULL && n_cor > 0u) || n_rec < 1u || n_keep > n_rec) return (int)STSP_ERR_NULL;
    for (j = j0; j < j1; ++j) {
        int st;
        harness_normals(rng, dZ, draws);
        st = tick_paths(ctrls, count, j, pl, dZ, X, cost, saturated, u_low, u_high,
                        x_sum + (size_t)(j + 1u) * n, u_rec, n_rec, NULL, NULL, NULL, NULL,
                        NULL, cor, n_cor);
        if (st < worst) worst = st;
        for (i = 0; i < n; ++i) sample_x[(size_t)(j + 1u) * n + i] = X[i];
        for (i = 0; i < m; ++i) sample_u[(size_t)j * m + i] = (double)u_rec[i];
        for (i = 0; i < n_keep * n; ++i) rec_x[((size_t)(j + 1u) * n_keep) * n + i] = (float)X[i];
        for (i = 0; i < n_keep * m; ++i) rec_u[((size_t)j * n_keep) * m + i] = u_rec[i];
    }
    return worst;
}
/* Verify the table once (the CRC covers every byte), then clone the fresh instance.
 * count == 0 (or NULL ctrls) touches no memory and returns STSP_ERR_NULL: there is no
 * ctrls[0] to initialise. */
int harness_init_batch(stsp_ctrl_t *ctrls, size_t count, const stsp_table_t *table) {
    size_t i; int s;
    if (ctrls == NULL || count == 0u) return (int)STSP_ERR_NULL;
    s = (int)stsp_init(&ctrls[0], table);
    for (i = 1; i < count; ++i) ctrls[i] = ctrls[0];
    return s;
}
int harness_step_batch(stsp_ctrl_t *ctrls, size_t count, uint32_t tick,
                       const stsp_scalar_t *x, stsp_scalar_t *u, int *status) {
    const stsp_table_t *t;
    size_t i, nx, nu; int worst = 0;
    if (ctrls == NULL || count == 0u) return (int)STSP_ERR_NULL;   /* no ctrls[0] to read */
    t = ctrls[0].table;
    nx = t ? t->nx : 0u; nu = t ? t->nu : 0u;
    for (i = 0; i < count; ++i) {
        status[i] = (int)stsp_step(&ctrls[i], tick, x + i * nx, u + i * nu);
        if (status[i] < worst) worst = status[i];
    }
    return worst;
}
/* Sample k: a copy of the fresh instance `proto` latches at t_latch[k] from x_latch[k], then
 * steps tick[k] with x[k]; u[k] and the worse of the two statuses are kept. */
int harness_pair_batch(const stsp_ctrl_t *proto, size_t count, const uint32_t *t_latch,
                       const stsp_scalar_t *x_latch, const uint32_t *tick,
                       const stsp_scalar_t *x, stsp_scalar_t *u, int *status) {
    size_t k, nx, nu; int worst = 0;
    if (proto == NULL || proto->table == NULL) return (int)STSP_ERR_NULL;
    nx = proto->table->nx; nu = proto->table->nu;
    for (k = 0; k < count; ++k) {
        stsp_ctrl_t c = *proto;
        int s1 = (int)stsp_step(&c, t_latch[k], x_latch + k * nx, u + k * nu);
        int s2 = (int)stsp_step(&c, tick[k], x + k * nx, u + k * nu);
        status[k] = (s1 < 0) ? s1 : s2;
        if (status[k] < worst) worst = status[k];
    }
    return worst;
}
"""

# Per variant: C type of stsp_scalar_t, numpy dtype, compile definition.
VARIANTS = {"float32": ("float", np.float32, []),
            "q15": ("int16_t", np.int16, ["-DSTSP_ARITH_Q15"]),
            "q31": ("int32_t", np.int32, ["-DSTSP_ARITH_Q31"])}
_EXPS = "\n    const int8_t *x_exp; const int8_t *u_exp; const int8_t *v_exp;"
_CONV = """
stsp_status_t stsp_state_to_q(const stsp_ctrl_t *ctrl, const stsp_f32_t *x, stsp_scalar_t *x_q);
stsp_status_t stsp_command_to_f32(const stsp_ctrl_t *ctrl, const stsp_scalar_t *u_q,
                                  stsp_f32_t *u);"""


def controller_cdef(arith: str) -> str:
    """The declarations cffi sees for a controller module of arithmetic `arith`."""
    fixed = arith != "float32"
    return CDEF % {"scalar": VARIANTS[arith][0], "exps": _EXPS if fixed else "",
                    "plant": PLANT_CDEF, "batch": BATCH_CDEF,
                    # the spline gains' type of the arithmetic (stsp_table_t.spline)
                    "spline_t": "stsp_qspline_t" if fixed else "stsp_spline_t",
                    "conv": _CONV if fixed else ""}
