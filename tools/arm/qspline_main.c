/* Cortex-M image (tools/arm/qspline_bench.py): the fixed-point spline gains of the robot's Q15 or
 * Q31 spline table (qspline_data.c, generated from the host's table) evaluated at every tick by
 * stsp_qspline_gains; an FNV-1a hash of every gain (int32, little-endian, tick by tick) is
 * compared with the host's (stospline.table.spline.fixed_point.evaluate_q). With BENCH_COUNT only the
 * first BENCH_COUNT ticks of each stage, for the instruction count (QEMU -singlestep traces). */
#include <stdint.h>
#include <stdio.h>

#include "stsp_qspline.h"

extern const stsp_qspline_t qspline_robot;
extern const uint32_t qspline_stage_start[];
extern const uint32_t qspline_n_stages;
extern const uint32_t qspline_nu;
extern const uint32_t qspline_nz;
extern const uint32_t qspline_expected_hash;

#define MAX_G 64u

/* The call the count isolates: one tick's gains. */
__attribute__((noinline)) void bench_gains(uint32_t s, uint32_t tau, stsp_scalar_t *g);
__attribute__((noinline)) void bench_gains(uint32_t s, uint32_t tau, stsp_scalar_t *g)
{
    stsp_qspline_gains(&qspline_robot, qspline_stage_start, s, qspline_nu, qspline_nz, tau, g);
}

int main(void)
{
    uint32_t hash = 2166136261u;
    uint32_t calls = 0u;
    uint32_t s;
    if (stsp_qspline_check(&qspline_robot, qspline_stage_start, qspline_n_stages, qspline_nu,
                           qspline_nz) != STSP_OK) {
        (void)printf("qspline: layout refused\n");
        return 1;
    }
    for (s = 0u; s < qspline_n_stages; ++s) {
        uint32_t T = qspline_stage_start[s + 1u] - qspline_stage_start[s];
        uint32_t tau;
#ifdef BENCH_COUNT
        if (T > BENCH_COUNT) {
            T = BENCH_COUNT;
        }
#endif
        for (tau = 0u; tau < T; ++tau) {
            stsp_scalar_t g[MAX_G];
            uint32_t i;
            bench_gains(s, tau, g);
            ++calls;
            for (i = 0u; i < (qspline_nu * qspline_nz); ++i) {
                const uint32_t v = (uint32_t)(int32_t)g[i];
                uint32_t b;
                for (b = 0u; b < 32u; b += 8u) {
                    hash = (hash ^ ((v >> b) & 0xFFu)) * 16777619u;
                }
            }
        }
    }
#ifdef BENCH_COUNT
    {
        /* a sentinel call: the trace's last call also holds whatever of the traced code runs
         * after it (printf and exit call memset), so the count drops it */
        stsp_scalar_t g[MAX_G];
        bench_gains(0u, 0u, g);
    }
#endif
    (void)printf("qspline calls %lu hash %08lx expected %08lx\n", (unsigned long)calls,
                 (unsigned long)hash, (unsigned long)qspline_expected_hash);
#ifdef BENCH_COUNT
    return 0;
#else
    return (hash == qspline_expected_hash) ? 0 : 1;
#endif
}
