/* The float32 law, its limit and finiteness checks, included once by stsp_controller.c
 * (static, inlined into stsp_step). Private: not installed. */
#ifndef STSP_LAW_F32_H
#define STSP_LAW_F32_H

#include "stsp_clamp.h"

/* The error of a non-finite command: the state was not finite, or it was and the law (or the
 * latch) overflowed. Reads x: called before u is written (x and u may overlap). */
static stsp_status_t stsp_nonfinite_status(const stsp_header_t *h, const stsp_f32_t *x)
{
    return (stsp_all_finite(x, stsp_nx(h)) == 0) ? STSP_ERR_NONFINITE_STATE
                                                 : STSP_ERR_NONFINITE_OUTPUT;
}

/* Cold path, part 3: some y[i] may be outside [u_min[i], u_max[i]] or not finite. If any is
 * NaN/Inf, returns the error that says why. Otherwise clamps y (bits of *mask) and returns
 * STSP_WARN_SATURATED, or STSP_OK if nothing needed clamping (a false alarm of the fast
 * check). Inlined into both cold paths, so that y can stay in registers. */
static STSP_ALWAYS_INLINE stsp_status_t stsp_limit(const stsp_header_t *h, const stsp_f32_t *x,
                                                   stsp_f32_t *y, uint16_t *mask)
{
    if (stsp_all_finite(y, stsp_nu(h)) == 0) {
        return stsp_nonfinite_status(h, x);
    }
    return stsp_clamp(h, y, mask);
}

/* The float32 row of the law (stsp_law.h), in the documented order:
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
/* The rows of the generic law (stsp_law.h), nu >= 1 of them, two at a time and an odd last row
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

/* 1 when sum is not finite: sum - sum is +0 for a finite sum, NaN for NaN and +-Inf. */
static STSP_ALWAYS_INLINE uint32_t stsp_total_alarm(stsp_f32_t sum)
{
    uint32_t out = 0u;
    if (!((sum - sum) == 0.0f)) {
        out = 1u;
    }
    return out;
}

/* Without limits, the cold-path alarm is whether the sum of the u[i] is not finite (any NaN
 * or Inf makes it NaN or Inf; a finite sum that overflows is a false alarm that stsp_limit()
 * clears). The generic float32 law takes the same sum as its rows end (stsp_law.h). */
static STSP_ALWAYS_INLINE uint32_t stsp_unlimited_alarm(const stsp_header_t *h,
                                                        const stsp_f32_t *y)
{
    const uint32_t nu = stsp_nu(h);
    stsp_f32_t sum = -0.0f; /* -0 + a = a for every a: the compiler drops this add */
    uint32_t i;
    STSP_UNROLL
    for (i = 0u; i < nu; ++i) {
        sum += y[i];
    }
    return stsp_total_alarm(sum);
}

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

/* 1 when every y[0..nu) is finite: the ordinary tick's test, inlined so that y can stay in
 * registers. */
static STSP_ALWAYS_INLINE int stsp_command_finite(const stsp_header_t *h, const stsp_f32_t *y)
{
    const uint32_t nu = stsp_nu(h);
    uint32_t i;
    int finite = 1;
    STSP_UNROLL
    for (i = 0u; i < nu; ++i) {
        if (stsp_isfinite_f32(y[i]) == 0) {
            finite = 0;
        }
    }
    return finite;
}

/* An ordinary tick whose command is not finite: the error, u the safe command (x not yet
 * overwritten). */
static STSP_NOINLINE stsp_status_t stsp_step_nonfinite(const stsp_ctrl_t *ctrl,
                                                       const stsp_f32_t *x, stsp_f32_t *u)
{
    const stsp_status_t st = stsp_nonfinite_status(&ctrl->checked, x);
    stsp_hold(ctrl, u);
    return st;
}

#endif /* STSP_LAW_F32_H */
