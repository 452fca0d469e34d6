/* The last line of a bench image's output (bench_main.c, plan_main.c), which
 * count_instructions.py's trace_calls() reads: the table's shape,
 *     table nx <nx> nu <nu> n_latch <n_latch> stage_n_latch <np0> <np1> ... */
#ifndef BENCH_TABLE_LINE_H
#define BENCH_TABLE_LINE_H

#include <stdint.h>
#include <stdio.h>

#include "stospline/stsp_controller.h"

static void bench_print_table_line(const stsp_table_t *t)
{
    uint32_t i;
    printf("table nx %u nu %u n_latch %u stage_n_latch", (unsigned)t->nx, (unsigned)t->nu,
           (unsigned)t->n_latch);
    for (i = 0u; i < t->n_stages; ++i) {
        printf(" %u", (unsigned)t->stage_n_latch[i]);
    }
    printf("\n");
}

#endif /* BENCH_TABLE_LINE_H */
