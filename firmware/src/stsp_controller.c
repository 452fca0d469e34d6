/* Latched time-varying affine controller: see stospline/stsp_controller.h for the contract
 * and docs/firmware.md for the response to every fault and the MISRA deviations.
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


/* Binary32 exponent field: all ones for NaN and +-Inf. */
#define STSP_F32_EXP_MASK 0x7F800000u
/* Binary64 exponent field. */
#define STSP_F64_EXP_MASK 0x7FF0000000000000u

/* A binary32 is finite unless its exponent bits are all ones (NaN, +-Inf). */
static inline int stsp_isfinite_f32(stsp_f32_t value)
{
    uint32_t bits;
    (void)memcpy(&bits, &value, sizeof bits);
    return ((bits & STSP_F32_EXP_MASK) != STSP_F32_EXP_MASK) ? 1 : 0;
}
#endif

static inline void stsp_zero(stsp_scalar_t *u, uint32_t count)
{
    uint32_t i;
    for (i = 0u; i < count; ++i) {
        u[i] = (stsp_scalar_t)0;
    }
}

/* Dimensions as the law uses them: compile-time constants in an STSP_FIXED_* build. */
static inline uint32_t stsp_nx(const stsp_table_t *t)
{
#ifdef STSP_FIXED_NX
    (void)t;
    return (uint32_t)STSP_FIXED_NX;
#else
    return (uint32_t)t->nx;
#endif
}

static inline uint32_t stsp_nu(const stsp_table_t *t)
{
#ifdef STSP_FIXED_NU
    (void)t;
    return (uint32_t)STSP_FIXED_NU;
#else
    return (uint32_t)t->nu;
#endif
}

static inline uint32_t stsp_nl(const stsp_table_t *t)
{
#ifdef STSP_FIXED_N_LATCH
    (void)t;
    return (uint32_t)STSP_FIXED_N_LATCH;
#else
    return (uint32_t)t->n_latch;
#endif
}

#ifndef STSP_ARITH_FIXED
/* A band dual belongs to a joint design: q rows, all latched once at stage 0. */
static stsp_status_t stsp_check_band_dims(const stsp_table_t *t)
{
    const stsp_bandqp_t *b = t->band_qp;
    uint32_t s;
    if ((b->Nt == NULL) || (b->mt == NULL) || (b->W == NULL) || (b->lo == NULL) ||
        (b->hi == NULL)) {
        return STSP_ERR_NULL;
    }
    if ((b->q == 0u) || (b->q > STSP_BANDQP_MAX) || (b->nx != t->nx) ||
        (b->q != t->stage_np[0])) {
        return STSP_ERR_BAD_DIMS;
    }
    for (s = 1u; s < t->n_stages; ++s) {
        if (t->stage_np[s] != 0u) {
            return STSP_ERR_BAD_DIMS;
        }
    }
    return STSP_OK;
}
#endif

static stsp_status_t stsp_check_dims(const stsp_table_t *t)
{
    uint32_t s;
    if ((t->nx == 0u) || (t->nx > STSP_MAX_NX) || (t->nu == 0u) || (t->nu > STSP_MAX_NU) ||
        (t->n_latch > STSP_MAX_LATCH) || (t->n_stages == 0u) ||
        (t->n_stages > STSP_MAX_STAGES) || (t->n_ticks == 0u) || (t->tick_hz == 0u)) {
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
    return (t->band_qp != NULL) ? STSP_ERR_BAD_DIMS : STSP_OK;
#else
    return (t->band_qp != NULL) ? stsp_check_band_dims(t) : STSP_OK;
#endif
}

#ifdef STSP_ARITH_FIXED
/* Fixed-point accumulator. It holds the bias 2^(2F) + 2^(F-1) plus a row's sum of products,
 * which stsp_check_values() bounds by (2^F - 1) 2^F in magnitude: so it stays in
 * [2^(F-1) + 2^F, 2^(2F+1)), inside int32 for Q15 (2^31) and int64 for Q31 (2^63), and is
 * never negative (see stsp_q_round). */
#if defined(STSP_ARITH_Q15)
typedef int32_t stsp_acc_t;
typedef uint32_t stsp_uacc_t;
static const stsp_acc_t stsp_q_one = 32768;          /* 2^F */
static const stsp_acc_t stsp_q_bias = 1073758208;    /* 2^(2F) + 2^(F-1) */
#else
typedef int64_t stsp_acc_t;
typedef uint64_t stsp_uacc_t;
static const stsp_acc_t stsp_q_one = INT64_C(2147483648);
static const stsp_acc_t stsp_q_bias = INT64_C(4611686019501129728);
#endif

/* The exact product a b in the accumulator type: |a b| <= 2^(2F), no overflow. One
 * multiply-accumulate instruction on the Cortex-M4 (smlabb for Q15, smlal for Q31). ARMv6-M
 * (Cortex-M0/M0+) has no 32x32->64 multiply: there a Q31 product is a libgcc __aeabi_lmul
 * call (see docs/firmware.md for its cost, and for the 16-bit-halves alternative measured and
 * not kept); Q15 is the variant for those cores. */
static inline stsp_acc_t stsp_q_mul(stsp_scalar_t a, stsp_scalar_t b)
{
    return (stsp_acc_t)a * (stsp_acc_t)b;
}

/* floor(sum / 2^F + 1/2) for acc = 2^(2F) + 2^(F-1) + sum: round half up, by a shift of a
 * non-negative value (no implementation-defined shift of a negative one). With
 * |sum| <= (2^F - 1) 2^F the result lies in [-(2^F - 1), 2^F - 1]: no saturation needed. */
static inline stsp_scalar_t stsp_q_round(stsp_acc_t acc)
{
    const stsp_uacc_t shifted = (stsp_uacc_t)acc >> STSP_Q_FRAC_BITS;
    const stsp_acc_t rounded = (stsp_acc_t)shifted - stsp_q_one;
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
static stsp_status_t stsp_check_values(const stsp_table_t *t)
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
static uint16_t stsp_has_limits(const stsp_table_t *t)
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
    uint32_t i;
    for (i = 0u; i < count; ++i) {
        uint64_t bits;
        (void)memcpy(&bits, &values[i], sizeof bits);
        if ((bits & STSP_F64_EXP_MASK) == STSP_F64_EXP_MASK) {
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
static stsp_status_t stsp_check_values(const stsp_table_t *t)
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
    return (t->band_qp != NULL) ? stsp_check_band_values(t->band_qp) : STSP_OK;
}

/* 1 if some input has a limit other than -FLT_MAX/FLT_MAX (selects the fast-path check). */
static uint16_t stsp_has_limits(const stsp_table_t *t)
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

uint32_t stsp_table_crc32(const stsp_table_t *table)
{
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
    crc = stsp_crc32_u32(crc, table->tick_hz);
#ifdef STSP_ARITH_FIXED
    crc = stsp_crc32_u32(crc, (uint32_t)table->scalar_kind);
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
    if (table->band_qp != NULL) {
        const stsp_bandqp_t *b = table->band_qp;
        const uint32_t q = b->q;
        crc = stsp_crc32_u32(crc, q);
        crc = stsp_crc32_u32(crc, (uint32_t)b->nx);
        crc = stsp_crc32_f64s(crc, b->Nt, q * (uint32_t)b->nx);
        crc = stsp_crc32_f64s(crc, b->mt, q);
        crc = stsp_crc32_f64s(crc, b->W, q * q);
        crc = stsp_crc32_f64s(crc, b->lo, q);
        crc = stsp_crc32_f64s(crc, b->hi, q);
    }
    crc = stsp_crc32_bytes(crc, table->problem_sha256, (uint32_t)sizeof table->problem_sha256);
    return stsp_crc32_end(crc);
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
    st = stsp_check_dims(table);
    if (st != STSP_OK) {
        return st;
    }
    if (stsp_table_crc32(table) != table->crc32) {
        return STSP_ERR_BAD_CRC;
    }
    st = stsp_check_values(table);
    if (st != STSP_OK) {
        return st;
    }
    ctrl->table = table;
    ctrl->limited = stsp_has_limits(table);
    ctrl->ready = STSP_CTRL_READY;
    return STSP_OK;
}

stsp_status_t stsp_init_expect(stsp_ctrl_t *ctrl, const stsp_table_t *table, uint32_t nx,
                               uint32_t nu)
{
    stsp_status_t st = stsp_init(ctrl, table);
    if ((st == STSP_OK) && ((table->nx != nx) || (table->nu != nu))) {
        ctrl->ready = 0u;
        ctrl->table = NULL;
        st = STSP_ERR_BAD_DIMS;
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
        ctrl->ready = 0u;
        ctrl->table = NULL;
        st = STSP_ERR_BAD_PROBLEM;
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
    if (stsp_table_crc32(ctrl->table) != ctrl->table->crc32) {
        ctrl->ready = 0u;
        return STSP_ERR_BAD_CRC;
    }
    return STSP_OK;
}

/* Stage containing `tick`, searching forward from `from` (ticks only move forward). */
static uint16_t stsp_stage_of(const stsp_table_t *t, uint16_t from, uint32_t tick)
{
    uint32_t s = from;
    while (((s + 1u) < t->n_stages) && (t->stage_start[s + 1u] <= tick)) {
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
static STSP_NOINLINE int stsp_band_latch(const stsp_table_t *t, const stsp_f32_t *x,
                                         stsp_f32_t *v_new)
{
    stsp_bandqp_work_t work;
    double lam[STSP_BANDQP_MAX];
    const uint32_t q = t->band_qp->q;
    uint32_t i;
    if (stsp_bandqp_solve(t->band_qp, x, lam, &work, NULL) != STSP_BANDQP_OK) {
        return 0;
    }
    /* A multiplier beyond the binary32 range has no float value (the conversion would be
     * undefined): fall back as for a failed solve. */
    for (i = 0u; i < q; ++i) {
        if (!((lam[i] <= (double)FLT_MAX) && (lam[i] >= -(double)FLT_MAX))) {
            return 0;
        }
    }
    for (i = 0u; i < stsp_nl(t); ++i) {
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
    const stsp_table_t *t = c->table;
    const uint32_t nx = stsp_nx(t);
    const uint32_t nl = stsp_nl(t);
    stsp_status_t status = STSP_OK;
    uint32_t i;
    uint32_t np;
    uint16_t stage;

    if (tick >= t->n_ticks) {
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
    stage = stsp_stage_of(t, c->stage, tick);
    /* A stage with stage_np > 0 latches a fresh v at its first tick; one with stage_np == 0
     * keeps the v latched earlier (joint multipliers are latched once, at stage 0). */
    np = t->stage_np[stage];
    plan->stage = stage;
    plan->relatch = 0u;
    if ((c->latched == 0u) || ((stage != c->stage) && (np > 0u))) {
        plan->relatch = 1u;
    }
#ifndef STSP_ARITH_FIXED
    if ((plan->relatch != 0u) && (stage == 0u) && (t->band_qp != NULL)) {
        if (stsp_band_latch(t, x, v_new) != 0) {
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
                const stsp_scalar_t *lam = &t->Lambda[row * nx];
                uint32_t j;
#ifdef STSP_ARITH_FIXED
                /* v_q = round half up of lambda0 + sum_j Lambda x_q / 2^F, exact in stsp_acc_t
                 * and within +-(2^F - 1) (the row bound of stsp_check_values). */
                stsp_acc_t sum = stsp_q_bias + ((stsp_acc_t)t->lambda0[row] * stsp_q_one);
                for (j = 0u; j < nx; ++j) {
                    sum += stsp_q_mul(lam[j], x[j]);
                }
                acc = stsp_q_round(sum);
#else
                acc = t->lambda0[row];
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

/* Cold path, part 2: the step succeeded; record the stage, the latch and the tick. */
static void stsp_commit(stsp_ctrl_t *c, uint32_t tick, const stsp_plan_t *plan,
                        const stsp_scalar_t *v_new)
{
    const stsp_table_t *t = c->table;
    if (plan->relatch != 0u) {
        uint32_t i;
        for (i = 0u; i < stsp_nl(t); ++i) {
            c->v[i] = v_new[i];
        }
        c->latched = 1u;
    }
    c->stage = plan->stage;
    c->stage_end = t->stage_start[(uint32_t)plan->stage + 1u];
    if ((tick + 1u) > c->next_tick) {
        c->next_tick = tick + 1u;
    }
}

/* Clamps u[i] to [u_min[i], u_max[i]] (bits of *mask); STSP_WARN_SATURATED if any was, else
 * STSP_OK. */
static stsp_status_t stsp_clamp(const stsp_table_t *t, stsp_scalar_t *u, uint16_t *mask)
{
    const uint32_t nu = stsp_nu(t);
    uint32_t i;
    uint32_t m = 0u;
    for (i = 0u; i < nu; ++i) {
        if (u[i] > t->u_max[i]) {
            u[i] = t->u_max[i];
            m |= (uint32_t)1u << i;
        } else if (u[i] < t->u_min[i]) {
            u[i] = t->u_min[i];
            m |= (uint32_t)1u << i;
        } else {
            /* within the limits */
        }
    }
    *mask = (uint16_t)m;
    return (m != 0u) ? STSP_WARN_SATURATED : STSP_OK;
}

#ifdef STSP_ARITH_FIXED
/* Cold path, part 3, fixed point: some u[i] is outside [u_min[i], u_max[i]]; clamp it (the
 * law's u_q is always a valid integer: there is no non-finite case). */
static STSP_NOINLINE stsp_status_t stsp_limit(const stsp_table_t *t, const stsp_scalar_t *x,
                                              stsp_scalar_t *u, uint16_t *mask)
{
    (void)x;
    return stsp_clamp(t, u, mask);
}

/* The law at `tick` with multipliers v, fixed point (Q15: int32 accumulator, Q31: int64):
 *     u_q[i] = floor((k0[i] 2^F + sum_j K[i][j] x_q[j] + sum_c L[i][c] v_q[c]) / 2^F + 1/2)
 * (the table stores -K, -k0, -L: one multiply-accumulate per term). Scaling: every term of
 * row i is in units of 2^(u_exp[i] - 2F) (the gains carry x_exp, v_exp and u_exp), so the
 * only shift is the final one by F. Overflow: none; the sum is exact (integer, any order
 * gives the same bits) and bounded by (2^F - 1) 2^F, the accumulator by 2^(2F+1) (see
 * stsp_acc_t); u_q is within +-(2^F - 1) without saturation. Returns nonzero when some u_q[i]
 * lies outside [u_min[i], u_max[i]] (only checked when the table is limited). */
static STSP_ALWAYS_INLINE uint32_t stsp_law(const stsp_table_t *t, uint32_t tick,
                                            const stsp_scalar_t *x, const stsp_scalar_t *v,
                                            stsp_scalar_t *u, uint32_t limited)
{
    const uint32_t nx = stsp_nx(t);
    const uint32_t nu = stsp_nu(t);
    const uint32_t nl = stsp_nl(t);
    const stsp_scalar_t *K = &t->K[tick * (nu * nx)];
    const stsp_scalar_t *k0 = &t->k0[tick * nu];
    /* L may be NULL when nl == 0: no pointer arithmetic on it then. */
    const stsp_scalar_t *L = (nl > 0u) ? &t->L[tick * (nu * nl)] : t->L;
    stsp_scalar_t y[STSP_MAX_NU];
    uint32_t i;
    uint32_t out = 0u;
    STSP_UNROLL
    for (i = 0u; i < nu; ++i) {
        stsp_acc_t acc = stsp_q_bias + ((stsp_acc_t)k0[i] * stsp_q_one);
        uint32_t j;
        STSP_UNROLL
        for (j = 0u; j < nx; ++j) {
            acc += stsp_q_mul(K[j], x[j]);
        }
        K = &K[nx];
        if (nl > 0u) {
            STSP_UNROLL
            for (j = 0u; j < nl; ++j) {
                acc += stsp_q_mul(L[j], v[j]);
            }
            L = &L[nl];
        }
        y[i] = stsp_q_round(acc);
    }
    if (limited != 0u) {
        STSP_UNROLL
        for (i = 0u; i < nu; ++i) {
            if ((y[i] < t->u_min[i]) || (y[i] > t->u_max[i])) {
                out = 1u;
            }
        }
    }
    STSP_UNROLL
    for (i = 0u; i < nu; ++i) {
        u[i] = y[i];
    }
    return out;
}
#else
/* Cold path, part 3: some u[i] may be outside [u_min[i], u_max[i]] or not finite. If any is
 * NaN/Inf, returns the error that says why: the state was not finite, or it was and the law
 * (or the latch) overflowed. Otherwise clamps (bits of *mask) and returns
 * STSP_WARN_SATURATED, or STSP_OK if nothing needed clamping (a false alarm of the fast
 * check). */
static STSP_NOINLINE stsp_status_t stsp_limit(const stsp_table_t *t, const stsp_f32_t *x,
                                              stsp_f32_t *u, uint16_t *mask)
{
    const uint32_t nu = stsp_nu(t);
    uint32_t i;
    for (i = 0u; i < nu; ++i) {
        if (stsp_isfinite_f32(u[i]) == 0) {
            return (stsp_all_finite(x, stsp_nx(t)) == 0) ? STSP_ERR_NONFINITE_STATE
                                                         : STSP_ERR_NONFINITE_OUTPUT;
        }
    }
    return stsp_clamp(t, u, mask);
}

/* The law at `tick` with multipliers v, in the documented order:
 *     u[i] = (((-(K[i][0] x[0]) - k0[i]) - K[i][1] x[1]) - ... ) - L[i][0] v[0] - ...
 * which is -(k0[i] + K[i][0] x[0] + ... + L[i][c] v[c] ...) exactly (IEEE rounding is
 * symmetric; a+b = b+a), up to the sign of an exactly zero result; starting from -(K x)
 * folds the final negation away, and each step is one stsp_nmla()/stsp_mls() (one VNMLA or
 * VMLS on the M4F, same bits). Returns nonzero when the command needs the cold path: with limits, some
 * u[i] outside [u_min[i], u_max[i]] (false for NaN, and for one of +-Inf since the limits are
 * finite); without, the sum of the u[i] is not finite (any NaN or Inf makes it NaN or Inf; a
 * finite sum that overflows is a false alarm that stsp_limit() clears). The sums stay in
 * locals until every load is done, so x and v can stay in registers (u may alias them as far
 * as the compiler knows). */
static STSP_ALWAYS_INLINE uint32_t stsp_law(const stsp_table_t *t, uint32_t tick,
                                            const stsp_f32_t *x, const stsp_f32_t *v,
                                            stsp_f32_t *u, uint32_t limited)
{
    const uint32_t nx = stsp_nx(t);
    const uint32_t nu = stsp_nu(t);
    const uint32_t nl = stsp_nl(t);
    const stsp_f32_t *K = &t->K[tick * (nu * nx)];
    const stsp_f32_t *k0 = &t->k0[tick * nu];
    /* L may be NULL when nl == 0: no pointer arithmetic on it then. */
    const stsp_f32_t *L = (nl > 0u) ? &t->L[tick * (nu * nl)] : t->L;
    stsp_f32_t y[STSP_MAX_NU];
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
        const stsp_f32_t *lo = t->u_min;
        const stsp_f32_t *hi = t->u_max;
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
    STSP_UNROLL
    for (i = 0u; i < nu; ++i) {
        u[i] = y[i];
    }
    return out;
}
#endif /* STSP_ARITH_FIXED */

/* Every tick but the ordinary one: range, order, repeat, skip, stage change, latch. */
static STSP_NOINLINE stsp_status_t stsp_step_cold(stsp_ctrl_t *ctrl, uint32_t tick,
                                                  const stsp_scalar_t *x, stsp_scalar_t *u)
{
    const stsp_table_t *t = ctrl->table;
    stsp_scalar_t v_new[STSP_MAX_LATCH];
    stsp_plan_t plan = {0u, 0u};
    stsp_status_t status;
    uint16_t mask = 0u;
    stsp_zero(v_new, STSP_MAX_LATCH);
    status = stsp_plan(ctrl, tick, x, v_new, &plan);
    if (status >= STSP_OK) {
        if (stsp_law(t, tick, x, v_new, u, ctrl->limited) != 0u) {
            const stsp_status_t st = stsp_limit(t, x, u, &mask);
            if (st != STSP_OK) {
                status = st; /* an error, or STSP_WARN_SATURATED over a tick warning */
            }
        }
    }
    if (status < STSP_OK) {
        stsp_zero(u, stsp_nu(t));
        return status;
    }
    ctrl->sat_mask = mask;
    stsp_commit(ctrl, tick, &plan, v_new);
    return status;
}

/* An ordinary tick whose command is out of range or not finite. */
static STSP_NOINLINE stsp_status_t stsp_step_fixup(stsp_ctrl_t *ctrl, uint32_t tick,
                                                   const stsp_scalar_t *x, stsp_scalar_t *u)
{
    uint16_t mask = 0u;
    const stsp_status_t st = stsp_limit(ctrl->table, x, u, &mask);
    if (st < STSP_OK) {
        stsp_zero(u, stsp_nu(ctrl->table));
        return st;
    }
    ctrl->sat_mask = mask;
    ctrl->next_tick = tick + 1u;
    return st;
}

stsp_status_t stsp_step(stsp_ctrl_t *ctrl, uint32_t tick, const stsp_scalar_t *x,
                        stsp_scalar_t *u)
{
    if ((u == NULL) || (ctrl == NULL)) {
        return STSP_ERR_NULL;
    }
    if (ctrl->ready != STSP_CTRL_READY) {
        return STSP_ERR_NOT_INITIALIZED; /* nu is unknown without a table: u is not written */
    }
    if (x == NULL) {
        stsp_zero(u, stsp_nu(ctrl->table));
        return STSP_ERR_NULL;
    }
    /* Ordinary tick: the expected one, inside the latched stage (stage_end is 0 until the
     * first latch, and never above n_ticks). Anything else takes the cold path. */
    if ((tick != ctrl->next_tick) || (tick >= ctrl->stage_end)) {
        return stsp_step_cold(ctrl, tick, x, u);
    }
    if (stsp_law(ctrl->table, tick, x, ctrl->v, u, ctrl->limited) != 0u) {
        return stsp_step_fixup(ctrl, tick, x, u);
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
    default: text = "unknown status"; break;
    }
    return text;
}
#endif
