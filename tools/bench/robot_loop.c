/* A hand-written closed loop of the robot corridor (examples/robot_corridor.toml), the
 * baseline of tools/bench/harness_throughput.py: the work the harness does per path and
 * tick, written directly for this one problem, with nothing general.
 *
 * Per tick j, for every path of the block: at a stage start latch v = Lambda_s x + lambda0_s,
 * then the float32 law u = -(K_j x + k0_j + L_j v) (x rounded to float), the running cost
 * h u'u (R = I), and one exact zero-order-hold step of the two double integrators with the
 * velocity noise vel += vel * sqrt(h) * z (z standard normal, two per path and tick, from
 * the harness's generator, normals.c, drawn per tick into a buffer; with draw == 0 the
 * buffer stays zero: the loop without the cost of normal numbers). The sum of the states
 * after each tick is kept, as the harness keeps it for the mean path. Tables as
 * stsp_table_t lays them out: K, L (ticks x 2 x 4), k0 (ticks x 2), Lambda (stages x 4 x 4),
 * lambda0 (stages x 4). */
#include <math.h>
#include <stddef.h>
#include <stdint.h>

void harness_normals(uint64_t *state, double *out, size_t count);

void robot_loop(const float *K, const float *k0, const float *L, const float *Lambda,
                const float *lambda0, const uint32_t *stage_start, uint32_t n_stages,
                double h, size_t paths, uint64_t *rng, int draw, double *z, double *X,
                float *V, double *cost, double *x_sum)
{
    const double sq = sqrt(h), hh = 0.5 * h * h;
    uint32_t s, j;
    size_t p;
    int i, k;
    for (s = 0; s < n_stages; ++s) {
        for (j = stage_start[s]; j < stage_start[s + 1]; ++j) {
            const float *Kj = K + (size_t)j * 8u, *Lj = L + (size_t)j * 8u, *k0j = k0 + 2u * j;
            double sum[4] = {0.0, 0.0, 0.0, 0.0};
            if (draw) harness_normals(rng, z, 2u * paths);
            for (p = 0; p < paths; ++p) {
                double *x = X + 4u * p;
                float *v = V + 4u * p;
                float xf[4], u[2];
                for (i = 0; i < 4; ++i) xf[i] = (float)x[i];
                if (j == stage_start[s]) {
                    const float *Ls = Lambda + 16u * s;
                    for (k = 0; k < 4; ++k) {
                        float a = lambda0[4u * s + (unsigned)k];
                        for (i = 0; i < 4; ++i) a += Ls[4 * k + i] * xf[i];
                        v[k] = a;
                    }
                }
                for (k = 0; k < 2; ++k) {
                    float a = k0j[k];
                    for (i = 0; i < 4; ++i) a += Kj[4 * k + i] * xf[i] + Lj[4 * k + i] * v[i];
                    u[k] = -a;
                }
                cost[p] += h * ((double)u[0] * u[0] + (double)u[1] * u[1]);
                {
                    const double ux = u[0], uy = u[1], vx = x[1], vy = x[3];
                    x[0] += h * vx + hh * ux;
                    x[1] = vx + h * ux + vx * sq * z[2u * p];
                    x[2] += h * vy + hh * uy;
                    x[3] = vy + h * uy + vy * sq * z[2u * p + 1u];
                }
                for (i = 0; i < 4; ++i) sum[i] += x[i];
            }
            for (i = 0; i < 4; ++i) x_sum[4u * (j + 1u) + (unsigned)i] = sum[i];
        }
    }
}
