/* Private to the firmware sources: compiler helpers, the dimensions the law uses, the
 * fixed-point accumulator, and the table validation that stsp_table.c provides to
 * stsp_controller.c. Not installed; the public API is stospline/stsp_controller.h. */
#ifndef STSP_INTERNAL_H
#define STSP_INTERNAL_H

#include "stospline/stsp_controller.h"
#include "stsp_f32bits.h"

#include <string.h>

/* The fast finiteness check relies on IEEE NaN and infinity semantics. */
#if defined(__FAST_MATH__) || (defined(__FINITE_MATH_ONLY__) && (__FINITE_MATH_ONLY__ != 0))
#error "stsp_controller.c must not be compiled with -ffast-math or -ffinite-math-only"
#endif

/* Compiler hints, empty where unknown: keep the cold paths out of stsp_step() (so that the
 * ordinary tick needs few registers), inline the law into it, and unroll the law's
 * constant-bound loops in an STSP_FIXED_* build (GCC's -O2 does not unroll loops that grow
 * the code; GCC and clang both read `#pragma GCC unroll`). */
#if defined(__GNUC__) || defined(__clang__)
#define STSP_NOINLINE __attribute__((noinline))
#define STSP_ALWAYS_INLINE inline __attribute__((always_inline))
#else
#define STSP_NOINLINE
#define STSP_ALWAYS_INLINE inline
#endif
/* After a call in tail position: keeps it a call (an empty asm statement the compiler must
 * emit after it), where a tail call would cost more than it saves (stsp_step_spline). */
#if defined(__GNUC__) || defined(__clang__)
#define STSP_NO_TAIL_CALL() __asm__ volatile("")
#else
#define STSP_NO_TAIL_CALL()
#endif
#if defined(STSP_FIXED_NX) && (defined(__GNUC__) || defined(__clang__))
#define STSP_UNROLL _Pragma("GCC unroll 16")
#else
#define STSP_UNROLL
#endif

#ifndef STSP_ARITH_FIXED_POINT
/* Non-fused multiply-accumulate on a single-precision VFP (Cortex-M4F, M7, M33 with FPU; GCC
 * or clang). VMLS.F32 and VNMLA.F32 round the product to binary32 and then round the sum
 * (ARMv7-M ARM, DDI 0403E, A7.7.238 VMLA, VMLS and A7.7.250 VNMLA, VNMLS, VNMUL: the
 * pseudocode is product = FPMul(n, m) followed by FPAdd()), so each gives the bits of the
 * VMUL + VSUB pair it replaces in one instruction; GCC does not emit them itself under
 * -ffp-contract=off. Elsewhere (the host, the Cortex-M0+, other compilers) the helpers are plain
 * C with the same operations. STSP_NO_VFP_MAC selects the plain C on the M4F too (same bits;
 * fewer instructions is not fewer cycles: the Cortex-M4 TRM lists 3 cycles for VMLS/VNMLA,
 * 1 each for VMUL and VSUB). The asm is volatile only to make each one a scheduling barrier:
 * GCC 12 then loads each gain next to its use instead of hoisting all 16 loads of the unrolled
 * STSP_FIXED_* law, which ran out of caller-saved registers (vpush/vpop {d8} on every tick). */
#if (defined(__GNUC__) || defined(__clang__)) && defined(__arm__) && defined(__ARM_FP) && \
    !defined(STSP_NO_VFP_MAC)
#if (__ARM_FP & 4) != 0
/* cppcheck-suppress misra-c2012-2.5 ; deviation D7: a Q15/Q31 check sees it, unused there */
#define STSP_VFP_MAC 1
#endif
#endif
#ifndef STSP_VFP_MAC
#define STSP_VFP_MAC 0
#endif

/* acc - (a b): the product rounded first (VMLS.F32 on a single-precision VFP). */
/* cppcheck-suppress misra-c2012-2.7 ; deviation D5: the parameters are asm operands */
static STSP_ALWAYS_INLINE stsp_f32_t stsp_mls(stsp_f32_t acc, stsp_f32_t a, stsp_f32_t b)
{
#if STSP_VFP_MAC
    stsp_f32_t r = acc;
    __asm__ volatile("vmls.f32 %0, %1, %2" : "+t"(r) : "t"(a), "t"(b));
    return r;
#else
    return acc - (a * b);
#endif
}

/* (-(a b)) - c: the product rounded first. VNMLA.F32 computes (-c) + (-(a b)), the same value
 * (x - y is x + (-y), and binary32 addition is commutative, signs of zero included); only the
 * payload of a NaN result may differ, and a NaN command never leaves the controller. */
/* cppcheck-suppress misra-c2012-2.7 ; deviation D5: the parameters are asm operands */
static STSP_ALWAYS_INLINE stsp_f32_t stsp_nmla(stsp_f32_t a, stsp_f32_t b, stsp_f32_t c)
{
#if STSP_VFP_MAC
    stsp_f32_t r = c;
    __asm__ volatile("vnmla.f32 %0, %1, %2" : "+t"(r) : "t"(a), "t"(b));
    return r;
#else
    return (-(a * b)) - c;
#endif
}

/* acc + (a b): the product rounded first (VMLA.F32 on a single-precision VFP; same manual
 * sections). The spline law's gain sums and basis steps. */
/* cppcheck-suppress misra-c2012-2.7 ; deviation D5: the parameters are asm operands */
static STSP_ALWAYS_INLINE stsp_f32_t stsp_mla(stsp_f32_t acc, stsp_f32_t a, stsp_f32_t b)
{
#if STSP_VFP_MAC
    stsp_f32_t r = acc;
    __asm__ volatile("vmla.f32 %0, %1, %2" : "+t"(r) : "t"(a), "t"(b));
    return r;
#else
    return acc + (a * b);
#endif
}

/* 1 when every one of values[0..count) is finite, else 0. */
static inline int stsp_all_finite(const stsp_f32_t *values, uint32_t count)
{
    uint32_t i;
    for (i = 0u; i < count; ++i) {
        if (stsp_isfinite_f32(values[i]) == 0) {
            return 0;
        }
    }
    return 1;
}
#endif

/* The optional code, linked only into programs whose tables refer to it: the band solver
 * (stsp_bandqp.c, about 4.5 KB on a Cortex-M4F), through stsp_bandqp_t.solve_f32, and a spline
 * table's code (stsp_spline.c, about 4 KB), through stsp_spline_t.ops (stsp_qspline_t.ops).
 * stsp_init() refuses a table whose pointer is NULL (or, for the spline code, of another
 * arithmetic), so every later call may use them. */

/* 1 when a spline table's ops pointer is this build's spline code. */
static inline int stsp_spline_code_ok(const stsp_spline_ops_t *ops)
{
    return ((ops != NULL) && (ops->scalar_kind == STSP_SCALAR_KIND)) ? 1 : 0;
}

/* Value of stsp_ctrl_t.ready after a successful stsp_init(): a Thumb-2 immediate that no
 * byte-fill pattern of uninitialised memory (0x00, 0xFF, 0xA5, 0xCC, ...) matches. */
#define STSP_CTRL_READY 0x53005300u
/* Value of stsp_ctrl_t.ready after stsp_verify() found the table changed (private): the
 * instance is stopped, and stsp_step() writes the copied u_hold to the validated u[nu]. */
#define STSP_CTRL_STOPPED 0x53015301u

/* STSP_OK when ctrl is an instance stsp_init() accepted (and stsp_verify() did not stop),
 * else STSP_ERR_NULL or STSP_ERR_NOT_INITIALIZED: the entry check of every call after init. */
static inline stsp_status_t stsp_check_ready(const stsp_ctrl_t *ctrl)
{
    if (ctrl == NULL) {
        return STSP_ERR_NULL;
    }
    return (ctrl->ready == STSP_CTRL_READY) ? STSP_OK : STSP_ERR_NOT_INITIALIZED;
}

static inline void stsp_zero(stsp_scalar_t *u, uint32_t count)
{
    uint32_t i;
    for (i = 0u; i < count; ++i) {
        u[i] = (stsp_scalar_t)0;
    }
}

static inline void stsp_copy(stsp_scalar_t *u, const stsp_scalar_t *y, uint32_t count)
{
    uint32_t i;
    STSP_UNROLL
    for (i = 0u; i < count; ++i) {
        u[i] = y[i];
    }
}

/* The command y[0 .. count) into u, on an ordinary tick (stsp_copy elsewhere). Generic build:
 * two per pass, last to first, as GCC turns stsp_copy's loop into a memcpy call, which costs
 * the M4F ordinary tick some 20 instructions (newlib's memcpy) and the M0+ some 10; on the
 * cold paths a call costs less flash for the same time. */
static inline void stsp_copy_command(stsp_scalar_t *u, const stsp_scalar_t *y, uint32_t count)
{
#ifdef STSP_FIXED_NX
    stsp_copy(u, y, count);
#else
    uint32_t i = count;
    if ((i & 1u) != 0u) {
        --i;
        u[i] = y[i];
    }
    while (i > 0u) {
        i -= 2u;
        u[i + 1u] = y[i + 1u];
        u[i] = y[i];
    }
#endif
}


/* Dimensions as the law uses them: compile-time constants in an STSP_FIXED_* build (the
 * public header requires all three macros or none), else the validated copy (never the table
 * header: it may have changed since init). */
#ifdef STSP_FIXED_NX
static inline uint32_t stsp_nx(const stsp_header_t *h) { (void)h; return (uint32_t)STSP_FIXED_NX; }
static inline uint32_t stsp_nu(const stsp_header_t *h) { (void)h; return (uint32_t)STSP_FIXED_NU; }
static inline uint32_t stsp_n_latch(const stsp_header_t *h)
{
    (void)h;
    return (uint32_t)STSP_FIXED_N_LATCH;
}
#else
static inline uint32_t stsp_nx(const stsp_header_t *h) { return (uint32_t)h->nx; }
static inline uint32_t stsp_nu(const stsp_header_t *h) { return (uint32_t)h->nu; }
static inline uint32_t stsp_n_latch(const stsp_header_t *h) { return (uint32_t)h->n_latch; }
#endif

/* A refused step's command: the safe u_hold init copied into the instance. */
static inline void stsp_hold(const stsp_ctrl_t *ctrl, stsp_scalar_t *u)
{
    stsp_copy(u, ctrl->hold, stsp_nu(&ctrl->checked));
}

#ifdef STSP_ARITH_FIXED_POINT
/* Fixed-point accumulator. It holds the bias 2^(2F) + 2^(F-1) plus a row's sum of products
 * (the row's constant term k0 or lambda0 is added after the shift, stsp_q_round), which
 * stsp_check_values() bounds by (2^F - 1) 2^F in magnitude: so it stays in
 * [2^(F-1) + 2^F, 2^(2F+1)), below 2^32 for Q15 and 2^64 for Q31, and is never negative. It is
 * unsigned: the sum is taken modulo 2^32 (2^64), which for a table that passed init is the
 * exact sum, and for one whose gains changed after init (until stsp_verify() notices) a wrong
 * command but no signed overflow, which would be undefined behaviour. */
#if defined(STSP_ARITH_Q15)
typedef int32_t stsp_acc_t;
typedef uint32_t stsp_uacc_t;
#define STSP_Q_ONE ((stsp_acc_t)32768) /* 2^F */
#else
typedef int64_t stsp_acc_t;
typedef uint64_t stsp_uacc_t;
#define STSP_Q_ONE ((stsp_acc_t)INT64_C(2147483648))
#endif

/* acc + a b, with the exact product (|a b| <= 2^(2F): no overflow) added modulo the
 * accumulator's range. One multiply-accumulate instruction on the Cortex-M4 (smlabb for Q15,
 * smlal for Q31: their addition wraps). ARMv6-M (Cortex-M0/M0+) has no 32x32->64 multiply:
 * there a Q31 product is a libgcc __aeabi_lmul call (see docs/guide/firmware.md for its cost, and
 * for the 16-bit-halves alternative measured and not kept); Q15 is the variant for those
 * cores. */
static inline stsp_uacc_t stsp_q_mac(stsp_uacc_t acc, stsp_scalar_t a, stsp_scalar_t b)
{
    const stsp_acc_t product = (stsp_acc_t)a * (stsp_acc_t)b;
    return acc + (stsp_uacc_t)product;
}

/* The accumulator's start: the bias 2^(2F) + 2^(F-1). */
static inline stsp_uacc_t stsp_q_start(void)
{
#if defined(STSP_ARITH_Q15)
    return 1073758208u;
#else
    return UINT64_C(4611686019501129728);
#endif
}

/* c + floor(sum / 2^F + 1/2) = floor((c 2^F + sum) / 2^F + 1/2) for acc = 2^(2F) + 2^(F-1) +
 * sum and the row's constant term c: round half up, by a shift of a non-negative value (no
 * implementation-defined shift of a negative one). With |c| 2^F + |sum| <= (2^F - 1) 2^F the
 * result lies in [-(2^F - 1), 2^F - 1]: no saturation needed. (For any acc and c the int32
 * (Q15) or int64 (Q31) arithmetic here cannot overflow: shifted < 2^(F+1).) */
static inline stsp_scalar_t stsp_q_round(stsp_uacc_t acc, stsp_scalar_t c)
{
    const stsp_uacc_t shifted = acc >> STSP_Q_FRAC_BITS;
    const stsp_acc_t rounded = ((stsp_acc_t)shifted - STSP_Q_ONE) + (stsp_acc_t)c;
    return (stsp_scalar_t)rounded;
}
#endif /* STSP_ARITH_FIXED_POINT */

#ifdef STSP_ARITH_FIXED_POINT
/* Sum of |values[0..count)| (count <= STSP_MAX_NX + STSP_MAX_LATCH + STSP_MAX_PARAMS: no
 * wrap-around, each term at most 2^F). */
static inline stsp_uacc_t stsp_q_abs_sum(const stsp_scalar_t *values, uint32_t count)
{
    stsp_uacc_t sum = 0u;
    uint32_t i;
    for (i = 0u; i < count; ++i) {
        const stsp_acc_t a = values[i];
        sum += (stsp_uacc_t)((a < 0) ? -a : a);
    }
    return sum;
}

/* Exponents within +-STSP_Q_EXP_MAX (stsp_state_to_q builds 2^(F - x_exp) as a binary32). */
static inline int stsp_q_exps_ok(const int8_t *e, uint32_t count)
{
    uint32_t i;
    for (i = 0u; i < count; ++i) {
        if ((e[i] > STSP_Q_EXP_MAX) || (e[i] < -STSP_Q_EXP_MAX)) {
            return 0;
        }
    }
    return 1;
}
#endif

/* 1 when every one of values[0..count) (binary64) is finite, else 0. */
static inline int stsp_all_finite_f64(const double *values, uint32_t count)
{
    const uint64_t exp_mask = 0x7FF0000000000000u; /* the exponent field */
    uint32_t i;
    for (i = 0u; i < count; ++i) {
        uint64_t bits;
        (void)memcpy(&bits, &values[i], sizeof bits);
        if ((bits & exp_mask) == exp_mask) {
            return 0;
        }
    }
    return 1;
}

/* What a tick other than the ordinary one does: decided before anything is written. */
typedef struct {
    uint16_t stage;   /* stage of the tick */
    uint16_t relatch; /* nonzero: v_new holds a fresh latch for `stage` */
} stsp_plan_t;

/* The first tick after stage s, capped at the validated n_ticks even if stage_start changed
 * since init: the law never indexes a tick beyond the table. */
static inline uint32_t stsp_stage_end(const stsp_header_t *h, uint16_t s)
{
    const uint32_t end = h->stage_start[(uint32_t)s + 1u];
    return (end < h->n_ticks) ? end : h->n_ticks;
}

/* The cold paths' plan and commit (stsp_controller.c), for stsp_spline.c. */
#define stsp_plan_tick STSP_NAME(stsp_plan_tick)
#define stsp_commit_tick STSP_NAME(stsp_commit_tick)
stsp_status_t stsp_plan_tick(const stsp_ctrl_t *c, uint32_t tick, const stsp_scalar_t *x,
                             stsp_scalar_t *v_new, stsp_plan_t *plan);
void stsp_commit_tick(stsp_ctrl_t *c, uint32_t tick, const stsp_plan_t *plan,
                      const stsp_scalar_t *v_new);

/* The functions between the sources below, named per arithmetic (STSP_NAME) as the API. */
#define stsp_copy_header STSP_NAME(stsp_copy_header)
#define stsp_header_changed STSP_NAME(stsp_header_changed)
#define stsp_has_limits STSP_NAME(stsp_has_limits)
#define stsp_crc_of STSP_NAME(stsp_crc_of)
#define stsp_check_table STSP_NAME(stsp_check_table)

/* The header fields every later call uses, read once from the table (init, CRC). */
void stsp_copy_header(stsp_header_t *h, const stsp_table_t *t);

/* 1 if the table header differs from the validated copy in anything a later call relies on
 * (reads only the header structs, never an array); stsp_verify(). */
int stsp_header_changed(const stsp_header_t *h, const stsp_table_t *t);

/* 1 if some input has an actuator limit the law can exceed (the cold path then clamps). */
uint16_t stsp_has_limits(const stsp_header_t *t);

/* The CRC of stsp_table_crc32() over the validated copy and the table's scalars. */
uint32_t stsp_crc_of(const stsp_header_t *table, const stsp_table_t *scalars);

/* Every check of stsp_init() on the header copy h: dimensions, CRC, values. */
stsp_status_t stsp_check_table(const stsp_header_t *h, const stsp_table_t *table);

#endif /* STSP_INTERNAL_H */
