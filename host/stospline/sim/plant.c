/* Harness-only plant integrator (not firmware): advance every Monte Carlo path by one tick.
 *
 * With u held over the tick, each of `substeps` steps is the exponential Euler–Maruyama step
 *     x+ = Ad x + Bd u + sum_i x_i G_i dZ,      dZ ~ N(0, dt I)  (supplied by the caller)
 * and the running cost accumulates the left-point rule dt * L(x, u). All in double.
 * The diffusion is passed as its nonzeros: entry e adds w[i] * g_value[e] * dZ[k] to
 * component a, with g_index[3e .. 3e+2] = (i, a, k) and w = [x; u] (state noise i < n,
 * input noise i >= n). */
#include <stddef.h>

void harness_plant_tick(size_t paths, size_t n, size_t m, size_t mz, size_t substeps,
                        double dt, const double *Ad, const double *Bd,
                        size_t g_count, const size_t *g_index, const double *g_value,
                        const double *Q, const double *S, const double *q,
                        const double *R, const double *r, double rho, int state_cost,
                        const double *dZ, const float *U, double *X, double *cost)
{
    size_t p, s, i, j, k;
    (void)mz;
    double x[64], xn[64], u[32];
    if (n > 64u || m > 32u) {
        return;
    }
    for (p = 0; p < paths; ++p) {
        double *xp = X + p * n;
        double c = 0.0, uru = 0.0;
        for (j = 0; j < m; ++j) {
            u[j] = (double)U[p * m + j];
        }
        for (i = 0; i < m; ++i) {
            double acc = 2.0 * r[i];
            for (j = 0; j < m; ++j) {
                acc += R[i * m + j] * u[j];
            }
            uru += acc * u[i];
        }
        c += dt * (double)substeps * (uru + rho);
        for (i = 0; i < n; ++i) {
            x[i] = xp[i];
        }
        for (s = 0; s < substeps; ++s) {
            const double *dz = dZ + (p * substeps + s) * mz;
            double lx = 0.0;
            for (i = 0; i < (state_cost ? n : 0u); ++i) {
                double acc = 2.0 * q[i];
                for (j = 0; j < n; ++j) {
                    acc += Q[i * n + j] * x[j];
                }
                for (j = 0; j < m; ++j) {
                    acc += 2.0 * S[i * m + j] * u[j];
                }
                lx += acc * x[i];
            }
            c += dt * lx;
            for (i = 0; i < n; ++i) {
                double acc = 0.0;
                for (j = 0; j < n; ++j) {
                    acc += Ad[i * n + j] * x[j];
                }
                for (j = 0; j < m; ++j) {
                    acc += Bd[i * m + j] * u[j];
                }
                xn[i] = acc;
            }
            for (k = 0; k < g_count; ++k) {
                const size_t *e = g_index + 3u * k;
                const double w = (e[0] < n) ? x[e[0]] : u[e[0] - n];
                xn[e[1]] += w * g_value[k] * dz[e[2]];
            }
            for (i = 0; i < n; ++i) {
                x[i] = xn[i];
            }
        }
        for (i = 0; i < n; ++i) {
            xp[i] = x[i];
        }
        cost[p] += c;
    }
}
