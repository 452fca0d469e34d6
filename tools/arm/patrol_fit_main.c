/* A minimal Cortex-M0+ program around the 60 s patrol's spline table (tools/arm/patrol_fit.sh):
 * the controller as an application links it, for the flash it takes with its table. */
#include "robot_patrol_60s_spline.h"
static stsp_ctrl_t ctrl;
volatile float out[2];
int main(void)
{
    float x[4] = {0.0f, 0.0f, 0.0f, 0.0f};
    float u[2];
    uint32_t t;
    if (stsp_init(&ctrl, &robot_patrol_60s_spline_table) != STSP_OK) { return 1; }
    for (t = 0u; t < ROBOT_PATROL_60S_SPLINE_N_TICKS; ++t) {
        (void)stsp_step(&ctrl, t, x, u);
        out[0] = u[0]; out[1] = u[1];
    }
    return 0;
}
