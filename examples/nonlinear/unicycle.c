/* The paper's robot as a unicycle: state (x, y, heading, speed), input (acceleration, turn
 * rate). Slip on the speed and on the heading grows with the speed, as the paper's floor noise
 * grows with the velocity: params = (sigma_speed, sigma_heading). */
#include <math.h>

#include "stospline_plant.h"

void stospline_plant_dims(int dims[4])
{
    dims[0] = 4;   /* n: x, y, heading, speed */
    dims[1] = 2;   /* m: acceleration, turn rate */
    dims[2] = 2;   /* mz: speed slip, heading slip */
    dims[3] = 2;   /* params: sigma_speed, sigma_heading */
}

int stospline_plant_drift(double t, const double *x, const double *u, const double *p,
                          double *f)
{
    (void)t;
    (void)p;
    f[0] = x[3] * cos(x[2]);
    f[1] = x[3] * sin(x[2]);
    f[2] = u[1];
    f[3] = u[0];
    return 0;
}

int stospline_plant_diffusion(double t, const double *x, const double *u, const double *p,
                              double *g)
{
    (void)t;
    (void)u;
    g[0] = 0.0; g[1] = 0.0;              /* x */
    g[2] = 0.0; g[3] = 0.0;              /* y */
    g[4] = 0.0; g[5] = p[1] * x[3];      /* heading: dZ_1 */
    g[6] = p[0] * x[3]; g[7] = 0.0;      /* speed: dZ_0 */
    return 0;
}
