/* Latched time-varying affine controller: see stospline/stsp_controller.h for the contract
 * and docs/guide/firmware.md for the response to every fault and the MISRA deviations.
 *
 * Hot path. An ordinary tick (the expected tick, inside the stage already latched) runs
 * straight through stsp_step(): two compares select it, the law is evaluated from the tick's
 * rows of K, k0, L and the latched v, and one check says whether the command needs the cold
 * path. With limits, that check is a compare pair per input against [u_min, u_max], false
 * for NaN and for +-Inf (the limits are finite); without, it is whether the sum of the inputs
 * is finite. Either also serves as the finiteness check of the state: a NaN or infinite x[j]
 * reaches every input (each input sums K[i][j] x[j] over all j, and 0 * Inf is NaN), as does
 * a non-finite latch (each input sums L[i][c] v[c] over all columns). So x itself is read for
 * finiteness only on the cold path, to tell a bad state from an overflow. Everything else
 * (tick range, order, repeats, skips, stage changes, latching, clamping, errors) is on cold
 * paths in functions of their own.
 *
 * After init every function works from the instance's copy of the validated header
 * (stsp_header_t: dimensions, array addresses, the band dual's header), never from the table
 * header, so a header changed later cannot move an access outside the arrays init checked;
 * stsp_verify() compares the two. x and u may overlap: each path computes the command into a
 * local array and writes u last, after every read of x.
 *
 * Arithmetic variants (stsp_controller.h): the float32 code below is the default; with
 * STSP_ARITH_Q15/Q31 the blocks under STSP_ARITH_FIXED replace the law, the latch, the limit
 * check, the value check and the CRC serialization of the arrays, each documented where it
 * is. Everything else (ticks, stages, latching order, statuses) is the same code. */
#include "stospline/stsp_controller.h"

#include <float.h>
#include <string.h>

#include "stsp_crc32.h"

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
#if defined(STSP_FIXED_NX) && (defined(__GNUC__) || defined(__clang__))
#define STSP_UNROLL _Pragma("GCC unroll 16")
#else
#define STSP_UNROLL
#endif

#ifndef STSP_ARITH_FIXED
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


/* A binary32 is finite unless its exponent bits are all ones (NaN, +-Inf). */
static inline int stsp_isfinite_f32(stsp_f32_t value)
{
    const uint32_t exp_mask = 0x7F800000u; /* the exponent field */
    uint32_t bits;
    (void)memcpy(&bits, &value, sizeof bits);
    return ((bits & exp_mask) != exp_mask) ? 1 : 0;
}
#endif

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

/* Dimensions as the law uses them: compile-time constants in an STSP_FIXED_* build, else the
 * validated copy (never the table header: it may have changed since init). */
static inline uint32_t stsp_nx(const stsp_header_t *h)
{
#ifdef STSP_FIXED_NX
    (void)h;
    return (uint32_t)STSP_FIXED_NX;
#else
    return (uint32_t)h->nx;
#endif
}

static inline uint32_t stsp_nu(const stsp_header_t *h)
{
#ifdef STSP_FIXED_NU
    (void)h;
    return (uint32_t)STSP_FIXED_NU;
#else
    return (uint32_t)h->nu;
#endif
}

static inline uint32_t stsp_nl(const stsp_header_t *h)
{
#ifdef STSP_FIXED_N_LATCH
    (void)h;
    return (uint32_t)STSP_FIXED_N_LATCH;
#else
    return (uint32_t)h->n_latch;
#endif
}

/* The header fields every later call uses, read once (init, and stsp_table_crc32). */
static void stsp_copy_header(stsp_header_t *h, const stsp_table_t *t)
{
    (void)memset(h, 0, sizeof *h);
    h->K = t->K;
    h->k0 = t->k0;
    h->L = t->L;
    h->u_min = t->u_min;
    h->u_max = t->u_max;
    h->Lambda = t->Lambda;
    h->lambda0 = t->lambda0;
    h->stage_start = t->stage_start;
    h->stage_np = t->stage_np;
#ifdef STSP_ARITH_FIXED
    h->x_exp = t->x_exp;
    h->u_exp = t->u_exp;
    h->v_exp = t->v_exp;
#else
    h->band_qp = t->band_qp;
    if (t->band_qp != NULL) {
        h->band = *t->band_qp;
    }
#endif
    h->n_ticks = t->n_ticks;
    h->nx = t->nx;
    h->nu = t->nu;
    h->n_latch = t->n_latch;
    h->n_stages = t->n_stages;
}

/* 1 if the table header differs from the validated copy in anything a later call relies on
 * (reads only the header structs, never an array). */
static int stsp_header_changed(const stsp_header_t *h, const stsp_table_t *t)
{
    int changed = 0;
    if ((t->magic != STSP_TABLE_MAGIC) || (t->format_version != STSP_FORMAT_VERSION) ||
        (t->scalar_kind != STSP_SCALAR_KIND) || (t->nx != h->nx) || (t->nu != h->nu) ||
        (t->n_latch != h->n_latch) || (t->n_stages != h->n_stages) ||
        (t->n_ticks != h->n_ticks)) {
        changed = 1;
    }
    if ((t->K != h->K) || (t->k0 != h->k0) || (t->L != h->L) || (t->u_min != h->u_min) ||
        (t->u_max != h->u_max) || (t->Lambda != h->Lambda) || (t->lambda0 != h->lambda0) ||
        (t->stage_start != h->stage_start) || (t->stage_np != h->stage_np)) {
        changed = 1;
    }
#ifdef STSP_ARITH_FIXED
    if ((t->x_exp != h->x_exp) || (t->u_exp != h->u_exp) || (t->v_exp != h->v_exp) ||
        (t->band_qp != NULL)) {
        changed = 1;
    }
#else
    if (t->band_qp != h->band_qp) {
        changed = 1;
    } else if (t->band_qp != NULL) {
        const stsp_bandqp_t *b = t->band_qp;
        if ((b->q != h->band.q) || (b->nx != h->band.nx) || (b->Nt != h->band.Nt) ||
            (b->mt != h->band.mt) || (b->W != h->band.W) || (b->lo != h->band.lo) ||
            (b->hi != h->band.hi)) {
            changed = 1;
        }
    } else {
        /* no band dual, as validated */
    }
#endif
    return changed;
}

#ifndef STSP_ARITH_FIXED
/* A band dual belongs to a joint design: q rows, all latched once at stage 0. */
static stsp_status_t stsp_check_band_dims(const stsp_header_t *h)
{
    const stsp_bandqp_t *b = &h->band;
    uint32_t s;
    if ((b->Nt == NULL) || (b->mt == NULL) || (b->W == NULL) || (b->lo == NULL) ||
        (b->hi == NULL)) {
        return STSP_ERR_NULL;
    }
    if ((b->q == 0u) || (b->q > STSP_BANDQP_MAX) || (b->nx != h->nx) ||
        (b->q != h->stage_np[0])) {
        return STSP_ERR_BAD_DIMS;
    }
    for (s = 1u; s < h->n_stages; ++s) {
        if (h->stage_np[s] != 0u) {
            return STSP_ERR_BAD_DIMS;
        }
    }
    return STSP_OK;
}
#endif

/* The copy's dimensions and layout (tick_hz and the band pointer come from the header:
 * scalars read once). */
static stsp_status_t stsp_check_dims(const stsp_header_t *t, uint32_t tick_hz, int has_band)
{
    uint32_t s;
    if ((t->nx == 0u) || (t->nx > STSP_MAX_NX) || (t->nu == 0u) || (t->nu > STSP_MAX_NU) ||
        (t->n_latch > STSP_MAX_LATCH) || (t->n_stages == 0u) ||
        (t->n_stages > STSP_MAX_STAGES) || (t->n_ticks == 0u) || (tick_hz == 0u)) {
        return STSP_ERR_BAD_DIMS;
    }
#ifdef STSP_FIXED_NX
    if ((t->nx != STSP_FIXED_NX) || (t->nu != STSP_FIXED_NU) ||
        (t->n_latch != STSP_FIXED_N_LATCH)) {
        return STSP_ERR_BAD_DIMS;
    }
#endif
    /* Every table offset is computed in uint32_t: the largest array must stay addressable. */
    if (t->n_ticks > (UINT32_MAX / ((uint32_t)t->nu * ((uint32_t)t->nx + t->n_latch)))) {
        return STSP_ERR_BAD_DIMS;
    }
    if ((t->stage_start == NULL) || (t->stage_np == NULL) || (t->K == NULL) ||
        (t->k0 == NULL) || (t->u_min == NULL) || (t->u_max == NULL) ||
        ((t->n_latch > 0u) && ((t->L == NULL) || (t->Lambda == NULL) || (t->lambda0 == NULL)))) {
        return STSP_ERR_NULL;
    }
#ifdef STSP_ARITH_FIXED
    if ((t->x_exp == NULL) || (t->u_exp == NULL) || ((t->n_latch > 0u) && (t->v_exp == NULL))) {
        return STSP_ERR_NULL;
    }
#endif
    if ((t->stage_start[0] != 0u) || (t->stage_start[t->n_stages] != t->n_ticks)) {
        return STSP_ERR_BAD_DIMS;
    }
    for (s = 0u; s < t->n_stages; ++s) {
        if ((t->stage_start[s + 1u] <= t->stage_start[s]) || (t->stage_np[s] > t->n_latch)) {
            return STSP_ERR_BAD_DIMS;
        }
    }
#ifdef STSP_ARITH_FIXED
    /* The band solver latches binary32 multipliers: float32 tables only. */
    return (has_band != 0) ? STSP_ERR_BAD_DIMS : STSP_OK;
#else
    return (has_band != 0) ? stsp_check_band_dims(t) : STSP_OK;
#endif
}

#ifdef STSP_ARITH_FIXED
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
static const stsp_acc_t stsp_q_one = 32768; /* 2^F */
#else
typedef int64_t stsp_acc_t;
typedef uint64_t stsp_uacc_t;
static const stsp_acc_t stsp_q_one = INT64_C(2147483648);
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
    const stsp_acc_t rounded = ((stsp_acc_t)shifted - stsp_q_one) + (stsp_acc_t)c;
    return (stsp_scalar_t)rounded;
}

/* Sum of |values[0..count)| (count <= STSP_MAX_NX + STSP_MAX_LATCH: no wrap-around). */
static stsp_uacc_t stsp_q_abs_sum(const stsp_scalar_t *values, uint32_t count)
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
static int stsp_q_exps_ok(const int8_t *e, uint32_t count)
{
    uint32_t i;
    for (i = 0u; i < count; ++i) {
        if ((e[i] > STSP_Q_EXP_MAX) || (e[i] < -STSP_Q_EXP_MAX)) {
            return 0;
        }
    }
    return 1;
}

/* Fixed point: exponents in range; every law row (tick, input) with
 * |k0| + sum_j |K| + sum_c |L| <= 2^F - 1 and every latch row with |lambda0| + sum_j |Lambda|
 * <= 2^F - 1, the condition under which stsp_law and the latch cannot overflow or leave the
 * Q range (stsp_step); limits with u_min <= 0 <= u_max. */
static stsp_status_t stsp_check_values(const stsp_header_t *t)
{
    const stsp_uacc_t row_max = (stsp_uacc_t)stsp_q_one - 1u;
    const uint32_t nx = t->nx;
    const uint32_t nu = t->nu;
    const uint32_t np = t->n_latch;
    uint32_t r;
    if ((stsp_q_exps_ok(t->x_exp, nx) == 0) || (stsp_q_exps_ok(t->u_exp, nu) == 0) ||
        ((np > 0u) && (stsp_q_exps_ok(t->v_exp, np) == 0))) {
        return STSP_ERR_BAD_VALUES;
    }
    for (r = 0u; r < (t->n_ticks * nu); ++r) {
        stsp_uacc_t sum = stsp_q_abs_sum(&t->k0[r], 1u) + stsp_q_abs_sum(&t->K[r * nx], nx);
        if (np > 0u) {
            sum += stsp_q_abs_sum(&t->L[r * np], np);
        }
        if (sum > row_max) {
            return STSP_ERR_BAD_VALUES;
        }
    }
    for (r = 0u; r < ((uint32_t)t->n_stages * np); ++r) {
        if ((stsp_q_abs_sum(&t->lambda0[r], 1u) + stsp_q_abs_sum(&t->Lambda[r * nx], nx)) >
            row_max) {
            return STSP_ERR_BAD_VALUES;
        }
    }
    for (r = 0u; r < nu; ++r) {
        if ((t->u_min[r] > 0) || (t->u_max[r] < 0)) {
            return STSP_ERR_BAD_VALUES;
        }
    }
    return STSP_OK;
}

/* 1 if some input has a limit narrower than the Q range [-2^F, 2^F - 1]. */
static uint16_t stsp_has_limits(const stsp_header_t *t)
{
    uint32_t i;
    for (i = 0u; i < t->nu; ++i) {
        if (((stsp_acc_t)t->u_min[i] > -stsp_q_one) ||
            ((stsp_acc_t)t->u_max[i] < (stsp_q_one - 1))) {
            return 1u;
        }
    }
    return 0u;
}
#else
/* 1 when every one of values[0..count) is finite, else 0. */
static int stsp_all_finite(const stsp_f32_t *values, uint32_t count)
{
    uint32_t i;
    for (i = 0u; i < count; ++i) {
        if (stsp_isfinite_f32(values[i]) == 0) {
            return 0;
        }
    }
    return 1;
}

/* 1 when every one of values[0..count) (binary64) is finite, else 0. */
static int stsp_all_finite_f64(const double *values, uint32_t count)
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

/* Band dual data finite and every band ordered (lo <= hi; lo == hi is an equality row). */
static stsp_status_t stsp_check_band_values(const stsp_bandqp_t *b)
{
    const uint32_t q = b->q;
    uint32_t i;
    if ((stsp_all_finite_f64(b->Nt, q * (uint32_t)b->nx) == 0) ||
        (stsp_all_finite_f64(b->mt, q) == 0) || (stsp_all_finite_f64(b->W, q * q) == 0) ||
        (stsp_all_finite_f64(b->lo, q) == 0) || (stsp_all_finite_f64(b->hi, q) == 0)) {
        return STSP_ERR_BAD_VALUES;
    }
    for (i = 0u; i < q; ++i) {
        if (!(b->lo[i] <= b->hi[i])) {
            return STSP_ERR_BAD_VALUES;
        }
    }
    return STSP_OK;
}

/* Gains finite; limits finite, ordered, and containing the safe hold value 0; band data
 * finite and ordered. */
static stsp_status_t stsp_check_values(const stsp_header_t *t)
{
    const uint32_t nx = t->nx;
    const uint32_t nu = t->nu;
    const uint32_t np = t->n_latch;
    const uint32_t ns = t->n_stages;
    const uint32_t nt = t->n_ticks;
    uint32_t i;
    if ((stsp_all_finite(t->K, nt * nu * nx) == 0) || (stsp_all_finite(t->k0, nt * nu) == 0)) {
        return STSP_ERR_BAD_VALUES;
    }
    if ((np > 0u) && ((stsp_all_finite(t->L, nt * nu * np) == 0) ||
                      (stsp_all_finite(t->Lambda, ns * np * nx) == 0) ||
                      (stsp_all_finite(t->lambda0, ns * np) == 0))) {
        return STSP_ERR_BAD_VALUES;
    }
    for (i = 0u; i < nu; ++i) {
        const stsp_f32_t lo = t->u_min[i];
        const stsp_f32_t hi = t->u_max[i];
        if ((stsp_isfinite_f32(lo) == 0) || (stsp_isfinite_f32(hi) == 0) || !(lo <= 0.0f) ||
            !(hi >= 0.0f)) {
            return STSP_ERR_BAD_VALUES;
        }
    }
    return (t->band_qp != NULL) ? stsp_check_band_values(&t->band) : STSP_OK;
}

/* 1 if some input has a limit other than -FLT_MAX/FLT_MAX (selects the fast-path check). */
static uint16_t stsp_has_limits(const stsp_header_t *t)
{
    uint32_t i;
    for (i = 0u; i < t->nu; ++i) {
        if ((t->u_min[i] > -FLT_MAX) || (t->u_max[i] < FLT_MAX)) {
            return 1u;
        }
    }
    return 0u;
}
#endif /* STSP_ARITH_FIXED */

/* The CRC of stsp_table_crc32(), with the dimensions and arrays of the header copy `table`
 * and the remaining scalars (tick_hz, scalar_kind, problem_sha256) of the table header. */
static uint32_t stsp_crc_of(const stsp_header_t *table, const stsp_table_t *scalars)
{
#ifdef STSP_ARITH_FIXED
    /* Only stsp_table_crc32() of a table init would refuse can have one here. */
    const stsp_bandqp_t *b = scalars->band_qp;
#else
    const stsp_bandqp_t *b = (table->band_qp != NULL) ? &table->band : NULL;
#endif
    const uint32_t nx = table->nx;
    const uint32_t nu = table->nu;
    const uint32_t np = table->n_latch;
    const uint32_t ns = table->n_stages;
    const uint32_t nt = table->n_ticks;
    uint32_t crc = stsp_crc32_begin();
    uint32_t s;
    crc = stsp_crc32_u32(crc, nx);
    crc = stsp_crc32_u32(crc, nu);
    crc = stsp_crc32_u32(crc, np);
    crc = stsp_crc32_u32(crc, ns);
    crc = stsp_crc32_u32(crc, nt);
    crc = stsp_crc32_u32(crc, scalars->tick_hz);
#ifdef STSP_ARITH_FIXED
    crc = stsp_crc32_u32(crc, (uint32_t)scalars->scalar_kind);
#endif
    for (s = 0u; s <= ns; ++s) {
        crc = stsp_crc32_u32(crc, table->stage_start[s]);
    }
    for (s = 0u; s < ns; ++s) {
        crc = stsp_crc32_u32(crc, (uint32_t)table->stage_np[s]);
    }
    crc = stsp_crc32_scalars(crc, table->K, nt * nu * nx);
    crc = stsp_crc32_scalars(crc, table->k0, nt * nu);
    if (np > 0u) {
        crc = stsp_crc32_scalars(crc, table->L, nt * nu * np);
        crc = stsp_crc32_scalars(crc, table->Lambda, ns * np * nx);
        crc = stsp_crc32_scalars(crc, table->lambda0, ns * np);
    }
    crc = stsp_crc32_scalars(crc, table->u_min, nu);
    crc = stsp_crc32_scalars(crc, table->u_max, nu);
#ifdef STSP_ARITH_FIXED
    crc = stsp_crc32_i8s(crc, table->x_exp, nx);
    crc = stsp_crc32_i8s(crc, table->u_exp, nu);
    if (np > 0u) {
        crc = stsp_crc32_i8s(crc, table->v_exp, np);
    }
#endif
    if (b != NULL) {
        const uint32_t q = b->q;
        crc = stsp_crc32_u32(crc, q);
        crc = stsp_crc32_u32(crc, (uint32_t)b->nx);
        crc = stsp_crc32_f64s(crc, b->Nt, q * (uint32_t)b->nx);
        crc = stsp_crc32_f64s(crc, b->mt, q);
        crc = stsp_crc32_f64s(crc, b->W, q * q);
        crc = stsp_crc32_f64s(crc, b->lo, q);
        crc = stsp_crc32_f64s(crc, b->hi, q);
    }
    crc = stsp_crc32_bytes(crc, scalars->problem_sha256,
                           (uint32_t)sizeof scalars->problem_sha256);
    return stsp_crc32_end(crc);
}

uint32_t stsp_table_crc32(const stsp_table_t *table)
{
    stsp_header_t h;
    stsp_copy_header(&h, table);
    return stsp_crc_of(&h, table);
}

/* A refused init: the instance all zeros (not ready), as before it was given a table. */
static stsp_status_t stsp_refuse(stsp_ctrl_t *ctrl, stsp_status_t status)
{
    (void)memset(ctrl, 0, sizeof *ctrl);
    return status;
}

/* The checks of stsp_init() on the header copy h, read once from `table`. */
static stsp_status_t stsp_check_table(const stsp_header_t *h, const stsp_table_t *table)
{
    stsp_status_t st = stsp_check_dims(h, table->tick_hz, (table->band_qp != NULL) ? 1 : 0);
    if (st != STSP_OK) {
        return st;
    }
    if (stsp_crc_of(h, table) != table->crc32) {
        return STSP_ERR_BAD_CRC;
    }
    return stsp_check_values(h);
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
    ctrl->limited = stsp_has_limits(&ctrl->checked);
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
    if (ctrl == NULL) {
        return STSP_ERR_NULL;
    }
    if (ctrl->ready != STSP_CTRL_READY) {
        return STSP_ERR_NOT_INITIALIZED;
    }
    ctrl->next_tick = 0u;
    ctrl->stage_end = 0u;
    ctrl->stage = 0u;
    ctrl->latched = 0u;
    ctrl->sat_mask = 0u;
    stsp_zero(ctrl->v, STSP_MAX_LATCH);
    return STSP_OK;
}

stsp_status_t stsp_verify(stsp_ctrl_t *ctrl)
{
    if (ctrl == NULL) {
        return STSP_ERR_NULL;
    }
    if (ctrl->ready != STSP_CTRL_READY) {
        return STSP_ERR_NOT_INITIALIZED;
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

#ifndef STSP_ARITH_FIXED
/* The stage-0 latch of a band table: v = the band dual's multipliers for the measured x,
 * rounded to binary32, zero beyond q. Returns 1 on success; 0 if the solver failed (v_new
 * untouched): x not finite (the affine fallback then propagates the NaN/Inf, and the step
 * fails with STSP_ERR_NONFINITE_STATE as for any table), Nt x + mt overflowed, no active set
 * met the optimality conditions (W not positive definite in double precision), or a
 * multiplier lies outside the binary32 range. Out of line: its ~0.8 KB of
 * stack (solver work area) is used on this tick only. */
static STSP_NOINLINE int stsp_band_latch(const stsp_header_t *h, const stsp_f32_t *x,
                                         stsp_f32_t *v_new)
{
    stsp_bandqp_work_t work;
    double lam[STSP_BANDQP_MAX];
    const uint32_t q = h->band.q;
    uint32_t i;
    /* The validated copy of the band dual's header, not the table's: q and nx as init checked. */
    if (stsp_bandqp_solve(&h->band, x, lam, &work, NULL) != STSP_BANDQP_OK) {
        return 0;
    }
    /* A multiplier beyond the binary32 range has no float value (the conversion would be
     * undefined): fall back as for a failed solve. */
    for (i = 0u; i < q; ++i) {
        if (!((lam[i] <= (double)FLT_MAX) && (lam[i] >= -(double)FLT_MAX))) {
            return 0;
        }
    }
    for (i = 0u; i < stsp_nl(h); ++i) {
        v_new[i] = (i < q) ? (stsp_f32_t)lam[i] : 0.0f;
    }
    return 1;
}
#endif

/* What a tick other than the ordinary one does: decided before anything is written. */
typedef struct {
    uint16_t stage;   /* stage of the tick */
    uint16_t relatch; /* nonzero: v_new holds a fresh latch for `stage` */
} stsp_plan_t;

/* Cold path, part 1: range and order checks, stage search, and the latch v_new = Lambda x +
 * lambda0 (or a copy of the v kept) into the caller's scratch: the instance changes only on
 * success, in stsp_commit(). Returns a negative error, or the tick warning (or STSP_OK). */
static stsp_status_t stsp_plan(const stsp_ctrl_t *c, uint32_t tick, const stsp_scalar_t *x,
                               stsp_scalar_t *v_new, stsp_plan_t *plan)
{
    const stsp_header_t *h = &c->checked;
    const uint32_t nx = stsp_nx(h);
    const uint32_t nl = stsp_nl(h);
    stsp_status_t status = STSP_OK;
    uint32_t i;
    uint32_t np;
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
    /* A stage with stage_np > 0 latches a fresh v at its first tick; one with stage_np == 0
     * keeps the v latched earlier (joint multipliers are latched once, at stage 0). Only
     * columns below nl are ever touched, whatever stage_np holds. */
    np = h->stage_np[stage];
    plan->stage = stage;
    plan->relatch = 0u;
    if ((c->latched == 0u) || ((stage != c->stage) && (np > 0u))) {
        plan->relatch = 1u;
    }
#ifndef STSP_ARITH_FIXED
    if ((plan->relatch != 0u) && (stage == 0u) && (h->band_qp != NULL)) {
        if (stsp_band_latch(h, x, v_new) != 0) {
            return status;
        }
        status = STSP_WARN_BAND_FALLBACK; /* the affine map below, from the design's x0 */
    }
#endif
    if (plan->relatch != 0u) {
        for (i = 0u; i < nl; ++i) {
            stsp_scalar_t acc = (stsp_scalar_t)0;
            if (i < np) {
                const uint32_t row = ((uint32_t)stage * nl) + i;
                const stsp_scalar_t *lam = &h->Lambda[row * nx];
                uint32_t j;
#ifdef STSP_ARITH_FIXED
                /* v_q = round half up of lambda0 + sum_j Lambda x_q / 2^F, exact in stsp_uacc_t
                 * and within +-(2^F - 1) (the row bound of stsp_check_values). */
                stsp_uacc_t sum = stsp_q_start();
                for (j = 0u; j < nx; ++j) {
                    sum = stsp_q_mac(sum, lam[j], x[j]);
                }
                acc = stsp_q_round(sum, h->lambda0[row]);
#else
                acc = h->lambda0[row];
                for (j = 0u; j < nx; ++j) {
                    acc += lam[j] * x[j];
                }
#endif
            }
            v_new[i] = acc;
        }
    } else {
        for (i = 0u; i < nl; ++i) {
            v_new[i] = c->v[i];
        }
    }
    return status;
}

/* Cold path, part 2: the step succeeded; record the stage, the latch and the tick. The stage
 * end the ordinary tick compares with never exceeds the validated n_ticks, even if stage_start
 * changed since init: the law never indexes a tick beyond the table. */
static void stsp_commit(stsp_ctrl_t *c, uint32_t tick, const stsp_plan_t *plan,
                        const stsp_scalar_t *v_new)
{
    const stsp_header_t *h = &c->checked;
    const uint32_t end = h->stage_start[(uint32_t)plan->stage + 1u];
    if (plan->relatch != 0u) {
        uint32_t i;
        for (i = 0u; i < stsp_nl(h); ++i) {
            c->v[i] = v_new[i];
        }
        c->latched = 1u;
    }
    c->stage = plan->stage;
    c->stage_end = (end < h->n_ticks) ? end : h->n_ticks;
    if ((tick + 1u) > c->next_tick) {
        c->next_tick = tick + 1u;
    }
}

/* Clamps u[i] to [u_min[i], u_max[i]] (bits of *mask); STSP_WARN_SATURATED if any was, else
 * STSP_OK. */
static stsp_status_t stsp_clamp(const stsp_header_t *h, stsp_scalar_t *u, uint16_t *mask)
{
    const uint32_t nu = stsp_nu(h);
    uint32_t i;
    uint32_t m = 0u;
    for (i = 0u; i < nu; ++i) {
        if (u[i] > h->u_max[i]) {
            u[i] = h->u_max[i];
            m |= (uint32_t)1u << i;
        } else if (u[i] < h->u_min[i]) {
            u[i] = h->u_min[i];
            m |= (uint32_t)1u << i;
        } else {
            /* within the limits */
        }
    }
    *mask = (uint16_t)m;
    return (m != 0u) ? STSP_WARN_SATURATED : STSP_OK;
}

#ifdef STSP_ARITH_FIXED
/* Cold path, part 3, fixed point: some y[i] is outside [u_min[i], u_max[i]]; clamp it (the
 * law's u_q is always a valid integer: there is no non-finite case). */
static stsp_status_t stsp_limit(const stsp_header_t *h, const stsp_scalar_t *x,
                                stsp_scalar_t *y, uint16_t *mask)
{
    (void)x;
    return stsp_clamp(h, y, mask);
}

/* The law at `tick` with multipliers v, fixed point (Q15: 32-bit accumulator, Q31: 64-bit),
 * into y (never the caller's u: x and u may overlap):
 *     u_q[i] = floor((k0[i] 2^F + sum_j K[i][j] x_q[j] + sum_c L[i][c] v_q[c]) / 2^F + 1/2)
 * (the table stores -K, -k0, -L: one multiply-accumulate per term). Scaling: every term of
 * row i is in units of 2^(u_exp[i] - 2F) (the gains carry x_exp, v_exp and u_exp), so the
 * only shift is the final one by F. Overflow: none; the sum is exact (integer, any order
 * gives the same bits) and bounded by (2^F - 1) 2^F, the accumulator by 2^(2F+1) (see
 * stsp_uacc_t); u_q is within +-(2^F - 1) without saturation. Returns nonzero when some u_q[i]
 * lies outside [u_min[i], u_max[i]] (only checked when the table is limited). */
static STSP_ALWAYS_INLINE uint32_t stsp_law(const stsp_header_t *h, uint32_t tick,
                                            const stsp_scalar_t *x, const stsp_scalar_t *v,
                                            stsp_scalar_t *y, uint32_t limited)
{
    const uint32_t nx = stsp_nx(h);
    const uint32_t nu = stsp_nu(h);
    const uint32_t nl = stsp_nl(h);
    const stsp_scalar_t *K = &h->K[tick * (nu * nx)];
    const stsp_scalar_t *k0 = &h->k0[tick * nu];
    /* L may be NULL when nl == 0: no pointer arithmetic on it then. */
    const stsp_scalar_t *L = (nl > 0u) ? &h->L[tick * (nu * nl)] : h->L;
    uint32_t i;
    uint32_t out = 0u;
    STSP_UNROLL
    for (i = 0u; i < nu; ++i) {
        stsp_uacc_t acc = stsp_q_start();
        uint32_t j;
        STSP_UNROLL
        for (j = 0u; j < nx; ++j) {
            acc = stsp_q_mac(acc, K[j], x[j]);
        }
        K = &K[nx];
        if (nl > 0u) {
            STSP_UNROLL
            for (j = 0u; j < nl; ++j) {
                acc = stsp_q_mac(acc, L[j], v[j]);
            }
            L = &L[nl];
        }
        y[i] = stsp_q_round(acc, k0[i]);
    }
    if (limited != 0u) {
        STSP_UNROLL
        for (i = 0u; i < nu; ++i) {
            if ((y[i] < h->u_min[i]) || (y[i] > h->u_max[i])) {
                out = 1u;
            }
        }
    }
    return out;
}
#else
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
 * check). */
static stsp_status_t stsp_limit(const stsp_header_t *h, const stsp_f32_t *x, stsp_f32_t *y,
                                uint16_t *mask)
{
    if (stsp_all_finite(y, stsp_nu(h)) == 0) {
        return stsp_nonfinite_status(h, x);
    }
    return stsp_clamp(h, y, mask);
}

/* The law at `tick` with multipliers v, into y (never the caller's u: x and u may overlap),
 * in the documented order:
 *     u[i] = (((-(K[i][0] x[0]) - k0[i]) - K[i][1] x[1]) - ... ) - L[i][0] v[0] - ...
 * which is -(k0[i] + K[i][0] x[0] + ... + L[i][c] v[c] ...) exactly (IEEE rounding is
 * symmetric; a+b = b+a), up to the sign of an exactly zero result; starting from -(K x)
 * folds the final negation away, and each step is one stsp_nmla()/stsp_mls() (one VNMLA or
 * VMLS on the M4F, same bits). Returns nonzero when the command needs the cold path: with limits, some
 * u[i] outside [u_min[i], u_max[i]] (false for NaN, and for one of +-Inf since the limits are
 * finite); without, the sum of the u[i] is not finite (any NaN or Inf makes it NaN or Inf; a
 * finite sum that overflows is a false alarm that stsp_limit() clears). Inlined into callers
 * whose y is a local array, so that in an STSP_FIXED_* build x, v and y stay in registers. */
static STSP_ALWAYS_INLINE uint32_t stsp_law(const stsp_header_t *h, uint32_t tick,
                                            const stsp_f32_t *x, const stsp_f32_t *v,
                                            stsp_f32_t *y, uint32_t limited)
{
    const uint32_t nx = stsp_nx(h);
    const uint32_t nu = stsp_nu(h);
    const uint32_t nl = stsp_nl(h);
    const stsp_f32_t *K = &h->K[tick * (nu * nx)];
    const stsp_f32_t *k0 = &h->k0[tick * nu];
    /* L may be NULL when nl == 0: no pointer arithmetic on it then. */
    const stsp_f32_t *L = (nl > 0u) ? &h->L[tick * (nu * nl)] : h->L;
    uint32_t i;
    uint32_t out = 0u;
    STSP_UNROLL
    for (i = 0u; i < nu; ++i) {
        stsp_f32_t acc = stsp_nmla(K[0], x[0], k0[i]);
        uint32_t j;
        STSP_UNROLL
        for (j = 1u; j < nx; ++j) {
            acc = stsp_mls(acc, K[j], x[j]);
        }
        K = &K[nx];
        if (nl > 0u) {
            STSP_UNROLL
            for (j = 0u; j < nl; ++j) {
                acc = stsp_mls(acc, L[j], v[j]);
            }
            L = &L[nl];
        }
        y[i] = acc;
    }
    if (limited != 0u) {
        const stsp_f32_t *lo = h->u_min;
        const stsp_f32_t *hi = h->u_max;
        STSP_UNROLL
        for (i = 0u; i < nu; ++i) {
            if (!((y[i] >= lo[i]) && (y[i] <= hi[i]))) {
                out = 1u;
            }
        }
    } else {
        stsp_f32_t sum = -0.0f; /* -0 + a = a for every a: the compiler drops this add */
        STSP_UNROLL
        for (i = 0u; i < nu; ++i) {
            sum += y[i];
        }
        /* sum - sum is +0 for a finite sum, NaN for NaN and +-Inf. */
        if (!((sum - sum) == 0.0f)) {
            out = 1u;
        }
    }
    return out;
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

/* An ordinary tick whose command is not finite: the error, u zeroed (x not yet overwritten). */
static STSP_NOINLINE stsp_status_t stsp_step_nonfinite(const stsp_ctrl_t *ctrl,
                                                       const stsp_f32_t *x, stsp_f32_t *u)
{
    const stsp_status_t st = stsp_nonfinite_status(&ctrl->checked, x);
    stsp_zero(u, stsp_nu(&ctrl->checked));
    return st;
}
#endif /* STSP_ARITH_FIXED */

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
    stsp_zero(v_new, STSP_MAX_LATCH);
    status = stsp_plan(ctrl, tick, x, v_new, &plan);
    if (status >= STSP_OK) {
        if (stsp_law(h, tick, x, v_new, y, ctrl->limited) != 0u) {
            const stsp_status_t st = stsp_limit(h, x, y, &mask);
            if (st != STSP_OK) {
                status = st; /* an error, or STSP_WARN_SATURATED over a tick warning */
            }
        }
    }
    if (status < STSP_OK) {
        stsp_zero(u, stsp_nu(h));
        return status;
    }
    stsp_copy(u, y, stsp_nu(h));
    ctrl->sat_mask = mask;
    stsp_commit(ctrl, tick, &plan, v_new);
    return status;
}

/* An ordinary tick whose finite command (already in u) is out of range, or a false alarm. */
static STSP_NOINLINE stsp_status_t stsp_step_fixup(stsp_ctrl_t *ctrl, uint32_t tick,
                                                   stsp_scalar_t *u)
{
    uint16_t mask = 0u;
    const stsp_status_t st = stsp_clamp(&ctrl->checked, u, &mask);
    ctrl->sat_mask = mask;
    ctrl->next_tick = tick + 1u;
    return st;
}

/* Not ready: u is not written, as nu is unknown; except for an instance stsp_verify() stopped,
 * which knows its validated nu and holds zeros there. */
static STSP_NOINLINE stsp_status_t stsp_step_refused(const stsp_ctrl_t *ctrl, stsp_scalar_t *u)
{
    if (ctrl->ready == STSP_CTRL_STOPPED) {
        stsp_zero(u, stsp_nu(&ctrl->checked));
    }
    return STSP_ERR_NOT_INITIALIZED;
}

stsp_status_t stsp_step(stsp_ctrl_t *ctrl, uint32_t tick, const stsp_scalar_t *x,
                        stsp_scalar_t *u)
{
    stsp_scalar_t y[STSP_MAX_NU];
    uint32_t out;
    if ((u == NULL) || (ctrl == NULL)) {
        return STSP_ERR_NULL;
    }
    if (ctrl->ready != STSP_CTRL_READY) {
        return stsp_step_refused(ctrl, u);
    }
    if (x == NULL) {
        stsp_zero(u, stsp_nu(&ctrl->checked));
        return STSP_ERR_NULL;
    }
    /* Ordinary tick: the expected one, inside the latched stage (stage_end is 0 until the
     * first latch, and never above n_ticks). Anything else takes the cold path. */
    if ((tick != ctrl->next_tick) || (tick >= ctrl->stage_end)) {
        return stsp_step_cold(ctrl, tick, x, u);
    }
    out = stsp_law(&ctrl->checked, tick, x, ctrl->v, y, ctrl->limited);
#ifndef STSP_ARITH_FIXED
    /* A NaN/Inf command: which error it is depends on x, read before u is written. */
    if ((out != 0u) && (stsp_command_finite(&ctrl->checked, y) == 0)) {
        return stsp_step_nonfinite(ctrl, x, u);
    }
#endif
    stsp_copy(u, y, stsp_nu(&ctrl->checked));
    if (out != 0u) {
        return stsp_step_fixup(ctrl, tick, u);
    }
    ctrl->next_tick = tick + 1u;
    return STSP_OK;
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
    default: text = "unknown status"; break;
    }
    return text;
}
#endif
