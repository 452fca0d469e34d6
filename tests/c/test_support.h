/* Helpers shared by the cmocka unit tests: include after <cmocka.h> and
 * "stospline/stsp_controller.h". */
#ifndef STSP_TEST_SUPPORT_H
#define STSP_TEST_SUPPORT_H

#include <stdlib.h>
#include <string.h>

/* The bit pattern of a binary32, to compare commands exactly (NaN and signed zeros too). */
static inline uint32_t f32_bits(float value)
{
    uint32_t bits;
    memcpy(&bits, &value, sizeof bits);
    return bits;
}

/* A table header of this build's arithmetic and these dimensions, every array NULL: the
 * caller sets the arrays it has, then the CRC. */
static inline stsp_table_t table_header(uint16_t nx, uint16_t nu, uint16_t n_latch,
                                        uint16_t n_stages, uint32_t n_ticks, uint32_t tick_hz)
{
    stsp_table_t t;
    memset(&t, 0, sizeof t);
    t.magic = STSP_TABLE_MAGIC;
    t.format_version = STSP_FORMAT_VERSION;
    t.scalar_kind = STSP_SCALAR_KIND;
    t.nx = nx;
    t.nu = nu;
    t.n_latch = n_latch;
    t.n_stages = n_stages;
    t.n_ticks = n_ticks;
    t.tick_hz = tick_hz;
    return t;
}

/* Heap blocks of exactly the size asked. The unit tests are compiled without ASan (only the
 * controller of the _san builds is instrumented), so their own stack and static arrays have no
 * red zones; a block from ASan's malloc has, so a read or write by the controller beyond one
 * of these aborts the _san builds. */
static inline void *heap_copy(const void *src, size_t size)
{
    void *p = malloc((size > 0u) ? size : 1u);
    assert_non_null(p);
    memcpy(p, src, size);
    return p;
}

/* Table `t` with each array in its own heap block of exactly its size (from its header). */
static inline stsp_table_t heap_table(stsp_table_t t)
{
    const size_t s = sizeof(stsp_scalar_t), nt = t.n_ticks, ns = t.n_stages;
    t.stage_start = heap_copy(t.stage_start, (ns + 1u) * sizeof(uint32_t));
    t.stage_n_latch = heap_copy(t.stage_n_latch, ns * sizeof(uint16_t));
    t.K = heap_copy(t.K, nt * t.nu * t.nx * s);
    t.k0 = heap_copy(t.k0, nt * t.nu * s);
    t.L = heap_copy(t.L, nt * t.nu * t.n_latch * s);
    t.Lambda = heap_copy(t.Lambda, ns * t.n_latch * t.nx * s);
    t.lambda0 = heap_copy(t.lambda0, ns * t.n_latch * s);
    t.u_min = heap_copy(t.u_min, t.nu * s);
    t.u_max = heap_copy(t.u_max, t.nu * s);
    t.u_hold = heap_copy(t.u_hold, t.nu * s);
#ifdef STSP_ARITH_FIXED_POINT
    t.x_exp = heap_copy(t.x_exp, t.nx);
    t.u_exp = heap_copy(t.u_exp, t.nu);
    t.v_exp = heap_copy(t.v_exp, t.n_latch);
#endif
    return t;
}

static inline void free_heap_table(const stsp_table_t *t)
{
    free((void *)t->stage_start);
    free((void *)t->stage_n_latch);
    free((void *)t->K);
    free((void *)t->k0);
    free((void *)t->L);
    free((void *)t->Lambda);
    free((void *)t->lambda0);
    free((void *)t->u_min);
    free((void *)t->u_max);
    free((void *)t->u_hold);
#ifdef STSP_ARITH_FIXED_POINT
    free((void *)t->x_exp);
    free((void *)t->u_exp);
    free((void *)t->v_exp);
#endif
}

#endif /* STSP_TEST_SUPPORT_H */
