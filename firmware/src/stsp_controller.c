/* Latched time-varying affine controller: see stospline/stsp_controller.h for the contract
 * and docs/guide/firmware.md for the response to every fault and the MISRA deviations.
 *
 * Hot path. An ordinary tick (the expected tick, inside the stage already latched) runs
 * straight through stsp_step(): two compares select it, the law is evaluated from the tick's
 * rows of K, k0, L (in the float32 build with run-time dimensions the rows the instance keeps
 * for next_tick, stsp_ctrl_t.rows, in a tail-called stsp_step_ordinary) and the latched v,
 * and one check says whether the command needs the cold path. With limits, that check is a compare pair per input against [u_min, u_max], false
 * for NaN and for +-Inf (the limits are finite); without, it is whether the sum of the inputs
 * is finite. Either also serves as the finiteness check of the state: a NaN or infinite x[j]
 * reaches every input (each input sums K[i][j] x[j] over all j, and 0 * Inf is NaN), as does
 * a non-finite latch (each input sums L[i][c] v[c] over all columns). So x itself is read for
 * finiteness only on the cold path, to tell a bad state from an overflow. Everything else
 * (tick range, order, repeats, skips, stage changes, latching, clamping, errors) is on cold
 * paths in functions of their own.
 *
 * A spline table (float32) keeps stage_end at 0, so each of its ticks leaves that path for
 * stsp_spline_ops.step (stsp_spline.c): its ordinary tick is again two compares (the expected
 * tick, inside the recorded span), the spline law (stsp_spline.c) and the same checks, except that the
 * state is checked too (a sparse row need not use every x[j]); the first tick of the next
 * span is also evaluated without the cold path; everything else goes to stsp_step_cold_spline
 * (the per-tick cold path's plan and commit, plus the span search).
 *
 * After init every function works from the instance's copy of the validated header
 * (stsp_header_t: dimensions, array addresses, the band dual's header), never from the table
 * header, so a header changed later cannot move an access outside the arrays init checked;
 * stsp_verify() compares the two. x and u may overlap: each path computes the command into a
 * local array and writes u last, after every read of x.
 *
 * The sources, one job each: this file is the per-tick law (its row primitives in the build's
 * arithmetic, then one definition of the law, inlined into stsp_step()), the cold paths' plan
 * and commit, and the tick/latch state machine (init, reset, verify, step); stsp_table.c
 * validates and serialises the table (CRC-32); stsp_spline.c a spline table's law, ticks and
 * checks (linked only with a spline table, through its ops; it calls the plan and commit here
 * through stsp_plan_tick and stsp_commit_tick); stsp_tick.h the checks on a command both ticks
 * make (alarm, limits, clamp); stsp_internal.h the compiler and VFP helpers, the dimensions
 * the law uses and the fixed-point accumulator; stsp_crc32.c, stsp_qconv.c (Q state/command
 * conversions) and stsp_bandqp.c (the band dual) as named. Everything but the row primitives
 * (ticks, stages, latching order, statuses) is the same code in every arithmetic. */
#include "stsp_internal.h"
#include "stsp_tick.h"

#include <float.h>
#include <string.h>

/* The law's rows in the build's arithmetic: stsp_row_first, stsp_row_mac, stsp_row_end (and, for
 * the generic float32 law, stsp_law_pairs), and the latch row. */
#ifndef STSP_ARITH_FIXED_POINT
/* The float32 row of the law (below), in the documented order:
 *     u[i] = (((-(K[i][0] x[0]) - k0[i]) - K[i][1] x[1]) - ... ) - L[i][0] v[0] - ...
 * which is -(k0[i] + K[i][0] x[0] + ... + L[i][c] v[c] ...) exactly (IEEE rounding is
 * symmetric; a+b = b+a), up to the sign of an exactly zero result; starting from -(K x)
 * folds the final negation away, and each step is one stsp_nmla()/stsp_mls() (one VNMLA or
 * VMLS on the M4F, same bits). */
#ifdef STSP_FIXED_NX
typedef stsp_f32_t stsp_row_acc_t;
/* Aliases, not wrappers: GCC schedules the law through inline wrappers differently (one
 * more load on the M4F ordinary tick), so the law calls the VFP helpers by these names
 * directly, and the end of a row is the accumulator itself (k0 was folded in first). */
#define stsp_row_first stsp_nmla
#define stsp_row_mac stsp_mls
#define stsp_row_end(acc, k0) (acc)
#else
/* The rows of the generic law (below), nu >= 1 of them, two at a time and an odd last row
 * alone. A pair: acc0 = -k0[0] and acc1 = -k0[1], acc0 -= K[c] x[c] and acc1 -= K[nx + c] x[c]
 * for c = 0 .. nx - 1 in order, then acc0 -= L[c] v[c] and acc1 -= L[nl + c] v[c] for c = 0 ..
 * nl - 1, each step the bits of stsp_mls; y[0] = acc0, y[1] = acc1, and *total + acc0 + acc1 in
 * that order; then k0, y, K and L move to the next pair. The odd last row the same with acc0
 * alone. On return *k0, *y, *K and *L point past the rows (K nu nx, k0 nu and L nu nl entries
 * on: where the next tick's rows start; L unchanged when nl == 0). On a single-precision VFP
 * one asm statement: per pair (row), per four columns one VLDM each of x (v) and of the two
 * rows (the row) and eight (four) VMLS (11 instructions for 8 multiply-adds where separate
 * loads take 20), then the n % 4 last columns one at a time; the accumulators in s12-s13 (VLDM
 * of k0, VSTM to y), the operands in s0-s11 (caller-saved, declared clobbered); no loop count
 * or pointer for GCC to keep in a register around it. nl == 0: no access to L and no C pointer
 * arithmetic on it (it may be NULL). */
static STSP_ALWAYS_INLINE void
/* cppcheck-suppress misra-c2012-2.7 ; deviation D5: the parameters are asm operands */
stsp_law_pairs(const stsp_f32_t *x, const stsp_f32_t *v, uint32_t nx, uint32_t nl, uint32_t nu,
               const stsp_f32_t **k0, stsp_f32_t **y, const stsp_f32_t **K,
               const stsp_f32_t **L, stsp_f32_t *total)
{
    const stsp_f32_t *kp = *K;
    const stsp_f32_t *lp = *L;
    const stsp_f32_t *bp = *k0;
    stsp_f32_t *yp = *y;
    stsp_f32_t t = *total;
#if STSP_VFP_MAC
    const stsp_f32_t *p1;
    const stsp_f32_t *q;
    uint32_t k;
    uint32_t n = nu;
    /* n counts the rows left, less two: per pair (loop 1) the rows against x (labels 2-5), then
     * against v (6-9); per four columns one VLDM each and eight VMLS (loops 2, 6), then the
     * n % 4 last columns (4, 8). An odd last row (label 10 on): the same, one row (11-18). */
    __asm__ volatile("subs %[n], %[n], #2\n\t"
                     "bmi 10f\n\t"
                     "1:\n"
                     "vldmia %[k0]!, {s12-s13}\n\t"
                     "vneg.f32 s12, s12\n\t"
                     "vneg.f32 s13, s13\n\t"
                     "add %[p1], %[kp], %[nx], lsl #2\n\t"
                     "mov %[q], %[x]\n\t"
                     "lsrs %[k], %[nx], #2\n\t"
                     "beq 3f\n\t"
                     "2:\n"
                     "vldmia %[q]!, {s0-s3}\n\t"
                     "vldmia %[kp]!, {s4-s7}\n\t"
                     "vldmia %[p1]!, {s8-s11}\n\t"
                     "vmls.f32 s12, s4, s0\n\t"
                     "vmls.f32 s13, s8, s0\n\t"
                     "vmls.f32 s12, s5, s1\n\t"
                     "vmls.f32 s13, s9, s1\n\t"
                     "vmls.f32 s12, s6, s2\n\t"
                     "vmls.f32 s13, s10, s2\n\t"
                     "vmls.f32 s12, s7, s3\n\t"
                     "vmls.f32 s13, s11, s3\n\t"
                     "subs %[k], %[k], #1\n\t"
                     "bne 2b\n\t"
                     "3:\n"
                     "ands %[k], %[nx], #3\n\t"
                     "beq 5f\n\t"
                     "4:\n"
                     "vldmia %[q]!, {s0}\n\t"
                     "vldmia %[kp]!, {s4}\n\t"
                     "vldmia %[p1]!, {s8}\n\t"
                     "vmls.f32 s12, s4, s0\n\t"
                     "vmls.f32 s13, s8, s0\n\t"
                     "subs %[k], %[k], #1\n\t"
                     "bne 4b\n\t"
                     "5:\n"
                     "mov %[kp], %[p1]\n\t"
                     "add %[p1], %[lp], %[nl], lsl #2\n\t"
                     "mov %[q], %[v]\n\t"
                     "lsrs %[k], %[nl], #2\n\t"
                     "beq 7f\n\t"
                     "6:\n"
                     "vldmia %[q]!, {s0-s3}\n\t"
                     "vldmia %[lp]!, {s4-s7}\n\t"
                     "vldmia %[p1]!, {s8-s11}\n\t"
                     "vmls.f32 s12, s4, s0\n\t"
                     "vmls.f32 s13, s8, s0\n\t"
                     "vmls.f32 s12, s5, s1\n\t"
                     "vmls.f32 s13, s9, s1\n\t"
                     "vmls.f32 s12, s6, s2\n\t"
                     "vmls.f32 s13, s10, s2\n\t"
                     "vmls.f32 s12, s7, s3\n\t"
                     "vmls.f32 s13, s11, s3\n\t"
                     "subs %[k], %[k], #1\n\t"
                     "bne 6b\n\t"
                     "7:\n"
                     "ands %[k], %[nl], #3\n\t"
                     "beq 9f\n\t"
                     "8:\n"
                     "vldmia %[q]!, {s0}\n\t"
                     "vldmia %[lp]!, {s4}\n\t"
                     "vldmia %[p1]!, {s8}\n\t"
                     "vmls.f32 s12, s4, s0\n\t"
                     "vmls.f32 s13, s8, s0\n\t"
                     "subs %[k], %[k], #1\n\t"
                     "bne 8b\n\t"
                     "9:\n"
                     "mov %[lp], %[p1]\n\t"
                     "vstmia %[y]!, {s12-s13}\n\t"
                     "vadd.f32 %[t], %[t], s12\n\t"
                     "vadd.f32 %[t], %[t], s13\n\t"
                     "subs %[n], %[n], #2\n\t"
                     "bpl 1b\n\t"
                     "10:\n"
                     "adds %[n], %[n], #1\n\t"
                     "bne 18f\n\t"
                     "vldmia %[k0]!, {s12}\n\t"
                     "vneg.f32 s12, s12\n\t"
                     "mov %[q], %[x]\n\t"
                     "lsrs %[k], %[nx], #2\n\t"
                     "beq 12f\n\t"
                     "11:\n"
                     "vldmia %[q]!, {s0-s3}\n\t"
                     "vldmia %[kp]!, {s4-s7}\n\t"
                     "vmls.f32 s12, s4, s0\n\t"
                     "vmls.f32 s12, s5, s1\n\t"
                     "vmls.f32 s12, s6, s2\n\t"
                     "vmls.f32 s12, s7, s3\n\t"
                     "subs %[k], %[k], #1\n\t"
                     "bne 11b\n\t"
                     "12:\n"
                     "ands %[k], %[nx], #3\n\t"
                     "beq 14f\n\t"
                     "13:\n"
                     "vldmia %[q]!, {s0}\n\t"
                     "vldmia %[kp]!, {s4}\n\t"
                     "vmls.f32 s12, s4, s0\n\t"
                     "subs %[k], %[k], #1\n\t"
                     "bne 13b\n\t"
                     "14:\n"
                     "mov %[q], %[v]\n\t"
                     "lsrs %[k], %[nl], #2\n\t"
                     "beq 16f\n\t"
                     "15:\n"
                     "vldmia %[q]!, {s0-s3}\n\t"
                     "vldmia %[lp]!, {s4-s7}\n\t"
                     "vmls.f32 s12, s4, s0\n\t"
                     "vmls.f32 s12, s5, s1\n\t"
                     "vmls.f32 s12, s6, s2\n\t"
                     "vmls.f32 s12, s7, s3\n\t"
                     "subs %[k], %[k], #1\n\t"
                     "bne 15b\n\t"
                     "16:\n"
                     "ands %[k], %[nl], #3\n\t"
                     "beq 17f\n\t"
                     "161:\n"
                     "vldmia %[q]!, {s0}\n\t"
                     "vldmia %[lp]!, {s4}\n\t"
                     "vmls.f32 s12, s4, s0\n\t"
                     "subs %[k], %[k], #1\n\t"
                     "bne 161b\n\t"
                     "17:\n"
                     "vstmia %[y]!, {s12}\n\t"
                     "vadd.f32 %[t], %[t], s12\n\t"
                     "18:"
                     : [kp] "+&r"(kp), [lp] "+&r"(lp), [k0] "+&r"(bp), [y] "+&r"(yp), [n] "+&r"(n),
                       [t] "+t"(t), [p1] "=&r"(p1), [q] "=&r"(q), [k] "=&r"(k)
                     : [x] "r"(x), [v] "r"(v), [nx] "r"(nx), [nl] "r"(nl)
                     : "s0", "s1", "s2", "s3", "s4", "s5", "s6", "s7", "s8", "s9", "s10",
                       "s11", "s12", "s13", "cc", "memory");
#else
    uint32_t n;
    uint32_t c;
    for (n = 0u; n < (nu >> 1); ++n) {
        stsp_f32_t r0 = -bp[0];
        stsp_f32_t r1 = -bp[1];
        for (c = 0u; c < nx; ++c) {
            r0 = stsp_mls(r0, kp[c], x[c]);
            r1 = stsp_mls(r1, kp[nx + c], x[c]);
        }
        kp = &kp[2u * nx];
        if (nl > 0u) {
            for (c = 0u; c < nl; ++c) {
                r0 = stsp_mls(r0, lp[c], v[c]);
                r1 = stsp_mls(r1, lp[nl + c], v[c]);
            }
            lp = &lp[2u * nl];
        }
        yp[0] = r0;
        yp[1] = r1;
        t = (t + r0) + r1;
        bp = &bp[2];
        yp = &yp[2];
    }
    if ((nu & 1u) != 0u) {
        stsp_f32_t acc = -bp[0];
        for (c = 0u; c < nx; ++c) {
            acc = stsp_mls(acc, kp[c], x[c]);
        }
        kp = &kp[nx];
        if (nl > 0u) {
            for (c = 0u; c < nl; ++c) {
                acc = stsp_mls(acc, lp[c], v[c]);
            }
            lp = &lp[nl];
        }
        yp[0] = acc;
        t = t + acc;
        bp = &bp[1];
        yp = &yp[1];
    }
#endif
    *K = kp;
    *L = lp;
    *k0 = bp;
    *y = yp;
    *total = t;
}
#endif

/* One latched multiplier: lambda0 + sum_j Lambda[j] x[j], in that order. */
static STSP_ALWAYS_INLINE stsp_f32_t stsp_latch_row(const stsp_f32_t *lam, stsp_f32_t lambda0,
                                                    const stsp_f32_t *x, uint32_t nx)
{
    stsp_f32_t acc = lambda0;
    uint32_t j;
    for (j = 0u; j < nx; ++j) {
        acc += lam[j] * x[j];
    }
    return acc;
}

#else
/* The fixed-point (Q15: 32-bit accumulator, Q31: 64-bit) row of the law (below):
 *     u_q[i] = floor((k0[i] 2^F + sum_j K[i][j] x_q[j] + sum_c L[i][c] v_q[c]) / 2^F + 1/2)
 * (the table stores -K, -k0, -L: one multiply-accumulate per term). Scaling: every term of
 * row i is in units of 2^(u_exp[i] - 2F) (the gains carry x_exp, v_exp and u_exp), so the
 * only shift is the final one by F. Overflow: none; the sum is exact (integer, any order
 * gives the same bits) and bounded by (2^F - 1) 2^F, the accumulator by 2^(2F+1) (see
 * stsp_uacc_t); u_q is within +-(2^F - 1) without saturation. */
typedef stsp_uacc_t stsp_row_acc_t;
/* Aliases, as for float32 above (inline wrappers change GCC's schedule of the law): the row
 * starts from the accumulator's bias, and k0 is added after the shift. */
#define stsp_row_first(a, b, k0) stsp_q_mac(stsp_q_start(), (a), (b))
#define stsp_row_mac stsp_q_mac
#define stsp_row_end stsp_q_round

/* One latched multiplier: v_q = round half up of lambda0 + sum_j Lambda x_q / 2^F, exact in
 * stsp_uacc_t and within +-(2^F - 1) (the row bound of stsp_check_values). */
static STSP_ALWAYS_INLINE stsp_scalar_t stsp_latch_row(const stsp_scalar_t *lam,
                                                       stsp_scalar_t lambda0,
                                                       const stsp_scalar_t *x, uint32_t nx)
{
    stsp_uacc_t sum = stsp_q_start();
    uint32_t j;
    for (j = 0u; j < nx; ++j) {
        sum = stsp_q_mac(sum, lam[j], x[j]);
    }
    return stsp_q_round(sum, lambda0);
}

#endif

/* The law, one definition for every arithmetic on the row primitives above. Static, inlined
 * into stsp_step. */
#if defined(STSP_FIXED_NX) || defined(STSP_ARITH_FIXED_POINT)
/* The law at `tick` with multipliers v, into y (never the caller's u: x and u may overlap):
 * per input i, the row K[i][0] x[0] (with k0[i], as the arithmetic folds it in), the rest of
 * K[i] x, then L[i] v over all n_latch columns (zero padded, so every tick costs the same).
 * Returns stsp_law_alarm(). Inlined into callers whose y is a local array, so that in an
 * STSP_FIXED_* build x, v and y stay in registers. */
static STSP_ALWAYS_INLINE uint32_t stsp_law(const stsp_header_t *h, uint32_t tick,
                                            const stsp_scalar_t *x, const stsp_scalar_t *v,
                                            stsp_scalar_t *y, uint32_t limited)
{
    const uint32_t nx = stsp_nx(h);
    const uint32_t nu = stsp_nu(h);
    const uint32_t n_latch = stsp_n_latch(h);
    const stsp_scalar_t *K = &h->K[tick * (nu * nx)];
    const stsp_scalar_t *k0 = &h->k0[tick * nu];
    /* L may be NULL when n_latch == 0: no pointer arithmetic on it then. */
    const stsp_scalar_t *L = (n_latch > 0u) ? &h->L[tick * (nu * n_latch)] : h->L;
    uint32_t i;
    STSP_UNROLL
    for (i = 0u; i < nu; ++i) {
        stsp_row_acc_t acc = stsp_row_first(K[0], x[0], k0[i]);
        uint32_t j;
        STSP_UNROLL
        for (j = 1u; j < nx; ++j) {
            acc = stsp_row_mac(acc, K[j], x[j]);
        }
        K = &K[nx];
        if (n_latch > 0u) {
            STSP_UNROLL
            for (j = 0u; j < n_latch; ++j) {
                acc = stsp_row_mac(acc, L[j], v[j]);
            }
            L = &L[n_latch];
        }
        y[i] = stsp_row_end(acc, k0[i]);
    }
    return stsp_law_alarm(h, y, limited);
}
#else
/* float32, generic dimensions. The rows of `tick` (< n_ticks, which the cold path checked
 * first), from the validated copy h. */
static inline void stsp_rows_at(const stsp_header_t *h, uint32_t tick, stsp_rows_t *r)
{
    const uint32_t nu = stsp_nu(h);
    const uint32_t n_latch = stsp_n_latch(h);
    r->K = &h->K[tick * (nu * stsp_nx(h))];
    r->k0 = &h->k0[tick * nu];
    /* L may be NULL when n_latch == 0: no pointer arithmetic on it then. */
    r->L = (n_latch > 0u) ? &h->L[tick * (nu * n_latch)] : h->L;
}

/* The law on the rows r (those of one tick) with multipliers v, into y: two rows at a time,
 * each x[j] (v[c]) loaded once for both (stsp_law_pairs: on the M4F VLDM of four columns and
 * VMLS), an odd last row alone. Each row is still its own chain in the documented order: acc
 * = -k0[i], then acc = stsp_mls(acc, K[i][j], x[j]) for j = 0 .. nx - 1 and stsp_mls(acc,
 * L[i][c], v[c]) for c = 0 .. n_latch - 1. Its first step, -k0[i] - K[i][0] x[0], is the
 * documented (-(K[i][0] x[0])) - k0[i]: both are (-k0[i]) + (-(K[i][0] x[0])), and binary32
 * addition is commutative, signs of zero included (as for VNMLA, stsp_nmla). Writes y[0 ..
 * nu) (never the caller's u: x and u may overlap) and moves r past the tick's rows (to the
 * next tick's: nu nx, nu and nu n_latch entries on; L stays when n_latch == 0); returns the
 * inputs' sum in order, -0 + y[0] + y[1] + ... (stsp_unlimited_alarm's). Inlined into the
 * ordinary tick and the cold path's stsp_law_rows on a single-precision VFP (one asm
 * statement); elsewhere (soft float, the host) once, out of line: inlined twice, its C loops
 * cost the Cortex-M0+ some 650 B of flash. */
#if STSP_VFP_MAC
/* cppcheck-suppress misra-c2012-2.5 ; deviation D7: the host configuration uses the other */
#define STSP_LAW_ON_ROWS STSP_ALWAYS_INLINE
#else
#define STSP_LAW_ON_ROWS STSP_NOINLINE
#endif
static STSP_LAW_ON_ROWS stsp_f32_t stsp_law_on_rows(const stsp_header_t *h, stsp_rows_t *r,
                                                    const stsp_f32_t *x, const stsp_f32_t *v,
                                                    stsp_f32_t *y)
{
    const uint32_t nx = stsp_nx(h);
    const uint32_t nu = stsp_nu(h);
    const uint32_t n_latch = stsp_n_latch(h);
    const stsp_f32_t *K = r->K;
    const stsp_f32_t *k0 = r->k0;
    const stsp_f32_t *L = r->L;
    stsp_f32_t total = -0.0f; /* -0 + a = a for every a */
    stsp_f32_t *yp = y;
    stsp_law_pairs(x, v, nx, n_latch, nu, &k0, &yp, &K, &L, &total);
    r->K = K;
    r->k0 = k0;
    r->L = L;
    return total;
}

/* The law of an ordinary tick on the rows the instance keeps (*rows: those of the tick),
 * moving them on to the next tick's; as stsp_law() otherwise. */
static STSP_ALWAYS_INLINE uint32_t stsp_law_kept(const stsp_header_t *h, stsp_rows_t *rows,
                                                 const stsp_f32_t *x, const stsp_f32_t *v,
                                                 stsp_f32_t *y, uint32_t limited)
{
    const stsp_f32_t total = stsp_law_on_rows(h, rows, x, v, y);
    return (limited != 0u) ? stsp_law_alarm(h, y, limited) : stsp_total_alarm(total);
}

/* The law at `tick` (< n_ticks) on the cold path (stsp_step_cold): the rows from the tick's
 * index in the validated copy h; *next then holds the rows of tick + 1 (stsp_law_on_rows).
 * Out of line; the ordinary tick (stsp_step_ordinary) runs stsp_law_kept() on the rows the
 * instance keeps. */
static STSP_NOINLINE stsp_f32_t stsp_law_rows(const stsp_header_t *h, uint32_t tick,
                                              const stsp_f32_t *x, const stsp_f32_t *v,
                                              stsp_f32_t *y, stsp_rows_t *next)
{
    stsp_rows_t r;
    stsp_f32_t total;
    stsp_rows_at(h, tick, &r);
    total = stsp_law_on_rows(h, &r, x, v, y);
    *next = r;
    return total;
}

/* The law at `tick` with multipliers v, into y (never the caller's u: x and u may overlap),
 * and the rows of tick + 1 into *next. Returns the alarm of stsp_law_alarm(); without limits
 * from the inputs' sum that stsp_law_rows took (same order: the same value). */
static STSP_ALWAYS_INLINE uint32_t stsp_law(const stsp_header_t *h, uint32_t tick,
                                            const stsp_f32_t *x, const stsp_f32_t *v,
                                            stsp_f32_t *y, uint32_t limited, stsp_rows_t *next)
{
    const stsp_f32_t total = stsp_law_rows(h, tick, x, v, y, next);
    return (limited != 0u) ? stsp_law_alarm(h, y, limited) : stsp_total_alarm(total);
}
#endif

/* The cold paths' tick plan: range and order checks, the stage search, the latch into scratch,
 * and the commit of a successful step. */
#ifndef STSP_ARITH_FIXED_POINT
/* The stage-0 latch of a band table: v = the band dual's multipliers for the measured x,
 * rounded to binary32, zero beyond q. Returns 1 on success; 0 if the solver failed (v_new
 * untouched): x not finite (the affine fallback then propagates the NaN/Inf, and the step
 * fails with STSP_ERR_NONFINITE_STATE as for any table), Nt x + mt overflowed, no active set
 * met the optimality conditions (W not positive definite in double precision), or a
 * multiplier lies outside the binary32 range. The solver (stsp_bandqp_solve_f32, with its
 * ~0.8 KB of stack, used on this tick only) is the table's (stsp_bandqp_t.solve_f32), which
 * init checked (stsp_internal.h). */
static STSP_NOINLINE int stsp_band_latch(const stsp_header_t *h, const stsp_f32_t *x,
                                         stsp_f32_t *v_new)
{
    stsp_f32_t v[STSP_BANDQP_MAX];
    const uint32_t q = h->band.q;
    uint32_t i;
    /* The validated copy of the band dual's header, not the table's: q and nx as init checked. */
    if (h->band.solve_f32(&h->band, x, v) != STSP_BANDQP_OK) {
        return 0;
    }
    for (i = 0u; i < stsp_n_latch(h); ++i) {
        v_new[i] = (i < q) ? v[i] : 0.0f;
    }
    return 1;
}
#endif

/* Stage containing `tick`, searching forward from `from` (ticks only move forward; at most
 * n_stages steps, whatever stage_start holds now). */
static uint16_t stsp_stage_of(const stsp_header_t *h, uint16_t from, uint32_t tick)
{
    uint32_t s = from;
    while (((s + 1u) < h->n_stages) && (h->stage_start[s + 1u] <= tick)) {
        ++s;
    }
    return (uint16_t)s;
}

/* Cold path, part 1: range and order checks, stage search, and the latch v_new = Lambda x +
 * lambda0 (or a copy of the v kept) into the caller's scratch: the instance changes only on
 * success, in stsp_commit(). Returns a negative error, or the tick warning (or STSP_OK).
 * Inlined into the per-tick cold path (as a call it costs each cold tick some 20
 * instructions); stsp_spline.c's cold paths call it through stsp_plan_tick. */
static STSP_ALWAYS_INLINE stsp_status_t stsp_plan(const stsp_ctrl_t *c, uint32_t tick,
                                                  const stsp_scalar_t *x, stsp_scalar_t *v_new,
                                                  stsp_plan_t *plan)
{
    const stsp_header_t *h = &c->checked;
    const uint32_t nx = stsp_nx(h);
    const uint32_t n_latch = stsp_n_latch(h);
    stsp_status_t status = STSP_OK;
    uint32_t i;
    uint32_t n_stage;
    uint16_t stage;

    if (tick >= h->n_ticks) {
        return STSP_ERR_TICK_RANGE;
    }
    if (c->next_tick > 0u) {
        if ((tick + 1u) < c->next_tick) {
            return STSP_ERR_TICK_ORDER;
        }
        if ((tick + 1u) == c->next_tick) {
            status = STSP_WARN_TICK_REPEATED;
        }
    }
    if (tick > c->next_tick) {
        status = STSP_WARN_TICK_SKIPPED;
    }
    stage = stsp_stage_of(h, c->stage, tick);
    /* A stage with stage_n_latch > 0 latches a fresh v at its first tick; one with
     * stage_n_latch == 0 keeps the v latched earlier (joint multipliers are latched once, at
     * stage 0). Only columns below n_latch are ever touched, whatever stage_n_latch holds. */
    n_stage = h->stage_n_latch[stage];
    plan->stage = stage;
    plan->relatch = 0u;
    if ((c->latched == 0u) || ((stage != c->stage) && (n_stage > 0u))) {
        plan->relatch = 1u;
    }
#ifndef STSP_ARITH_FIXED_POINT
    if ((plan->relatch != 0u) && (stage == 0u) && (h->band_qp != NULL)) {
        if (stsp_band_latch(h, x, v_new) != 0) {
            return status;
        }
        status = STSP_WARN_BAND_FALLBACK; /* the affine map below, from the design's x0 */
    }
#endif
    if (plan->relatch != 0u) {
        for (i = 0u; i < n_latch; ++i) {
            stsp_scalar_t acc = (stsp_scalar_t)0;
            if (i < n_stage) {
                const uint32_t row = ((uint32_t)stage * n_latch) + i;
                acc = stsp_latch_row(&h->Lambda[row * nx], h->lambda0[row], x, nx);
            }
            v_new[i] = acc;
        }
    } else {
        for (i = 0u; i < n_latch; ++i) {
            v_new[i] = c->v[i];
        }
    }
    return status;
}

/* Cold path, part 2: the step succeeded; record the stage, the latch and the tick. */
static STSP_ALWAYS_INLINE void stsp_commit(stsp_ctrl_t *c, uint32_t tick,
                                           const stsp_plan_t *plan, const stsp_scalar_t *v_new)
{
    const stsp_header_t *h = &c->checked;
    if (plan->relatch != 0u) {
        uint32_t i;
        for (i = 0u; i < stsp_n_latch(h); ++i) {
            c->v[i] = v_new[i];
        }
        c->latched = 1u;
    }
    c->stage = plan->stage;
    c->stage_end = stsp_stage_end(h, plan->stage);
    if ((tick + 1u) > c->next_tick) {
        c->next_tick = tick + 1u;
    }
}


/* The plan and the commit for stsp_spline.c's cold paths: the same code, out of line. */
stsp_status_t stsp_plan_tick(const stsp_ctrl_t *c, uint32_t tick, const stsp_scalar_t *x,
                             stsp_scalar_t *v_new, stsp_plan_t *plan)
{
    return stsp_plan(c, tick, x, v_new, plan);
}

void stsp_commit_tick(stsp_ctrl_t *c, uint32_t tick, const stsp_plan_t *plan,
                      const stsp_scalar_t *v_new)
{
    stsp_commit(c, tick, plan, v_new);
}

/* float32 with run-time dimensions: the instance keeps the rows of tick next_tick
 * (stsp_ctrl_t.rows), and the ordinary tick is a function of its own (stsp_step_ordinary). */
#if !defined(STSP_ARITH_FIXED_POINT) && !defined(STSP_FIXED_NX)
#define STSP_ROW_CACHE 1
#else
#define STSP_ROW_CACHE 0
#endif

#if STSP_ROW_CACHE
/* The rows of tick 0 into the instance, from the validated copy: where init and reset leave
 * next_tick (stage_end 0: the first tick takes the cold path, which sets them again). */
static void stsp_rows_first(stsp_ctrl_t *ctrl)
{
    ctrl->rows.K = ctrl->checked.K;
    ctrl->rows.k0 = ctrl->checked.k0;
    ctrl->rows.L = ctrl->checked.L;
}
#endif

/* A refused init: the instance all zeros (not ready), as before it was given a table. */
static stsp_status_t stsp_refuse(stsp_ctrl_t *ctrl, stsp_status_t status)
{
    (void)memset(ctrl, 0, sizeof *ctrl);
    return status;
}

stsp_status_t stsp_init(stsp_ctrl_t *ctrl, const stsp_table_t *table)
{
    stsp_status_t st;
    if (ctrl == NULL) {
        return STSP_ERR_NULL;
    }
    (void)memset(ctrl, 0, sizeof *ctrl);
    if (table == NULL) {
        return STSP_ERR_NULL;
    }
    if (table->magic != STSP_TABLE_MAGIC) {
        return STSP_ERR_BAD_MAGIC;
    }
    if ((table->format_version != STSP_FORMAT_VERSION) ||
        (table->scalar_kind != STSP_SCALAR_KIND)) {
        return STSP_ERR_BAD_VERSION;
    }
    /* From here on only the copy's dimensions and addresses are used. */
    stsp_copy_header(&ctrl->checked, table);
    st = stsp_check_table(&ctrl->checked, table);
    if (st != STSP_OK) {
        return stsp_refuse(ctrl, st);
    }
    ctrl->table = table;
    stsp_copy(ctrl->hold, table->u_hold, ctrl->checked.nu);
    ctrl->limited = stsp_has_limits(&ctrl->checked);
    /* init checked the ops (stsp_spline_code_ok): the spline tick stsp_step calls */
    ctrl->checked.spline_step =
        (ctrl->checked.spline != NULL) ? ctrl->checked.sp.ops->step : NULL;
#if STSP_ROW_CACHE
    stsp_rows_first(ctrl);
#endif
    ctrl->ready = STSP_CTRL_READY;
    return STSP_OK;
}

stsp_status_t stsp_init_expect(stsp_ctrl_t *ctrl, const stsp_table_t *table, uint32_t nx,
                               uint32_t nu)
{
    stsp_status_t st = stsp_init(ctrl, table);
    if ((st == STSP_OK) && ((ctrl->checked.nx != nx) || (ctrl->checked.nu != nu))) {
        st = stsp_refuse(ctrl, STSP_ERR_BAD_DIMS);
    }
    return st;
}

stsp_status_t stsp_init_problem(stsp_ctrl_t *ctrl, const stsp_table_t *table, uint32_t nx,
                                uint32_t nu, const uint8_t *problem_sha256)
{
    stsp_status_t st;
    if (problem_sha256 == NULL) {
        if (ctrl != NULL) {
            (void)memset(ctrl, 0, sizeof *ctrl);
        }
        return STSP_ERR_NULL;
    }
    st = stsp_init_expect(ctrl, table, nx, nu);
    if ((st == STSP_OK) &&
        (memcmp(table->problem_sha256, problem_sha256, sizeof table->problem_sha256) != 0)) {
        st = stsp_refuse(ctrl, STSP_ERR_BAD_PROBLEM);
    }
    return st;
}

stsp_status_t stsp_reset(stsp_ctrl_t *ctrl)
{
    const stsp_status_t st = stsp_check_ready(ctrl);
    if (st != STSP_OK) {
        return st;
    }
    ctrl->next_tick = 0u;
    ctrl->stage_end = 0u;
    ctrl->stage = 0u;
    ctrl->latched = 0u;
    ctrl->sat_mask = 0u;
    stsp_zero(ctrl->v, STSP_MAX_LATCH);
#ifndef STSP_ARITH_FIXED_POINT
    (void)memset(&ctrl->span, 0, sizeof ctrl->span);
#endif
#if STSP_ROW_CACHE
    stsp_rows_first(ctrl);
#endif
    return STSP_OK;
}

stsp_status_t stsp_verify(stsp_ctrl_t *ctrl)
{
    const stsp_status_t st = stsp_check_ready(ctrl);
    if (st != STSP_OK) {
        return st;
    }
    /* The header first: the CRC below reads the arrays only as the copy describes them. */
    if (stsp_header_changed(&ctrl->checked, ctrl->table) != 0) {
        ctrl->ready = STSP_CTRL_STOPPED;
        return STSP_ERR_TABLE_CHANGED;
    }
    if (stsp_crc_of(&ctrl->checked, ctrl->table) != ctrl->table->crc32) {
        ctrl->ready = STSP_CTRL_STOPPED;
        return STSP_ERR_BAD_CRC;
    }
    return STSP_OK;
}


/* Every tick but the ordinary one: range, order, repeat, skip, stage change, latch. The
 * command is computed into y and written to u last, after every read of x. */
static STSP_NOINLINE stsp_status_t stsp_step_cold(stsp_ctrl_t *ctrl, uint32_t tick,
                                                  const stsp_scalar_t *x, stsp_scalar_t *u)
{
    const stsp_header_t *h = &ctrl->checked;
    stsp_scalar_t v_new[STSP_MAX_LATCH];
    stsp_scalar_t y[STSP_MAX_NU];
    stsp_plan_t plan = {0u, 0u};
    stsp_status_t status;
    uint16_t mask = 0u;
#if STSP_ROW_CACHE
    stsp_rows_t next = ctrl->rows;
#endif
    stsp_zero(v_new, STSP_MAX_LATCH);
    status = stsp_plan(ctrl, tick, x, v_new, &plan);
    if (status >= STSP_OK) {
#if STSP_ROW_CACHE
        const uint32_t alarm = stsp_law(h, tick, x, v_new, y, ctrl->limited, &next);
#else
        const uint32_t alarm = stsp_law(h, tick, x, v_new, y, ctrl->limited);
#endif
        if (alarm != 0u) {
            const stsp_status_t st = stsp_limit(h, x, y, &mask);
            if (st != STSP_OK) {
                status = st; /* an error, or STSP_WARN_SATURATED over a tick warning */
            }
        }
    }
    if (status < STSP_OK) {
        stsp_hold(ctrl, u);
        return status;
    }
    stsp_copy(u, y, stsp_nu(h));
    ctrl->sat_mask = mask;
    stsp_commit(ctrl, tick, &plan, v_new);
#if STSP_ROW_CACHE
    /* A successful cold tick leaves next_tick == tick + 1 (stsp_plan refuses tick + 1 <
     * next_tick, stsp_commit raises next_tick to tick + 1): the law's next rows are its rows. */
    ctrl->rows = next;
#endif
    return status;
}

/* Not ready: u is not written, as nu is unknown; except for an instance stsp_verify() stopped,
 * which knows its validated nu and the safe command init copied. */
static STSP_NOINLINE stsp_status_t stsp_step_refused(const stsp_ctrl_t *ctrl, stsp_scalar_t *u)
{
    if (ctrl->ready == STSP_CTRL_STOPPED) {
        stsp_hold(ctrl, u);
    }
    return STSP_ERR_NOT_INITIALIZED;
}

/* x is NULL: the safe command. Out of line, as the refused paths: inline, the copy costs the
 * Cortex-M0+ Q31 ordinary tick some 70 instructions of register pressure (and 1 elsewhere). */
static STSP_NOINLINE stsp_status_t stsp_step_null_state(const stsp_ctrl_t *ctrl,
                                                        stsp_scalar_t *u)
{
    stsp_hold(ctrl, u);
    return STSP_ERR_NULL;
}


/* The ordinary tick of a per-tick table (tick == next_tick < stage_end): the law, the
 * classification of a non-finite command (before u is written: x and u may overlap), the
 * command, and the tick. Inlined into stsp_step(), except in the float32 build with run-time
 * dimensions (STSP_ROW_CACHE): there the law runs on the rows the instance keeps for
 * next_tick, which move on to the next tick's only when the step succeeds (a non-finite
 * command leaves the instance unchanged), and the function is tail-called (stsp_step() then
 * needs no frame). */
#if STSP_ROW_CACHE
#define STSP_ORDINARY_TICK STSP_NOINLINE
#else
#define STSP_ORDINARY_TICK STSP_ALWAYS_INLINE
#endif
static STSP_ORDINARY_TICK stsp_status_t stsp_step_ordinary(stsp_ctrl_t *ctrl, uint32_t now,
                                                           const stsp_scalar_t *x,
                                                           stsp_scalar_t *u)
{
    stsp_scalar_t y[STSP_MAX_NU];
    uint32_t out;
    uint32_t tick;
#if STSP_ROW_CACHE
    stsp_rows_t rows = ctrl->rows;
    (void)now;
    out = stsp_law_kept(&ctrl->checked, &rows, x, ctrl->v, y, ctrl->limited);
    tick = ctrl->next_tick; /* == now, read after the law: one register fewer across it */
#else
    tick = now;
    out = stsp_law(&ctrl->checked, tick, x, ctrl->v, y, ctrl->limited);
#endif
#ifndef STSP_ARITH_FIXED_POINT
    /* A NaN/Inf command: which error it is depends on x, read before u is written. */
    if ((out != 0u) && (stsp_command_finite(&ctrl->checked, y) == 0)) {
        return stsp_step_nonfinite(ctrl, x, u);
    }
#endif
#if STSP_ROW_CACHE
    ctrl->rows = rows;
#endif
    stsp_copy_command(u, y, stsp_nu(&ctrl->checked));
    if (out != 0u) {
        return stsp_step_fixup(ctrl, tick, u);
    }
    ctrl->next_tick = tick + 1u;
    return STSP_OK;
}

#if !STSP_ROW_CACHE
/* A spline table's tick (stsp_spline.c, through the table's ops, which init checked), from
 * stsp_step(). A call, not a tail call: stsp_step() then has a call and saves lr in its
 * prologue, and its ordinary tick returns with one pop {..., pc} instead of pop and bx lr (one
 * instruction less on the Cortex-M4F ordinary tick of the STSP_FIXED_* and Q15/Q31 builds). */
static STSP_ALWAYS_INLINE stsp_status_t stsp_step_spline(stsp_ctrl_t *ctrl, uint32_t tick,
                                                         const stsp_scalar_t *x,
                                                         stsp_scalar_t *u)
{
    const stsp_status_t status = ctrl->checked.spline_step(ctrl, tick, x, u);
    STSP_NO_TAIL_CALL();
    return status;
}
#endif

#if STSP_ROW_CACHE
/* Every tick but the ordinary one of a per-tick table: a spline table's (stsp_spline.c, through
 * the table's ops, which init checked), or the cold path. Out of line, so that stsp_step()
 * tail-calls everything and needs no frame. */
static STSP_NOINLINE stsp_status_t stsp_step_other(stsp_ctrl_t *ctrl, uint32_t tick,
                                                   const stsp_f32_t *x, stsp_f32_t *u)
{
    if (ctrl->checked.spline_step != NULL) {
        return ctrl->checked.spline_step(ctrl, tick, x, u);
    }
    return stsp_step_cold(ctrl, tick, x, u);
}
#endif

stsp_status_t stsp_step(stsp_ctrl_t *ctrl, uint32_t tick, const stsp_scalar_t *x,
                        stsp_scalar_t *u)
{
    if ((u == NULL) || (ctrl == NULL)) {
        return STSP_ERR_NULL;
    }
    if (ctrl->ready != STSP_CTRL_READY) {
        return stsp_step_refused(ctrl, u);
    }
    if (x == NULL) {
        return stsp_step_null_state(ctrl, u);
    }
    /* Ordinary tick: the expected one, inside the latched stage (stage_end is 0 until the
     * first latch, and never above n_ticks). Anything else takes the cold path; every tick
     * of a spline table (stage_end 0) its own, stsp_spline_ops.step. */
    if ((tick != ctrl->next_tick) || (tick >= ctrl->stage_end)) {
#if STSP_ROW_CACHE
        return stsp_step_other(ctrl, tick, x, u);
#else
        if (ctrl->checked.spline_step != NULL) {
            return stsp_step_spline(ctrl, tick, x, u);
        }
        return stsp_step_cold(ctrl, tick, x, u);
#endif
    }
    return stsp_step_ordinary(ctrl, tick, x, u);
}

#ifdef STSP_HOST_MESSAGES
const char *stsp_status_str(stsp_status_t status)
{
    const char *text;
    switch (status) {
    case STSP_OK: text = "ok"; break;
    case STSP_WARN_TICK_SKIPPED: text = "tick skipped: evaluated at the given tick"; break;
    case STSP_WARN_TICK_REPEATED: text = "tick repeated: recomputed without a new latch"; break;
    case STSP_WARN_SATURATED: text = "command clamped to the actuator limits"; break;
    case STSP_WARN_STATE_CLAMPED: text = "state outside the fixed-point range, saturated"; break;
    case STSP_WARN_BAND_FALLBACK: text = "band QP failed: latched the design's affine map"; break;
    case STSP_ERR_NULL: text = "null pointer argument"; break;
    case STSP_ERR_NOT_INITIALIZED: text = "controller not initialized"; break;
    case STSP_ERR_BAD_MAGIC: text = "table magic mismatch"; break;
    case STSP_ERR_BAD_VERSION: text = "table format or scalar variant not supported"; break;
    case STSP_ERR_BAD_DIMS: text = "table dimensions invalid"; break;
    case STSP_ERR_BAD_CRC: text = "table CRC mismatch"; break;
    case STSP_ERR_TICK_RANGE: text = "tick beyond the end of the table"; break;
    case STSP_ERR_TICK_ORDER: text = "tick went backwards"; break;
    case STSP_ERR_NONFINITE_STATE: text = "state not finite"; break;
    case STSP_ERR_NONFINITE_OUTPUT: text = "command overflowed"; break;
    case STSP_ERR_BAD_PROBLEM: text = "table made from another problem file"; break;
    case STSP_ERR_BAD_VALUES: text = "table values not finite or limits invalid"; break;
    case STSP_ERR_TABLE_CHANGED: text = "table header changed since init"; break;
    case STSP_WARN_NO_MEASUREMENT: text = "no reading at a sampling tick: predicted"; break;
    case STSP_ERR_NONFINITE_MEASUREMENT: text = "measurement not finite"; break;
    case STSP_ERR_PARAM_RANGE: text = "parameter not finite or outside its range"; break;
    default: text = "unknown status"; break;
    }
    return text;
}
#endif
