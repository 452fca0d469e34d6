"""Build the real firmware sources plus generated tables into a cffi module, and load it.

Generate, build and load are separate steps: `generate_c` writes the table sources,
`build_controller` compiles them with ``firmware/src/*.c`` (cached by a hash of everything
that goes into the build), and the returned `CompiledController` steps C instances.
"""
from __future__ import annotations

import re

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from stospline.cache import cached_build, compile_cffi, load_module, source_key
from stospline.firmware_interface import STATUS, check_header
from stospline.harness.plant_spec import plant_source
from stospline.table.codegen import generate_c
from stospline.table.format import GainTable

__all__ = ["build_controller", "CompiledController", "CorridorWatch", "firmware_dir", "STATUS"]


# The plant's interface (plant.h), for cffi: the header itself, without its comments.
_PLANT_H = Path(__file__).with_name("plant.h")
_PLANT_PROTOTYPE = re.sub(r"/\*.*?\*/", "", _PLANT_H.read_text(), flags=re.S)

_CDEF = """%(plant)s
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
int harness_run_ticks(stsp_ctrl_t *ctrls, size_t count, uint32_t j0, uint32_t j1,
                      const harness_plant_t *pl, uint64_t *rng, double *dZ, double *X,
                      double *cost, int64_t *saturated, double *u_low, double *u_high,
                      double *x_sum, float *u_rec, size_t n_rec,
                      const harness_corridor_t *cor, size_t n_cor, double *sample_x,
                      double *sample_u, float *rec_x, float *rec_u, size_t n_keep);
int harness_init_batch(stsp_ctrl_t *ctrls, size_t count, const stsp_table_t *table);
int harness_corridor_compiled(const harness_corridor_t *c, size_t k, size_t n);
int harness_step_batch(stsp_ctrl_t *ctrls, size_t count, uint32_t tick,
                       const stsp_scalar_t *x, stsp_scalar_t *u, int *status);
int harness_pair_batch(const stsp_ctrl_t *proto, size_t count, const uint32_t *t_latch,
                       const stsp_scalar_t *x_latch, const uint32_t *tick,
                       const stsp_scalar_t *x, stsp_scalar_t *u, int *status);
int harness_tick(stsp_ctrl_t *ctrls, size_t count, uint32_t tick, const harness_plant_t *pl,
                 const double *dZ, double *X, double *cost, int64_t *saturated,
                 double *u_low, double *u_high, double *x_sum, float *u_rec, size_t n_rec);
int harness_tick_faults(stsp_ctrl_t *ctrls, size_t count, uint32_t tick,
                        const harness_plant_t *pl, const double *dZ, double *X, double *cost,
                        int64_t *saturated, double *u_low, double *u_high, double *x_sum,
                        float *u_rec, size_t n_rec, const harness_faults_t *f,
                        const double *sensor_z, const double *actuator_z, const double *miss_u,
                        double *held);
int harness_tick_watch(stsp_ctrl_t *ctrls, size_t count, uint32_t tick,
                       const harness_plant_t *pl, const double *dZ, double *X, double *cost,
                       int64_t *saturated, double *u_low, double *u_high, double *x_sum,
                       float *u_rec, size_t n_rec, const harness_faults_t *f,
                       const double *sensor_z, const double *actuator_z, const double *miss_u,
                       double *held, const harness_corridor_t *cor, size_t n_cor);"""

# Harness-only C: loops over instances so one Python call serves every Monte Carlo path.
_BATCH = """
#include <math.h>
/* The plant in this translation unit, so that its step inlines into the tick loop. */
#include "plant.c"
const stsp_table_t *harness_table(void) { return &%(p)s_table; }
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
    for (i = 0; i < c->p; ++i) {
        double s = 0.0;
        for (j = 0; j < n; ++j) s += c->C[i * n + j] * x[j];
        y[i] = s;
    }
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
    size_t i, j, k, r;
    int wall = -1;
    for (i = 0; i < c->p; ++i) {
        double s = 0.0;
        for (j = 0; j < n; ++j) s += c->C[i * n + j] * x[j];
        y[i] = s;
    }
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
    double ud[STSP_MAX_NU];
    plant_prep_t pp;
    uint32_t cor_fit = 0u;     /* bit i: corridor i is the module's compiled corridor i */
    size_t p, i;
    int worst = 0;
    if (n + (f != NULL && f->feed_held ? m : 0u) > STSP_MAX_NX || m > STSP_MAX_NU
        || n != pl->n || m != pl->m) {
        return (int)STSP_ERR_BAD_DIMS;
    }
    for (i = 0; i < n_cor; ++i) if (cor[i].p > 32u) return (int)STSP_ERR_BAD_DIMS;
    for (i = 0; i < n; ++i) x_sum[i] = 0.0;
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
                if (c < u_low[i]) u_low[i] = c;
                if (c > u_high[i]) u_high[i] = c;
                if (f != NULL) held[p * m + i] = c;
                if (f == NULL || f->delay_ticks == 0) ud[i] = c;
            }
        }
        if (f != NULL && f->actuator_std != NULL) {
            for (i = 0; i < m; ++i) ud[i] += f->actuator_std[i] * actuator_z[p * m + i];
        }
        if (p < n_rec) for (i = 0; i < m; ++i) u_rec[p * m + i] = (float)ud[i];
        cost[p] += plant_step(pl, &pp, ud, dZ + p * dz_stride, x);
        for (i = 0; i < n; ++i) x_sum[i] += x[i];
        for (i = 0; i < n_cor; ++i) {             /* the state after the tick: tick + 1 */
            const harness_corridor_t *c = &cor[i];
            if (tick + 1u >= c->first && tick + 1u <= c->last && c->exit_tick[p] < 0
                    && !corridor_test(cor_fit, i, c, n, x)) {
                const int w = corridor_wall(c, n, x);
                if (w >= 0) { c->exit_tick[p] = (int32_t)(tick + 1u); c->exit_wall[p] = w; }
            }
        }
    }
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


def _cdef(arith: str) -> str:
    fixed = arith != "float32"
    return _CDEF % {"scalar": VARIANTS[arith][0], "exps": _EXPS if fixed else "",
                    "plant": _PLANT_PROTOTYPE,
                    # the spline gains' type of the arithmetic (stsp_table_t.spline)
                    "spline_t": "stsp_qspline_t" if fixed else "stsp_spline_t",
                    "conv": _CONV if fixed else ""}

# -O3 as the host CMake build (Release); ISO C keeps floating-point contraction off, so the
# bits are those of any other build. Without the vectorizers: they moved the plant's small
# fixed-size state through the stack in 16-byte pieces written as 8-byte ones (a failed
# store-to-load forwarding per path, a third of the plant's time); they reorder no sums.
_CFLAGS = ["-std=c99", "-O3", "-fno-tree-slp-vectorize", "-fno-tree-loop-vectorize", "-Wall",
           "-Wextra", "-DSTSP_HOST_MESSAGES"]


def firmware_dir() -> Path:
    """The firmware source tree compiled by the harness (``STOSPLINE_FIRMWARE`` overrides;
    `stospline.firmware_files`)."""
    from stospline.firmware_files import firmware_dir as find
    return find()


def _positive_count(count) -> int:
    """`count` as an int >= 1 (instances to allocate); ValueError otherwise."""
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 1:
        raise ValueError(f"the number of controller instances must be an integer >= 1, "
                         f"got {count!r}")
    return int(count)


@dataclass
class CompiledController:
    """A compiled firmware + table module, with helpers to run many instances at once."""
    ffi: object
    lib: object
    table: GainTable
    plant_source: str | None = None     # the plant step compiled in (`plant_spec`), if any
    fixed_shape: bool = True

    def for_plant(self, problem) -> "CompiledController":
        """This controller in a module whose plant step is compiled for `problem`
        (`build_controller`'s `plant`): itself when it already is."""
        spec = plant_source(problem, self.table.tick_hz)
        if spec is None or spec == self.plant_source:
            return self
        return build_controller(self.table, fixed_shape=self.fixed_shape, plant=problem)

    @property
    def arith(self) -> str:
        return getattr(self.table, "arith", "float32")

    @property
    def dtype(self):
        """numpy type of x, u and the tables: float32, int16 (Q15) or int32 (Q31)."""
        return VARIANTS[self.arith][1]

    @property
    def c_table(self):
        return self.lib.harness_table()

    def new_instances(self, count: int):
        """`count` instances initialised on the compiled table (raises on a negative status).

        Raises ValueError unless ``count >= 1``: the C helper clones instance 0, and a
        zero-length array has none."""
        count = _positive_count(count)
        ctrls = self.ffi.new("stsp_ctrl_t[]", count)
        worst = self.lib.harness_init_batch(ctrls, count, self.c_table)
        if worst < 0:
            raise RuntimeError(f"stsp_init failed: {self.status_str(worst)}")
        return ctrls

    def status_str(self, status: int) -> str:
        return self.ffi.string(self.lib.stsp_status_str(status)).decode()

    def stepper(self, count: int):
        """Return ``step(tick, X) -> (U, status)`` driving `count` (>= 1) fresh instances."""
        count = _positive_count(count)
        n, m, _ = self.table.dims
        ctrls = self.new_instances(count)
        xbuf = np.zeros((count, n), dtype=self.dtype)
        ubuf = np.zeros((count, m), dtype=self.dtype)
        sbuf = np.zeros(count, dtype=np.intc)
        ffi, lib = self.ffi, self.lib
        px = ffi.cast("const stsp_scalar_t *", ffi.from_buffer(xbuf))
        pu = ffi.cast("stsp_scalar_t *", ffi.from_buffer(ubuf))
        ps = ffi.cast("int *", ffi.from_buffer(sbuf))

        def step(tick: int, X: np.ndarray):
            np.copyto(xbuf, X, casting="same_kind")
            lib.harness_step_batch(ctrls, count, tick, px, pu, ps)
            return ubuf, sbuf

        step.instances = ctrls
        return step

    def real_stepper(self, count: int):
        """``step(tick, X) -> (U, status)`` with real states X (float64, (count, n)) and real
        commands U (float32, (count, m)) whatever the table's arithmetic: `stepper` for a
        float32 table; for a Q15/Q31 one, X rounded half up to its Q format and saturated at
        the Q range (as a quantizing sensor would deliver it) and the integer commands times
        their LSB (exact in float32 for Q15, rounded to it for Q31). The Monte Carlo harness
        runs fixed-point tables through this."""
        step = self.stepper(count)
        if self.arith == "float32":
            return step
        t = self.table
        F = t.frac_bits
        to_q = np.ldexp(1.0, F - np.asarray(t.x_exp, dtype=int))
        lsb = np.asarray(t.u_lsb, dtype=float)
        lo, hi = -(1 << F), (1 << F) - 1

        def real(tick: int, X: np.ndarray):
            Xq = np.clip(np.floor(np.asarray(X, dtype=float) * to_q + 0.5), lo, hi)
            U, status = step(tick, Xq.astype(self.dtype))
            return (U * lsb).astype(np.float32), status

        real.instances = step.instances
        return real

    def pair_steps(self, t_latch, x_latch, tick, x):
        """For each sample k, a fresh instance latches at ``t_latch[k]`` from ``x_latch[k]``
        and is then stepped at ``tick[k]`` with ``x[k]``: returns ``(U, status)``."""
        n, m, _ = self.table.dims
        ffi = self.ffi
        proto = self.new_instances(1)
        arrs = [np.ascontiguousarray(t_latch, np.uint32),
                np.ascontiguousarray(x_latch, self.dtype).reshape(-1, n),
                np.ascontiguousarray(tick, np.uint32),
                np.ascontiguousarray(x, self.dtype).reshape(-1, n)]
        count = len(arrs[0])
        for name, a in zip(("x_latch", "tick", "x"), arrs[1:]):
            if len(a) != count:
                raise ValueError(f"pair_steps: {name} has {len(a)} samples, t_latch {count}")
        U = np.zeros((count, m), dtype=self.dtype)
        status = np.zeros(count, dtype=np.intc)
        self.lib.harness_pair_batch(
            proto, count, ffi.cast("const uint32_t *", ffi.from_buffer(arrs[0])),
            ffi.cast("const stsp_scalar_t *", ffi.from_buffer(arrs[1])),
            ffi.cast("const uint32_t *", ffi.from_buffer(arrs[2])),
            ffi.cast("const stsp_scalar_t *", ffi.from_buffer(arrs[3])),
            ffi.cast("stsp_scalar_t *", ffi.from_buffer(U)),
            ffi.cast("int *", ffi.from_buffer(status)))
        return U, status

    def normals(self, seed: np.random.SeedSequence):
        """``into(out) -> fill()``: a generator of standard normal numbers in C
        (``harness_normals``) seeded by `seed` (its first four 64-bit words); ``fill()``
        refills the float64 array `out` (bound once, so a tick pays one C call)."""
        state = np.ascontiguousarray(seed.generate_state(4, np.uint64))
        if not state.any():
            state[0] = 1                       # xoshiro's one forbidden state
        ffi, lib = self.ffi, self.lib
        pstate = ffi.from_buffer("uint64_t[]", state)

        def into(out: np.ndarray):
            if out.dtype != np.float64 or not out.flags.c_contiguous:
                raise ValueError("normals: out must be a C-contiguous float64 array")
            pout, size = ffi.from_buffer("double[]", out), out.size

            def fill() -> None:
                lib.harness_normals(pstate, pout, size)

            fill.keep = (state, out)
            return fill

        into.state = state                     # the generator's words (`runner` draws too)
        return into

    def runner(self, ctrls, count: int, normals, dZ: np.ndarray, X: np.ndarray,
               cost: np.ndarray, stats: "TickStats", watch: "CorridorWatch | None",
               x_sum: np.ndarray, sample_x: np.ndarray, sample_u: np.ndarray,
               record_x: np.ndarray | None, record_u: np.ndarray | None):
        """``run(j0, j1, plant) -> worst status``: ticks j0 .. j1 - 1 of `count` paths in one
        C call (``harness_run_ticks``; float32 tables, no faults): per tick the plant's
        normal numbers from `normals` (a `normals` generator) into dZ, then what a `ticker`
        tick does, the state sum written to row j + 1 of `x_sum`, path 0 to `sample_x` and
        `sample_u`, the first ``record_x.shape[1]`` paths to `record_x` and `record_u`."""
        ffi, lib = self.ffi, self.lib

        def buf(a, kind="double[]"):
            return ffi.NULL if a is None else ffi.from_buffer(kind, a)

        keep = [normals.state, dZ, X, cost, stats, x_sum, sample_x, sample_u, record_x,
                record_u]
        cors = watch.c_structs(ffi) if watch is not None else (ffi.NULL, None)
        keep.append(cors)
        args = [ffi.from_buffer("uint64_t[]", normals.state), buf(dZ), buf(X), buf(cost),
                ffi.cast("int64_t *", ffi.from_buffer(stats.saturated)),
                buf(stats.u_low), buf(stats.u_high), buf(x_sum),
                buf(stats.u_rec, "float[]"), len(stats.u_rec), cors[0],
                0 if watch is None else len(watch.corridors), buf(sample_x), buf(sample_u),
                buf(record_x, "float[]"), buf(record_u, "float[]"),
                0 if record_x is None else record_x.shape[1]]

        def run(j0: int, j1: int, plant) -> int:
            return lib.harness_run_ticks(ctrls, count, j0, j1, plant.c, *args)

        run.keep = keep
        return run

    def plant(self, stage, Ad, Bd, fd, dt: float, substeps: int):
        """The plant of one stage for `plant_tick`/`tick` (a ``harness_plant_t`` that keeps
        its arrays alive): step matrices Ad, Bd and drift fd (None: none) over dt, `substeps`
        steps per tick."""
        ffi = self.ffi
        GH = stage.noise_tensor                              # multipliers [x; u]
        nz = np.argwhere(GH != 0)                            # rows (i, a, k)
        keep = [np.ascontiguousarray(nz, dtype=np.uintp),
                np.ascontiguousarray(GH[tuple(nz.T)], dtype=float)]
        keep += [np.ascontiguousarray(a, dtype=float) for a in
                 (Ad, Bd, stage.Q, stage.S, stage.q, stage.R, stage.r)]
        n, m = stage.B.shape
        pl = ffi.new("harness_plant_t *")
        pl.n, pl.m, pl.mz, pl.substeps, pl.dt = n, m, stage.G.shape[2], substeps, dt
        pl.dz_scale = float(np.sqrt(dt))
        pl.g_count = len(keep[1])
        pl.g_index = ffi.cast("const size_t *", ffi.from_buffer(keep[0]))
        pl.g_value, pl.Ad, pl.Bd, pl.Q, pl.S, pl.q, pl.R, pl.r = (
            ffi.cast("const double *", ffi.from_buffer(a)) for a in keep[1:])
        pl.rho = float(stage.rho)
        pl.state_cost = int(bool(np.any(stage.Q) or np.any(stage.S) or np.any(stage.q)))
        if fd is None:
            pl.fd = ffi.NULL
        else:
            keep.append(np.ascontiguousarray(fd, dtype=float))
            pl.fd = ffi.cast("const double *", ffi.from_buffer(keep[-1]))
        return _Plant(pl, keep)

    def plant_tick(self, plant, dZ: np.ndarray, U: np.ndarray, X: np.ndarray,
                   cost: np.ndarray) -> None:
        """Advance X (paths, n) in place by one tick of the C plant integrator; dZ (paths,
        substeps, mz) holds standard normal numbers (scaled by sqrt(dt) in C)."""
        ffi = self.ffi
        assert X.flags.c_contiguous and X.dtype == np.float64 and U.dtype == np.float32
        self.lib.harness_plant_tick(plant.c, X.shape[0], ffi.from_buffer("double[]", dZ),
                                    ffi.from_buffer("float[]", U),
                                    ffi.from_buffer("double[]", X),
                                    ffi.from_buffer("double[]", cost))

    def ticker(self, ctrls, count: int, dZ: np.ndarray, X: np.ndarray, cost: np.ndarray,
               stats: "TickStats", faults: "FaultDraws | None" = None,
               watch: "CorridorWatch | None" = None):
        """``tick(j, plant) -> worst status``: one tick of `count` paths in one C call (float32
        tables): the controllers `ctrls` step from X, the plant advances X with dZ, the cost
        and `stats` (`TickStats`) accumulate. With `faults` (``harness_tick_faults``), the
        fault levels, the arrays the caller refills with each tick's random numbers and the
        actuator's held commands. With `watch` (``harness_tick_watch``), each path's first
        exit from the corridors (`CorridorWatch`). The arrays are bound once, here."""
        ffi, lib = self.ffi, self.lib

        def buf(a, kind="double[]"):
            return ffi.NULL if a is None else ffi.from_buffer(kind, a)

        keep = [dZ, X, cost, stats, faults]
        args = [buf(dZ), buf(X), buf(cost),
                ffi.cast("int64_t *", ffi.from_buffer(stats.saturated)),
                buf(stats.u_low), buf(stats.u_high), buf(stats.x_sum),
                buf(stats.u_rec, "float[]"), len(stats.u_rec)]
        step = lib.harness_tick
        if faults is not None:
            f = ffi.new("harness_faults_t *")
            levels = [buf(faults.sensor_std), buf(faults.quantum), buf(faults.actuator_std)]
            f.sensor_std, f.quantum, f.actuator_std = levels
            f.miss_probability = faults.miss_probability
            f.delay_ticks = faults.delay_ticks
            f.feed_held = faults.feed_held
            keep += [f, levels]
            args += [f, buf(faults.sensor_z), buf(faults.actuator_z), buf(faults.miss_u),
                     buf(faults.held)]
            step = lib.harness_tick_faults
        if watch is not None:
            if faults is None:
                args += [ffi.NULL] * 5
            cors = watch.c_structs(ffi)
            keep.append(cors)
            args += [cors[0], len(watch.corridors)]
            step = lib.harness_tick_watch

        def tick(j: int, plant) -> int:
            return step(ctrls, count, j, plant.c, *args)

        tick.keep = keep
        return tick


@dataclass
class _Plant:
    c: object         # harness_plant_t *
    keep: list        # the arrays it points into


@dataclass
class FaultDraws:
    """The faults of a block of paths for `CompiledController.fault_ticker`: levels (None: no
    such fault), the per-tick random numbers (refilled by `draw`) and the actuator's held
    commands."""
    sensor_std: np.ndarray | None
    quantum: np.ndarray | None
    actuator_std: np.ndarray | None
    miss_probability: float
    delay_ticks: int
    feed_held: int                   # 1: a table designed for the delay (`GainTable`)
    sensor_z: np.ndarray | None      # (paths, n) standard normal
    actuator_z: np.ndarray | None    # (paths, m) standard normal
    miss_u: np.ndarray | None        # (paths,) uniform in [0, 1)
    held: np.ndarray                 # (paths, m)

    @classmethod
    def of(cls, faults, paths: int, n: int, hold: np.ndarray,
           table_delay: int = 0) -> "FaultDraws":
        """The draws of `faults` for `paths` paths of n states; the actuator of every path
        starts on the safe command `hold` (m,). `table_delay` 1: the table is designed for a
        one-tick delay, so the loop has one (its controller also measures the held command);
        a delay fault on top of it is refused (ValueError)."""
        if table_delay and faults.delay_ticks:
            raise ValueError("a table designed for a one-tick delay runs with that delay; a "
                             "delay fault on top of it is not simulated")
        m = len(hold)

        def vec(a):
            return np.ascontiguousarray(a, dtype=float) if np.any(a) else None
        sensor, quantum, actuator = (vec(faults.sensor_noise), vec(faults.sensor_quantum),
                                     vec(faults.actuator_noise))
        return cls(sensor, quantum, actuator, float(faults.miss_probability),
                   int(faults.delay_ticks) or int(table_delay), int(table_delay),
                   np.empty((paths, n)) if sensor is not None else None,
                   np.empty((paths, m)) if actuator is not None else None,
                   np.empty(paths) if faults.miss_probability > 0 else None,
                   np.tile(np.asarray(hold, dtype=float), (paths, 1)))

    def draw(self, rng: np.random.Generator) -> None:
        """This tick's numbers, from the faults' own stream `rng`."""
        if self.sensor_z is not None:
            rng.standard_normal(out=self.sensor_z)
        if self.actuator_z is not None:
            rng.standard_normal(out=self.actuator_z)
        if self.miss_u is not None:
            rng.random(out=self.miss_u)


@dataclass
class CorridorWatch:
    """Each path's first exit from each corridor (`stospline.problem.corridors`): the state
    tick (``exit_tick``, corridors x paths, -1: never) and the wall (``exit_wall``). The C
    tick (``harness_tick_watch``) fills them; `check` does the same in numpy, for the tick-0
    state and for runs that step the plant outside that C call."""
    corridors: tuple
    ticks: list                    # (first, last) state tick per corridor
    exit_tick: np.ndarray          # (corridors, paths) int32
    exit_wall: np.ndarray

    @classmethod
    def of(cls, corridors, paths: int, t0: float, tick_hz: int) -> "CorridorWatch":
        from stospline.problem.corridors import corridor_ticks
        k = len(corridors)
        return cls(tuple(corridors), [corridor_ticks(c, t0, tick_hz) for c in corridors],
                   np.full((k, paths), -1, np.int32), np.full((k, paths), -1, np.int32))

    def check(self, state_tick: int, X: np.ndarray) -> None:
        """Record the paths that are outside at `state_tick` (states X) for the first time."""
        for i, (c, (lo, hi)) in enumerate(zip(self.corridors, self.ticks)):
            if lo <= state_tick <= hi:
                fresh = self.exit_tick[i] < 0
                wall = c.exit_wall(X[fresh] @ c.C.T)
                idx = np.flatnonzero(fresh)[wall >= 0]
                self.exit_tick[i, idx] = state_tick
                self.exit_wall[i, idx] = wall[wall >= 0]

    def c_structs(self, ffi):
        """``(harness_corridor_t[], arrays they point into)`` for the C tick."""
        cors = ffi.new("harness_corridor_t[]", len(self.corridors))
        keep = []

        def ptr(a, kind):
            keep.append(a)
            return ffi.cast(kind, ffi.from_buffer(a))
        for i, c in enumerate(self.corridors):
            A, b = c.unit_walls()
            cs = cors[i]
            cs.first, cs.last = self.ticks[i]
            cs.p, cs.n_poly = c.p, len(c.polygons)
            cs.C = ptr(np.ascontiguousarray(c.C, dtype=float), "const double *")
            cs.row_start = ptr(np.ascontiguousarray(c.row_start, dtype=np.uintp),
                               "const size_t *")
            cs.A = ptr(A, "const double *")
            cs.b = ptr(b, "const double *")
            cs.exit_tick = ptr(self.exit_tick[i], "int32_t *")
            cs.exit_wall = ptr(self.exit_wall[i], "int32_t *")
        return cors, keep


@dataclass
class TickStats:
    """What a `CompiledController.ticker` tick accumulates (saturated ticks per path, the
    extreme commands per input) and writes (the sum of the states after the tick, the
    commands applied to the first ``len(u_rec)`` paths)."""
    saturated: np.ndarray
    u_low: np.ndarray
    u_high: np.ndarray
    x_sum: np.ndarray
    u_rec: np.ndarray           # (recorded paths >= 1, m) float32

    @classmethod
    def zeros(cls, paths: int, n: int, m: int, record: int = 1) -> "TickStats":
        return cls(np.zeros(paths, np.int64), np.full(m, np.inf), np.full(m, -np.inf),
                   np.zeros(n), np.zeros((max(1, min(record, paths)), m), np.float32))


# The generated C of recent tables: writing every gain as a shortest float32 literal takes
# about 0.2 s per 100 000 entries, and a run builds the same table's controller more than
# once (the substep pilot, then the run). Keyed by the table object's id; the entry holds the
# table, so the id cannot be reused while cached.
_SOURCES: dict = {}


def _table_sources(table) -> tuple[str, str]:
    hit = _SOURCES.get(id(table))
    if hit is not None and hit[0] is table:
        return hit[1]
    if len(_SOURCES) >= 4:
        _SOURCES.clear()
    text = generate_c(table)
    _SOURCES[id(table)] = (table, text)
    return text


def build_controller(table: GainTable, *, build_dir: str | Path | None = None,
                     quiet: bool = True, fixed_shape: bool = True,
                     plant=None) -> CompiledController:
    """Compile ``firmware/src/*.c`` with the table's generated C into a cffi module and load it.

    Builds are cached in `build_dir` (default: `stospline.cache.cache_root`) under a hash of
    every input (sources, flags, table), built atomically (`stospline.cache.cached_build`).

    Parameters
    ----------
    table : GainTable or FixedPointTable
        The firmware is compiled for the table's arithmetic.
    build_dir : str or Path, optional
    quiet : bool
        Hide the compiler's output.
    fixed_shape : bool
        True (default): the firmware's fixed-shape build for the table's dimensions
        (``STSP_FIXED_NX/NU/N_LATCH``, the fastest; it refuses a table of another shape).
        False: the generic build, which takes any table within the ``STSP_MAX_*`` limits.
        Both compute the same bits.
    plant : Problem, optional
        The plant the Monte Carlo harness will run: its step is compiled for it
        (`stospline.harness.plant_spec`: its zero and unit coefficients and noise entries
        built in), the same bits as the generic step, which still serves any other plant.

    Returns
    -------
    CompiledController
        ``stepper(count)`` gives ``step(tick, X) -> (U, status)`` over `count` instances of
        the real ``stsp_step``.

    Examples
    --------
    >>> import numpy as np, stospline
    >>> p = stospline.load_problem("examples/robot_corridor.toml")
    >>> ctl = stospline.build_controller(stospline.design_problem(p).table)
    >>> step = ctl.stepper(1)                      # one controller instance
    >>> u, status = step(0, p.x0[None, :].astype(np.float32))
    >>> u.shape, ctl.status_str(int(status[0]))    # the t0 tick latches and commands
    ((1, 2), 'ok')
    """
    header, source = _table_sources(table)
    arith = getattr(table, "arith", "float32")
    # The module serves this one table: its dimensions are compile-time constants of the
    # plant (HARNESS_N/M) and, by default, of the controller (the firmware's fixed-shape build,
    # which computes the same bits as the generic one; both are tested by ctest and QEMU).
    n, m, n_latch = table.dims
    cdef = _cdef(arith)
    n_plant = n - m * getattr(table, "delay_ticks", 0)   # a delayed law also measures u
    cflags = _CFLAGS + VARIANTS[arith][2] + [f"-DHARNESS_N={n_plant}", f"-DHARNESS_M={m}"]
    if fixed_shape:
        cflags += [f"-DSTSP_FIXED_NX={n}u", f"-DSTSP_FIXED_NU={m}u",
                   f"-DSTSP_FIXED_N_LATCH={n_latch}u"]
    spec = None if plant is None else plant_source(plant, table.tick_hz)
    if spec is not None:
        cflags.append("-DHARNESS_PLANT_SPEC")
    fw = firmware_dir()
    check_header(fw / "include")   # the shared constants are still the header's
    fw_sources = sorted((fw / "src").glob("*.c"))
    here = Path(__file__).parent
    harness = [here / "normals.c"]      # the harness's own C (plant.c: included by _BATCH)
    key = source_key([header, source, cdef, _BATCH, " ".join(cflags), spec or ""]
                     + [p.read_bytes() for p in sorted(fw.rglob("*.[ch]")) + harness
                        + [_PLANT_H, here / "plant.c", here / "ziggurat_tables.h"]])
    modname = f"_stsp_{table.name}_{key}"

    def build(out: Path) -> Path:
        (out / f"{table.name}.h").write_text(header)
        (out / f"{table.name}.c").write_text(source)
        if spec is not None:
            (out / "plant_spec.h").write_text(spec)
        return compile_cffi(
            out, modname, cdef,
            f'#include "stospline/stsp_controller.h"\n#include "{table.name}.h"\n'
            + _BATCH % {"p": table.name},
            sources=[*fw_sources, out / f"{table.name}.c", *harness],
            include_dirs=[fw / "include", fw / "src", out, here], cflags=cflags,
            quiet=quiet)

    mod = load_module(cached_build(key, modname, build, root=build_dir))
    return CompiledController(mod.ffi, mod.lib, table, spec, fixed_shape)
