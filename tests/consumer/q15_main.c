/* The Q15 robot alone (q15_robot.c): the reference that two_arith.c's Q15 lines must equal. */
#include "q15_robot.h"

int main(void)
{
    uint32_t tick;
    if (q15_robot_init() != 0) {
        return 1;
    }
    for (tick = 0u; tick < q15_robot_ticks(); ++tick) {
        if (q15_robot_tick(tick, stdout) < 0) {
            return 1;
        }
    }
    return 0;
}
