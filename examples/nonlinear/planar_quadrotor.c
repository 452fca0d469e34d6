/* A planar quadrotor: state (x, z, pitch, x rate, z rate, pitch rate, s), input (thrust T,
 * torque tau); params = (mass, inertia, gravity, sigma_thrust, sigma_torque).
 *
 *     x'' = -(T/m) sin(pitch),   z'' = (T/m) cos(pitch) - gravity,   pitch'' = tau / I
 *
 * The thrust's error is proportional to the thrust and acts along the body axis
 * (sigma_thrust T dZ_0); the rotors' mismatch turns a share of the thrust into a torque error
 * (sigma_torque T dZ_1). The linear model's noise is a sum of terms proportional to x or u
 * (plant-model.md), so the diffusion is written homogeneous of degree 1 in (x, u),
 * g(c x, c u) = c g(x, u): s is a state held at 1 and the body axis is taken at pitch / s. On
 * the plant s stays exactly 1, and the diffusion is the one above. */
#include <math.h>

#include "stospline_plant.h"

void stospline_plant_dims(int dims[4])
{
    dims[0] = 7;   /* n: x, z, pitch, their rates, s = 1 */
    dims[1] = 2;   /* m: thrust (N), torque (N m) */
    dims[2] = 2;   /* mz: thrust error, torque error */
    dims[3] = 5;   /* params: mass, inertia, gravity, sigma_thrust, sigma_torque */
}

int stospline_plant_drift(double t, const double *x, const double *u, const double *p,
                          double *f)
{
    (void)t;
    f[0] = x[3];
    f[1] = x[4];
    f[2] = x[5];
    f[3] = -u[0] / p[0] * sin(x[2]);
    f[4] = u[0] / p[0] * cos(x[2]) - p[2];
    f[5] = u[1] / p[1];
    f[6] = 0.0;
    return 0;
}

int stospline_plant_diffusion(double t, const double *x, const double *u, const double *p,
                              double *g)
{
    double axis;
    int i;
    (void)t;
    if (x[6] <= 0.0)
        return 1;                        /* s is 1 on every path the design asks for */
    for (i = 0; i < 14; i++)
        g[i] = 0.0;
    axis = x[2] / x[6];
    g[3 * 2 + 0] = -p[3] * u[0] / p[0] * sin(axis);     /* x rate: dZ_0 */
    g[4 * 2 + 0] = p[3] * u[0] / p[0] * cos(axis);      /* z rate: dZ_0 */
    g[5 * 2 + 1] = p[4] * u[0] / p[1];                  /* pitch rate: dZ_1 */
    return 0;
}
