/* libFuzzer target on the init/step API (built by CMakeLists.txt with clang,
 * -fsanitize=fuzzer,address,undefined; the test fuzz_step runs it for a bounded time).
 *
 * Each input describes a table and a sequence of calls. The table: dimensions (some invalid),
 * stage layout, gains (small values or raw bit patterns, so NaN/Inf/subnormal appear), limits
 * (none, finite, or invalid), the CRC (correct, or flipped), and NULL pointers now and then;
 * about one table in three carries a band dual (band_qp, format 3): q = 1..8 rows or an
 * invalid count, nx the table's or not, W positive definite, diagonal, indefinite, negative
 * definite, singular or raw bits (NaN/Inf), bands, equality rows, lo > hi, huge or
 * non-finite bounds, NULL arrays, stage_n_latch as the contract requires (q at stage 0, 0 after)
 * or not, and the CRC right or wrong; and about one table in three carries spline gains
 * (spline, format 5; fz_build_spline): valid (random spans, breakpoints, stored entries and
 * coefficients, modest, huge or subnormal; stages of up to 2^24 - 1 ticks now and then) or
 * with one corruption (knots out of order, equal, not integers, T wrong at either end,
 * row_start decreasing, a col out of range, a NaN/Inf coefficient, coef_start inconsistent,
 * lengths lying, too few knots, a NULL array, per-tick gains next to it, raw
 * index bits, a stage of 2^24 ticks or more), and now and then a knot or coefficient bit
 * changed after the CRC; now and then with a band dual too (a spline band table: its stage-0
 * latch the band solver's, the command the spline model's with that latch; W sometimes not
 * symmetric, the solver's Gaussian-elimination path). The arrays always have room for the dimensions the
 * table declares: that is the documented precondition of stsp_init() (the generated tables
 * satisfy it by construction). The calls: init, init_expect, reset, verify and step, with
 * ticks in order, repeated, skipped, backwards or past the end, states with
 * NaN/Inf/huge/subnormal entries, and NULL arguments.
 *
 * Any sanitizer report, crash, or broken invariant (abort) is a finding. The invariants are
 * the contract of stsp_controller.h: a known status; init returns exactly the status its
 * checks prescribe for a table without a main-table corruption (band checks included), and
 * never STSP_OK for a table with an invalid band dual; before init u untouched; on an error
 * u all +0.0 and the instance byte-for-byte unchanged; otherwise u finite, within
 * [u_min, u_max], and saturated inputs exactly at a limit; nothing written past u[nu]; the
 * tick bookkeeping as documented (range, order, non-finite state detected first); at the
 * stage-0 latch of a band table STSP_WARN_BAND_FALLBACK exactly when stsp_bandqp_solve()
 * fails for that state (no optimal active set, or Nt x0 + mt overflowed, which the target
 * recomputes in the solver's order) or some multiplier lies beyond +-FLT_MAX (unless
 * saturation wins); else v = (float)lam bit for bit, on a fallback v = Lambda x + lambda0 in
 * the firmware's order, and u the law with that v, clamped, bit for bit (or, if it overflows,
 * STSP_ERR_NONFINITE_OUTPUT); and the solver's own contract: at most 3^(band rows)
 * candidates, exactly that many when it finds none, none on an overflow, lam all zeros on a
 * failure. Spline tables: init returns exactly the status the spline checks prescribe
 * (fz_spline_check, written from the contract) and never STSP_OK for invalid spline gains;
 * every step of an accepted one at a tick in range and order with a finite state gives the
 * status, the command (clamped, bit for bit), the stage, the latch v and the saturation mask
 * of fz_spline_model (the stage, the latch, and The NURBS Book A2.2 literally), or
 * STSP_ERR_NONFINITE_OUTPUT exactly when that latch or command is not finite.
 *
 * Built once per arithmetic variant (fuzz_step, fuzz_step_q15, fuzz_step_q31): in the Q15/Q31
 * builds the tables, states and commands are integers (gains small enough for valid row sums,
 * or full-range ones that break the row bound), the scale exponents are fuzzed as well, and
 * there is no non-finite value. A fixed-point build has no band solver: about one table in
 * eight carries a band dual all the same (the generator above), and init must never return
 * STSP_OK for it, and return exactly STSP_ERR_BAD_DIMS when the rest of the table is valid
 * (or has any main-table corruption but magic, version and NULL arrays, which come first).
 * About one table in three carries fixed-point spline gains (stsp_qspline_t; the Q
 * fz_build_spline): valid (spans of 2^k ticks, k in 0..9, shifts 1..30, modest coefficients,
 * or full-range ones that break the row bound at some tick) or with one corruption
 * (span_log2 beyond 9, a shift of 0 or beyond 30, row_start, col, coef_start or a length
 * wrong, a NULL array, per-tick gains next to it, raw index bits), and now and then a
 * coefficient or shift bit changed after the CRC; init returns exactly the status of the
 * contract's checks (fz_spline_check, every row at every tick by exact __int128 gains from
 * the B-spline's power form, the CRC, exponents, latch rows, limits), and every step of an
 * accepted one at a tick in range and order gives the command (clamped), status, stage,
 * latch and mask of that model (fz_spline_model). */
#include <float.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fuzz_input.h"
#include "stospline/stsp_controller.h"

#define FZ_MAX_NX 7u
#define FZ_MAX_NU 4u
#define FZ_MAX_NL 8u   /* storage; >= STSP_BANDQP_MAX: a band table needs n_latch >= q */
#define FZ_MAX_NS 5u
#define FZ_MAX_STAGE_TICKS 8u
#define FZ_MAX_NT (FZ_MAX_NS * FZ_MAX_STAGE_TICKS)
#define FZ_MAX_CALLS 64u
#define FZ_BAND_STORE 16u /* band rows/states the storage holds (invalid counts up to 16) */

#ifdef STSP_ARITH_FIXED_POINT
typedef stsp_scalar_t fz_val_t;
#define FZ_Q_ONE ((int64_t)1 << STSP_Q_FRAC_BITS)
#define FZ_SENTINEL ((stsp_scalar_t)12345)
#define FZ_GEN_NL 5u   /* n_latch of a table without bands: a row of 1 + 7 + 5 small gains */
#define FZ_BAND_PICK(sel) (((sel) % 8u) == 7u) /* not an exhausted input's 0: refused */
#define FZ_SPLINE_PICK(sel) (((sel) % 3u) == 1u) /* stsp_qspline_t */
#else
typedef float fz_val_t;
#define FZ_SENTINEL 1234.5f
#define FZ_GEN_NL FZ_MAX_NL
#define FZ_BAND_PICK(sel) (((sel) % 3u) == 0u)
#define FZ_SPLINE_PICK(sel) (((sel) % 3u) == 1u)
#endif

#ifdef STSP_ARITH_FIXED_POINT
static int fz_finite(fz_val_t v)
{
    (void)v;
    return 1;
}

/* Mostly modest values; a selector byte picks the range ends, 0 or a raw bit pattern. */
static fz_val_t fz_value(fuzz_in_t *in)
{
    const uint32_t sel = fuzz_u8(in);
    if (sel < 200u) {
        return (fz_val_t)(((int64_t)fuzz_u8(in) - 128) * (FZ_Q_ONE / 256));
    }
    switch (sel % 4u) {
    case 0u: return (fz_val_t)(-FZ_Q_ONE);
    case 1u: return (fz_val_t)(FZ_Q_ONE - 1);
    case 2u: return 0;
    default: return (fz_val_t)(int64_t)(((int64_t)fuzz_u32(in) % (2 * FZ_Q_ONE)) - FZ_Q_ONE);
    }
}
#else
static float fz_bits_f32(uint32_t bits)
{
    float f;
    memcpy(&f, &bits, sizeof f);
    return f;
}

static uint32_t fz_f32_bits(float f)
{
    uint32_t bits;
    memcpy(&bits, &f, sizeof bits);
    return bits;
}

static int fz_finite(float f)
{
    return (fz_f32_bits(f) & 0x7F800000u) != 0x7F800000u;
}

static int fz_f64_is_pos_zero(double d)
{
    uint64_t bits;
    memcpy(&bits, &d, sizeof bits);
    return bits == 0u;
}

/* Mostly modest values; a selector byte picks specials or a raw bit pattern. */
static float fz_value(fuzz_in_t *in)
{
    const uint32_t sel = fuzz_u8(in);
    if (sel < 200u) {
        return ((float)(int32_t)fuzz_u8(in) - 128.0f) / 16.0f;
    }
    switch (sel % 8u) {
    case 0u: return fz_bits_f32(0x7FC00000u);          /* NaN */
    case 1u: return fz_bits_f32(0x7F800000u);          /* +Inf */
    case 2u: return fz_bits_f32(0xFF800000u);          /* -Inf */
    case 3u: return fz_bits_f32(0x7F7FFFFFu);          /* FLT_MAX */
    case 4u: return fz_bits_f32(0xFF7FFFFFu);          /* -FLT_MAX */
    case 5u: return fz_bits_f32(0x00000001u);          /* smallest subnormal */
    case 6u: return fz_bits_f32(0x80000000u);          /* -0 */
    default: return fz_bits_f32(fuzz_u32(in));           /* anything */
    }
}
#endif

/* -DFZ_STATS: count what the inputs reached and print it at exit (to see that the generator
 * reaches the band paths; not part of the ctest build). */
#ifdef FZ_STATS
enum { FZS_TABLES, FZS_BAND_TABLES, FZS_INIT_MODELLED, FZS_INIT_OK, FZS_BAND_INIT_OK,
       FZS_BAND_NULL, FZS_BAND_DIMS, FZS_BAND_CRC, FZS_BAND_VALUES, FZS_LATCH, FZS_LATCH_OK,
       FZS_LATCH_INFEASIBLE, FZS_LATCH_OVERFLOW, FZS_LATCH_BEYOND_FLT, FZS_FALLBACK,
       FZS_LATCH_Q8, FZS_LATCH_ERR, FZS_SPL_TABLES, FZS_SPL_CORRUPT, FZS_SPL_INIT_OK,
       FZS_SPL_NULL, FZS_SPL_DIMS, FZS_SPL_CRC, FZS_SPL_VALUES, FZS_SPL_READY, FZS_SPL_STEPS,
       FZS_SPL_LATCH, FZS_SPL_SAT, FZS_SPL_OVERFLOW, FZS_SPL_LONG, FZS_N };
static const char *const fzs_names[FZS_N] = {
    "tables", "band tables", "init modelled", "init ok", "band init ok", "band init ERR_NULL",
    "band init BAD_DIMS", "band init BAD_CRC", "band init BAD_VALUES", "band latch steps",
    "  solver ok", "  solver infeasible", "  solver e overflow", "  |lam| > FLT_MAX",
    "  status BAND_FALLBACK", "  q = 8", "  step error", "spline tables",
    "  with a corruption", "  init ok (model)", "  init ERR_NULL (model)",
    "  init BAD_DIMS (model)", "  init BAD_CRC (model)", "  init BAD_VALUES (model)",
    "  init ok (real)", "  steps modelled", "    latching", "    saturated",
    "    NONFINITE_OUTPUT", "    on stages > 4096 ticks"};
static unsigned long fzs[FZS_N];
static void fzs_print(void)
{
    int i;
    for (i = 0; i < FZS_N; ++i) {
        (void)fprintf(stderr, "FZ_STATS %-22s %lu\n", fzs_names[i], fzs[i]);
    }
}
#define FZS(k) (++fzs[(k)])
#else
#define FZS(k) ((void)0)
#endif

/* The statuses init/reset/verify/step can return: STSP_WARN_STATE_CLAMPED only comes from the
 * fixed-point conversion, STSP_WARN_BAND_FALLBACK only from a float32 band table. */
static int fz_known_status(stsp_status_t st)
{
    return ((st >= STSP_ERR_BAD_VALUES) && (st <= STSP_WARN_SATURATED))
#ifndef STSP_ARITH_FIXED_POINT
        || (st == STSP_WARN_BAND_FALLBACK)
#endif
        ;
}

/* Storage with room for every dimension the input can declare. */
static uint32_t g_start[FZ_MAX_NS + 1u];
static uint16_t g_stage_n_latch[FZ_MAX_NS];
static fz_val_t g_K[FZ_MAX_NT * FZ_MAX_NU * FZ_MAX_NX];
static fz_val_t g_k0[FZ_MAX_NT * FZ_MAX_NU];
static fz_val_t g_L[FZ_MAX_NT * FZ_MAX_NU * FZ_MAX_NL];
static fz_val_t g_Lambda[FZ_MAX_NS * FZ_MAX_NL * FZ_MAX_NX];
static fz_val_t g_lambda0[FZ_MAX_NS * FZ_MAX_NL];
static fz_val_t g_lo[FZ_MAX_NU], g_hi[FZ_MAX_NU], g_hold[FZ_MAX_NU];
#ifdef STSP_ARITH_FIXED_POINT
static int8_t g_xe[FZ_MAX_NX], g_ue[FZ_MAX_NU], g_ve[FZ_MAX_NL];
#endif
static stsp_bandqp_t g_band;
static double g_bNt[FZ_BAND_STORE * FZ_BAND_STORE];
static double g_bmt[FZ_BAND_STORE];
static double g_bW[FZ_BAND_STORE * FZ_BAND_STORE];
static double g_blo[FZ_BAND_STORE];
static double g_bhi[FZ_BAND_STORE];

/* What the input asked of the table, for the init model. */
typedef struct {
    uint32_t main_corrupt; /* nonzero: 1 + the main-table corruption (float32: init's status
                              not modelled) */
    uint32_t band;         /* the table carries band_qp */
    uint32_t band_crc_ok;  /* the CRC covers the band (and spline) data as it is now */
    uint32_t spline;       /* the table carries spline gains */
    uint32_t spline_corrupt; /* 1 + the spline corruption asked for, or 0 */
} fz_table_info_t;

/* Gains from a generator seeded by the input (so that a short input describes a whole table
 * and most bytes drive calls); `special` in 1..255 makes about one value in `special` a
 * special one (NaN, Inf, FLT_MAX, subnormal, -0), 0 none. */
#ifdef STSP_ARITH_FIXED_POINT
/* Fixed point: values within +-2^F/16 (a row of at most 13 of them stays below 2^F - 1);
 * `special` makes about one in `special` a full-range value, which breaks the row bound. */
static void fz_fill(uint32_t *seed, fz_val_t *a, size_t count, uint32_t special)
{
    size_t i;
    for (i = 0u; i < count; ++i) {
        *seed = *seed * 1664525u + 1013904223u;
        if ((special != 0u) && (((*seed >> 8) % special) == 0u)) {
            a[i] = (fz_val_t)((int64_t)(*seed % 65536u) * (FZ_Q_ONE / 32768) - FZ_Q_ONE);
        } else {
            a[i] = (fz_val_t)(((int64_t)((*seed >> 12) % 4096u) - 2048) * (FZ_Q_ONE / 32768));
        }
    }
}
#else
static void fz_fill(uint32_t *seed, float *a, size_t count, uint32_t special)
{
    static const uint32_t specials[6] = {0x7FC00000u, 0x7F800000u, 0xFF800000u, 0x7F7FFFFFu,
                                         0x00000001u, 0x80000000u};
    size_t i;
    for (i = 0u; i < count; ++i) {
        *seed = *seed * 1664525u + 1013904223u;
        if ((special != 0u) && (((*seed >> 8) % special) == 0u)) {
            a[i] = fz_bits_f32(specials[(*seed >> 20) % 6u]);
        } else {
            a[i] = ((float)((*seed >> 12) % 4096u) - 2048.0f) / 512.0f;
        }
    }
}
#endif

static uint32_t fz_lcg(uint32_t *seed)
{
    *seed = *seed * 1664525u + 1013904223u;
    return *seed >> 8;
}

/* A double in [-scale, scale). */
static double fz_lcg_f64(uint32_t *seed, double scale)
{
    return scale * (((double)(fz_lcg(seed) % 65536u) - 32768.0) / 32768.0);
}

static double fz_bits_f64(uint64_t bits)
{
    double d;
    memcpy(&d, &bits, sizeof d);
    return d;
}

#ifndef STSP_ARITH_FIXED_POINT
static int fz_finite_f64(double d)
{
    uint64_t bits;
    memcpy(&bits, &d, sizeof bits);
    return (bits & 0x7FF0000000000000ull) != 0x7FF0000000000000ull;
}
#endif

static double fz_special_f64(uint32_t *seed)
{
    switch (fz_lcg(seed) % 8u) {
    case 0u: return fz_bits_f64(0x7FF8000000000000ull);    /* NaN */
    case 1u: return fz_bits_f64(0x7FF0000000000000ull);    /* +Inf */
    case 2u: return fz_bits_f64(0xFFF0000000000000ull);    /* -Inf */
    case 3u: return fz_bits_f64(0x7FEFFFFFFFFFFFFFull);    /* DBL_MAX */
    case 4u: return -1e300;
    case 5u: return fz_bits_f64(0x0000000000000001ull);    /* least subnormal */
    case 6u: return fz_bits_f64(0x8000000000000000ull);    /* -0 */
    default: return fz_bits_f64(((uint64_t)fz_lcg(seed) << 40) ^ ((uint64_t)fz_lcg(seed) << 16) ^
                                (uint64_t)fz_lcg(seed));   /* anything */
    }
}

/* The band dual of a table (format 3): shape, data and contract violations from the input
 * (the same in every build: a fixed-point build must refuse whatever it is). Called with the
 * main table built; sets t->band_qp (and stage_n_latch, n_latch), and the CRC afterwards must
 * cover it. Returns the band corruption applied after the CRC (1: flip a CRC bit, 2: change a
 * band value), else 0. */
static uint32_t fz_build_band(fuzz_in_t *in, stsp_table_t *t)
{
    const uint32_t qsel = fuzz_u8(in), nxsel = fuzz_u8(in), wsel = fuzz_u8(in), rsel = fuzz_u8(in);
    const uint32_t npsel = fuzz_u8(in), nullsel = fuzz_u8(in), crcsel = fuzz_u8(in);
    uint32_t seed = fuzz_u32(in);
    uint32_t q, bnx, i, j;
    /* Rows: 1..8 mostly, else an invalid count (0, 9..16, or beyond the storage). */
    if (qsel < 224u) {
        q = 1u + qsel % STSP_BANDQP_MAX;
    } else if (qsel < 248u) {
        q = (qsel % 2u == 0u) ? 0u : STSP_BANDQP_MAX + 1u + qsel % (FZ_BAND_STORE - STSP_BANDQP_MAX);
    } else {
        q = 17u + 1000u * (qsel % 66u);
    }
    if (nxsel < 232u) {
        bnx = t->nx;
    } else {
        bnx = nxsel % (FZ_BAND_STORE + 1u);                    /* maybe t->nx anyway */
    }
    g_band.q = (uint16_t)q;
    g_band.nx = (uint16_t)bnx;
    g_band.Nt = g_bNt;
    g_band.mt = g_bmt;
    g_band.W = g_bW;
    g_band.lo = g_blo;
    g_band.hi = g_bhi;
    g_band.solve_f32 = stsp_bandqp_solve_f32;
    /* Fill the whole storage, so that every size the table may declare reads set values. */
    {
        const uint32_t nt_special = ((wsel & 0xC0u) == 0xC0u) ? 1u + fz_lcg(&seed) % 32u : 0u;
        for (i = 0u; i < FZ_BAND_STORE * FZ_BAND_STORE; ++i) {
            g_bNt[i] = ((nt_special != 0u) && (fz_lcg(&seed) % nt_special == 0u))
                ? fz_special_f64(&seed) : fz_lcg_f64(&seed, 1.0);
        }
        for (i = 0u; i < FZ_BAND_STORE; ++i) {
            g_bmt[i] = ((nt_special != 0u) && (fz_lcg(&seed) % nt_special == 0u))
                ? fz_special_f64(&seed) : fz_lcg_f64(&seed, 2.0);
        }
    }
    {
        /* W over the storage's leading q x q block (stride q, as the solver reads it). */
        const uint32_t n = (q <= FZ_BAND_STORE) ? q : FZ_BAND_STORE;
        double G[FZ_BAND_STORE * FZ_BAND_STORE];
        for (i = 0u; i < FZ_BAND_STORE * FZ_BAND_STORE; ++i) {
            G[i] = fz_lcg_f64(&seed, 1.0);
            g_bW[i] = 0.0;
        }
        for (i = 0u; i < n; ++i) {
            for (j = 0u; j < n; ++j) {
                double w = 0.0;
                uint32_t k;
                switch (wsel % 8u) {
                case 0u: case 1u: case 2u:                     /* G G' + d I: positive definite */
                    for (k = 0u; k < n; ++k) {
                        w += G[i * n + k] * G[j * n + k];
                    }
                    w += (i == j) ? 0.01 + (double)(wsel % 16u) / 16.0 : 0.0;
                    /* Now and then not symmetric (a spline table's W': Gaussian elimination),
                     * the upper triangle moved: a P-matrix when the move is small. */
                    if (((wsel / 8u) % 2u == 1u) && (i < j)) {
                        w += 0.25 * G[j * n + i];
                    }
                    break;
                case 3u: w = (i == j) ? 0.1 + G[i * n + i] * G[i * n + i] : 0.0; break;
                case 4u: w = (i <= j) ? G[i * n + j] : G[j * n + i]; break;  /* indefinite */
                case 5u: w = (i == j) ? -1.0 - G[i] * G[i] : 0.0; break;  /* negative definite */
                case 6u: w = G[i] * G[j]; break;                 /* rank one (or zero) */
                default: w = fz_bits_f64(((uint64_t)fz_lcg(&seed) << 40) ^
                                         ((uint64_t)fz_lcg(&seed) << 16));
                         break;
                }
                g_bW[i * n + j] = w;
            }
        }
        if (((wsel & 0x30u) == 0x30u) && (n > 0u)) {            /* one special entry */
            g_bW[fz_lcg(&seed) % (n * n)] = fz_special_f64(&seed);
        }
    }
    /* Bounds: bands around 0 (some rows active at the optimum), equality rows, and, unless
     * the table is meant to be valid (rsel < 192), lo > hi, huge or non-finite bounds. */
    for (i = 0u; i < FZ_BAND_STORE; ++i) {
        const uint32_t kind = fz_lcg(&seed) % ((rsel < 192u) ? 6u : 9u);
        const double a = fz_lcg_f64(&seed, 3.0), b = fz_lcg_f64(&seed, 3.0);
        const double lo = (a < b) ? a : b, hi = (a < b) ? b : a;
        switch (kind) {
        case 0u: case 1u: case 2u: g_blo[i] = lo; g_bhi[i] = hi; break;
        case 3u: g_blo[i] = a; g_bhi[i] = a; break;           /* equality row */
        case 4u: g_blo[i] = -1e300; g_bhi[i] = hi; break;     /* one-sided in effect */
        case 5u: g_blo[i] = -fz_bits_f64(0x7FEFFFFFFFFFFFFFull);
                 g_bhi[i] = fz_bits_f64(0x7FEFFFFFFFFFFFFFull); break;
        case 6u: g_blo[i] = hi; g_bhi[i] = lo - 1e-3; break;  /* lo > hi */
        case 7u: g_blo[i] = fz_special_f64(&seed); g_bhi[i] = hi; break;
        default: g_blo[i] = lo; g_bhi[i] = fz_special_f64(&seed); break;
        }
    }
    /* stage_n_latch: q at stage 0 and 0 after, as the contract requires, unless npsel >= 224. */
    if (q <= STSP_BANDQP_MAX) {
        if (t->n_latch < q) {
            t->n_latch = (uint16_t)q;
        }
    }
    g_stage_n_latch[0] = (uint16_t)q;
    for (i = 1u; i < FZ_MAX_NS; ++i) {
        g_stage_n_latch[i] = 0u;
    }
    if (npsel >= 224u) {
        switch (npsel % 3u) {
        case 0u: g_stage_n_latch[0] = (uint16_t)(q + 1u); break;
        case 1u: g_stage_n_latch[0] = (uint16_t)((q > 0u) ? q - 1u : 0u); break;
        default:
            g_stage_n_latch[1u + npsel % (FZ_MAX_NS - 1u)] = (uint16_t)(1u + npsel % 4u);
            break;
        }
    }
    if (nullsel >= 240u) {
        switch (nullsel % 5u) {
        case 0u: g_band.Nt = NULL; break;
        case 1u: g_band.mt = NULL; break;
        case 2u: g_band.W = NULL; break;
        case 3u: g_band.lo = NULL; break;
        default: g_band.hi = NULL; break;
        }
    }
    t->band_qp = &g_band;
    return (crcsel >= 232u) ? 1u + crcsel % 2u : 0u;
}


#ifndef STSP_ARITH_FIXED_POINT
/* Spline gains (format 5): storage with room for every layout the input can declare (up to
 * FZ_SPL_SPANS spans per stage, every operand of every (stage, input) stored). */
#define FZ_SPL_SPANS 8u
#define FZ_SPL_NZ (FZ_MAX_NX + 1u + FZ_MAX_NL)
#define FZ_SPL_KNOTS (FZ_MAX_NS * (FZ_SPL_SPANS + 7u) + 8u)
#define FZ_SPL_ENTRIES (FZ_MAX_NS * FZ_MAX_NU * FZ_SPL_NZ + 8u)
#define FZ_SPL_COEF (FZ_MAX_NS * FZ_MAX_NU * FZ_SPL_NZ * (FZ_SPL_SPANS + 3u) + 16u)
#define FZ_SPL_KINDS 14u  /* corruptions of fz_build_spline */
static uint32_t g_knot_start[FZ_MAX_NS + 1u];
static float g_knot[FZ_SPL_KNOTS];
static uint16_t g_row_start[FZ_MAX_NS * FZ_MAX_NU + 1u];
static uint8_t g_col[FZ_SPL_ENTRIES];
static uint32_t g_coef_start[FZ_MAX_NS + 1u];
static float g_coef[FZ_SPL_COEF];
static stsp_spline_t g_spline;

/* Bits to binary32 and back, in every build (spline knots and coefficients are binary32). */
static float fz_spl_f32(uint32_t bits)
{
    float f;
    memcpy(&f, &bits, sizeof f);
    return f;
}

static float fz_spline_value(uint32_t *seed, uint32_t vsel)
{
    const uint32_t r = fz_lcg(seed);
    float f = ((float)(int32_t)(r % 4096u) - 2048.0f) / 512.0f;   /* +-4 */
    switch (vsel % 8u) {
    case 6u: f *= 1e35f; break;                  /* commands that overflow or saturate */
    case 7u: f *= ((r >> 12) % 4u == 0u) ? 1e-40f : 1.0f; break;  /* some subnormal */
    default: break;
    }
    return f;
}

/* A spline table's gains from the input. Valid unless the selector asks for one corruption, all applied
 * before the CRC (so that init's status is the one of that check): knots out of order or
 * equal, not integers, the stage's tick count T wrong at either end, row_start decreasing or
 * not from 0, a col beyond nx + 1 + n_latch, a NaN/Inf coefficient, coef_start inconsistent,
 * lengths (n_knots, n_entries, n_coef) lying, fewer than 8 knots or knot_start decreasing, a
 * NULL array, K/k0/L next to the spline, raw bits in an index array or the
 * knots, a stage of 2^24 ticks or more, a stage's coefficient count off by its entries. Stages
 * are long (up to 2^24 - 1 ticks: a spline table has no per-tick arrays) now and then.
 * Sets t->spline (K, k0, L NULL); returns 1 + the corruption, or 0. */
static uint32_t fz_build_spline(fuzz_in_t *in, stsp_table_t *t)
{
    const uint32_t lsel = fuzz_u8(in), csel = fuzz_u8(in), vsel = fuzz_u8(in);
    const uint32_t corrupt = (csel >= 160u) ? 1u + csel % FZ_SPL_KINDS : 0u;
    uint32_t seed = fuzz_u32(in);
    const uint32_t ns = t->n_stages, nu = t->nu, nz = (uint32_t)t->nx + 1u + t->n_latch;
    uint32_t s, i, nk = 0u, ne = 0u, nc = 0u;
    memset(g_knot_start, 0, sizeof g_knot_start);
    memset(g_knot, 0, sizeof g_knot);
    memset(g_row_start, 0, sizeof g_row_start);
    memset(g_col, 0, sizeof g_col);
    memset(g_coef_start, 0, sizeof g_coef_start);
    memset(g_coef, 0, sizeof g_coef);
    if ((lsel & 3u) == 3u) {                       /* long stages */
        uint32_t nt = 0u;
        for (s = 0u; s < FZ_MAX_NS; ++s) {
            nt += 1u + fz_lcg(&seed) % (((lsel & 4u) != 0u) ? 4096u : 16777215u);
            g_start[s + 1u] = nt;
        }
        t->n_ticks = g_start[t->n_stages];
    }
    if (corrupt == 1u + 13u) {                     /* a stage of 2^24 ticks or more */
        const uint32_t d = 16777216u + fz_lcg(&seed) % 3u - (g_start[1] - g_start[0]);
        for (s = 1u; s <= FZ_MAX_NS; ++s) {
            g_start[s] += d;
        }
        t->n_ticks = g_start[t->n_stages];
    }
    g_row_start[0] = 0u;
    for (s = 0u; s < ns; ++s) {
        const uint32_t T = g_start[s + 1u] - g_start[s];
        const uint32_t max_spans = (T < FZ_SPL_SPANS) ? T : FZ_SPL_SPANS;
        uint32_t spans = 1u + fz_lcg(&seed) % max_spans;
        uint32_t b[FZ_SPL_SPANS];
        uint32_t nb = 0u, k;
        /* spans - 1 distinct breakpoints in (0, T), sorted (duplicates dropped) */
        for (k = 0u; (k + 1u < spans) && (T > 1u); ++k) {
            const uint32_t v = 1u + fz_lcg(&seed) % (T - 1u);
            uint32_t j = nb;
            int dup = 0;
            for (j = 0u; j < nb; ++j) {
                dup = dup || (b[j] == v);
            }
            if (!dup) {
                for (j = nb; (j > 0u) && (b[j - 1u] > v); --j) {
                    b[j] = b[j - 1u];
                }
                b[j] = v;
                ++nb;
            }
        }
        spans = nb + 1u;
        g_knot_start[s] = nk;
        for (k = 0u; k < 4u; ++k) {
            g_knot[nk + k] = 0.0f;
            g_knot[nk + 4u + nb + k] = (float)T;
        }
        for (k = 0u; k < nb; ++k) {
            g_knot[nk + 4u + k] = (float)b[k];
        }
        nk += spans + 7u;
        g_coef_start[s] = nc;
        for (i = 0u; i < nu; ++i) {
            const uint32_t pick = fz_lcg(&seed);
            const uint32_t bits = fz_lcg(&seed);
            uint32_t c;
            for (c = 0u; c < nz; ++c) {
                const int stored = ((pick % 8u) == 0u) ? 0 : ((pick % 8u) == 1u) ? 1
                                   : (int)((bits >> c) & 1u);
                if (stored) {
                    uint32_t e;
                    g_col[ne] = (uint8_t)c;
                    for (e = 0u; e < spans + 3u; ++e) {
                        g_coef[nc++] = fz_spline_value(&seed, vsel);
                    }
                    ++ne;
                }
            }
            g_row_start[s * nu + i + 1u] = (uint16_t)ne;
        }
    }
    g_knot_start[ns] = nk;
    g_coef_start[ns] = nc;
    g_spline.n_knots = nk;
    g_spline.n_entries = ne;
    g_spline.n_coef = nc;
    g_spline.knot_start = g_knot_start;
    g_spline.knot = g_knot;
    g_spline.row_start = g_row_start;
    g_spline.col = g_col;
    g_spline.coef_start = g_coef_start;
    g_spline.coef = g_coef;
    g_spline.ops = &stsp_spline_ops;
    t->spline = &g_spline;
    t->K = NULL;
    t->k0 = NULL;
    t->L = NULL;
    {
        const uint32_t s0 = fz_lcg(&seed) % ns;                 /* the stage to corrupt */
        const uint32_t k0 = g_knot_start[s0], len = g_knot_start[s0 + 1u] - k0;
        const uint32_t r = fz_lcg(&seed);
        switch (corrupt) {
        case 1u + 0u:                                /* knots out of order, or equal */
            if (len > 8u) {
                const uint32_t j = k0 + 4u + r % (len - 8u);
                g_knot[j] = ((r >> 8) & 1u) ? g_knot[j - 1u] : g_knot[j - 1u] - 1.0f;
            } else {
                g_knot[k0 + 1u + r % 3u] = 1.0f;     /* a nonzero among the first four */
            }
            break;
        case 1u + 1u:                                /* not an integer */
            g_knot[k0 + 4u + ((len > 8u) ? r % (len - 8u) : 0u)] -= 0.5f;
            break;
        case 1u + 2u:                                /* T wrong at either end */
            if ((r & 1u) != 0u) {
                g_knot[k0 + len - 1u - (r >> 1) % 4u] += ((r & 2u) ? 1.0f : -1.0f);
            } else {
                g_knot[k0 + (r >> 1) % 4u] = (float)(g_start[s0 + 1u] - g_start[s0]);
            }
            break;
        case 1u + 3u: {                              /* row_start decreasing, or not from 0 */
            const uint32_t j = r % (ns * nu);
            g_row_start[j] = (uint16_t)(g_row_start[j + 1u] + 1u);
            break;
        }
        case 1u + 4u:                                /* a col out of range */
            if (ne > 0u) {
                g_col[r % ne] = (uint8_t)(nz + (r >> 8) % (256u - nz));
            } else {
                g_spline.n_entries = 1u;             /* and a lying length */
            }
            break;
        case 1u + 5u:                                /* a NaN/Inf coefficient */
            if (nc > 0u) {
                static const uint32_t bad[3] = {0x7FC00000u, 0x7F800000u, 0xFF800000u};
                g_coef[r % nc] = fz_spl_f32(bad[(r >> 8) % 3u]);
            }
            break;
        case 1u + 6u:                                /* coef_start inconsistent */
            g_coef_start[r % (ns + 1u)] += ((r >> 8) & 1u) ? 1u : (uint32_t)-1;
            break;
        case 1u + 7u: {                              /* a length lying (within the storage) */
            const uint32_t d = 1u + (r >> 2) % 8u;
            const int up = ((r >> 5) & 1u) != 0u;
            switch (r % 3u) {
            case 0u: g_spline.n_knots = up ? nk + d : ((nk > d) ? nk - d : 0u); break;
            case 1u: g_spline.n_entries = up ? ne + d : ((ne > d) ? ne - d : 0u); break;
            default: g_spline.n_coef = up ? nc + d : ((nc > d) ? nc - d : 0u); break;
            }
            break;
        }
        case 1u + 8u:                                /* fewer than 8 knots, or decreasing */
            if ((r & 1u) != 0u) {
                g_knot_start[s0 + 1u] = g_knot_start[s0] + (r >> 1) % 8u;
            } else {
                g_knot_start[r % (ns + 1u)] += ((r >> 8) & 1u) ? 1u : (uint32_t)-1;
            }
            break;
        case 1u + 9u:                                /* a NULL array */
            switch (r % 6u) {
            case 0u: g_spline.knot_start = NULL; break;
            case 1u: g_spline.knot = NULL; break;
            case 2u: g_spline.row_start = NULL; break;
            case 3u: g_spline.col = NULL; break;
            case 4u: g_spline.coef_start = NULL; break;
            default: g_spline.coef = NULL; break;
            }
            break;
        case 1u + 10u:                               /* per-tick gains next to the spline */
            switch (r % 3u) {
            case 0u: t->K = g_K; break;
            case 1u: t->k0 = g_k0; break;
            default: t->L = g_L; break;
            }
            break;
        case 1u + 11u:                               /* raw bits */
            switch (r % 4u) {
            case 0u: g_row_start[r % (ns * nu + 1u)] = (uint16_t)(r >> 8); break;
            case 1u: g_knot_start[r % (ns + 1u)] = fz_lcg(&seed) % (FZ_SPL_KNOTS + 1u); break;
            case 2u: g_coef_start[r % (ns + 1u)] = fz_lcg(&seed); break;
            default: g_knot[r % (nk + 1u)] = fz_spl_f32(fz_lcg(&seed) ^ (r << 20)); break;
            }
            break;
        case 1u + 12u:               /* the last stage's coefficients off by its entries */
            g_coef_start[ns] = nc + (g_row_start[ns * nu] - g_row_start[0]);
            g_spline.n_coef = g_coef_start[ns];
            if (g_spline.n_coef > FZ_SPL_COEF) {
                g_spline.n_coef = FZ_SPL_COEF;
            }
            break;
        default:                                     /* valid, or 2^24 ticks (above) */
            break;
        }
    }
    /* Declared lengths never beyond the storage (init's precondition). */
    if (g_spline.n_knots > FZ_SPL_KNOTS) {
        g_spline.n_knots = FZ_SPL_KNOTS;
    }
    if (g_spline.n_entries > FZ_SPL_ENTRIES) {
        g_spline.n_entries = FZ_SPL_ENTRIES;
    }
    if (g_spline.n_coef > FZ_SPL_COEF) {
        g_spline.n_coef = FZ_SPL_COEF;
    }
    return corrupt;
}

/* The spline arrays stsp_table_crc32() reads are there (its precondition). */
static int fz_spline_arrays_ok(void)
{
    return (g_spline.knot_start != NULL) && (g_spline.knot != NULL) &&
           (g_spline.row_start != NULL) && (g_spline.col != NULL) &&
           (g_spline.coef_start != NULL) && (g_spline.coef != NULL);
}

/* A bit of a knot or coefficient changed after the CRC. */
static void fz_spline_flip(fuzz_in_t *in)
{
    const uint32_t k = fuzz_u8(in), bit = fuzz_u8(in) % 32u;
    uint32_t bits;
    float *a = ((k & 1u) != 0u) ? &g_knot[(k >> 1) % FZ_SPL_KNOTS]
                                : &g_coef[(k >> 1) % FZ_SPL_COEF];
    memcpy(&bits, a, sizeof bits);
    bits ^= 1u << bit;
    memcpy(a, &bits, sizeof bits);
}
#else
/* Fixed-point spline gains (stsp_qspline_t): storage with room for every layout the input can
 * declare (spans of 1 tick: at most FZ_MAX_STAGE_TICKS + 3 coefficients per entry). */
#define FZ_SPL_NZ (FZ_MAX_NX + 1u + FZ_MAX_NL)
#define FZ_SPL_ENTRIES (FZ_MAX_NS * FZ_MAX_NU * FZ_SPL_NZ + 8u)
#define FZ_SPL_COEF (FZ_MAX_NS * FZ_MAX_NU * FZ_SPL_NZ * (FZ_MAX_STAGE_TICKS + 3u) + 16u)
#define FZ_SPL_KINDS 10u  /* corruptions of fz_build_spline */
static uint8_t g_log2[FZ_MAX_NS];
static uint16_t g_row_start[FZ_MAX_NS * FZ_MAX_NU + 1u];
static uint8_t g_col[FZ_SPL_ENTRIES];
static uint8_t g_shift[FZ_SPL_ENTRIES];
static uint32_t g_coef_start[FZ_MAX_NS + 1u];
static fz_val_t g_coef[FZ_SPL_COEF];
static stsp_qspline_t g_spline;

/* A coefficient: within +-2^F/64 (a gain is at most 3 of them: a row of 13 stays below
 * 2^F - 1), or, for vsel % 8 == 6, anywhere in the Q range (rows that break the bound). */
static fz_val_t fz_spline_value(uint32_t *seed, uint32_t vsel)
{
    const uint32_t r = fz_lcg(seed);
    if ((vsel % 8u) == 6u) {
        return (fz_val_t)((int64_t)(r % 65536u) * (FZ_Q_ONE / 32768) - FZ_Q_ONE);
    }
    return (fz_val_t)(((int64_t)(r % 4096u) - 2048) * FZ_Q_ONE / 131072);
}

/* A fixed-point spline table's gains from the input. Valid unless the selector asks for one
 * corruption, applied before the CRC: span_log2 beyond 9, a shift of 0 or beyond 30, row_start
 * decreasing or not from 0, a col beyond nx + 1 + n_latch, a col not increasing in its row,
 * coef_start inconsistent, a length (n_entries, n_coef) lying, a NULL array, K/k0/L next to
 * the spline, raw bits in an index array. Spans of 2^k ticks, k in 0..9 (mostly 0..3: several
 * spans per stage). Sets t->spline (K, k0, L NULL); returns 1 + the corruption, or 0. */
static uint32_t fz_build_spline(fuzz_in_t *in, stsp_table_t *t)
{
    const uint32_t lsel = fuzz_u8(in), csel = fuzz_u8(in), vsel = fuzz_u8(in);
    const uint32_t corrupt = (csel >= 160u) ? 1u + csel % FZ_SPL_KINDS : 0u;
    uint32_t seed = fuzz_u32(in);
    const uint32_t ns = t->n_stages, nu = t->nu, nz = (uint32_t)t->nx + 1u + t->n_latch;
    uint32_t s, i, ne = 0u, nc = 0u;
    memset(g_log2, 0, sizeof g_log2);
    memset(g_row_start, 0, sizeof g_row_start);
    memset(g_col, 0, sizeof g_col);
    memset(g_shift, 0, sizeof g_shift);
    memset(g_coef_start, 0, sizeof g_coef_start);
    memset(g_coef, 0, sizeof g_coef);
    for (s = 0u; s < ns; ++s) {
        const uint32_t T = g_start[s + 1u] - g_start[s];
        const uint32_t k = ((lsel & 1u) != 0u) ? fz_lcg(&seed) % 10u : fz_lcg(&seed) % 4u;
        const uint32_t spans = (T + (1u << k) - 1u) >> k;
        g_log2[s] = (uint8_t)k;
        g_coef_start[s] = nc;
        for (i = 0u; i < nu; ++i) {
            const uint32_t pick = fz_lcg(&seed);
            const uint32_t bits = fz_lcg(&seed);
            uint32_t c;
            for (c = 0u; c < nz; ++c) {
                const int stored = ((pick % 8u) == 0u) ? 0 : ((pick % 8u) == 1u) ? 1
                                   : (int)((bits >> c) & 1u);
                if (stored) {
                    uint32_t e;
                    g_col[ne] = (uint8_t)c;
                    g_shift[ne] = (uint8_t)(1u + fz_lcg(&seed) % 30u);
                    for (e = 0u; e < spans + 3u; ++e) {
                        g_coef[nc++] = fz_spline_value(&seed, vsel);
                    }
                    ++ne;
                }
            }
            g_row_start[s * nu + i + 1u] = (uint16_t)ne;
        }
    }
    g_coef_start[ns] = nc;
    g_spline.n_entries = ne;
    g_spline.n_coef = nc;
    g_spline.span_log2 = g_log2;
    g_spline.row_start = g_row_start;
    g_spline.col = g_col;
    g_spline.shift = g_shift;
    g_spline.coef_start = g_coef_start;
    g_spline.coef = g_coef;
    g_spline.ops = &stsp_spline_ops;
    t->spline = &g_spline;
    t->K = NULL;
    t->k0 = NULL;
    t->L = NULL;
    {
        const uint32_t s0 = fz_lcg(&seed) % ns;
        const uint32_t r = fz_lcg(&seed);
        switch (corrupt) {
        case 1u + 0u:                                /* spans beyond 2^9 ticks */
            g_log2[s0] = (uint8_t)(10u + r % 246u);
            break;
        case 1u + 1u:                                /* a shift of 0 or beyond 30 */
            if (ne > 0u) {
                g_shift[r % ne] = (uint8_t)(((r >> 8) & 1u) ? 0u : 31u + (r >> 9) % 225u);
            }
            break;
        case 1u + 2u: {                              /* row_start decreasing, or not from 0 */
            const uint32_t j = r % (ns * nu);
            g_row_start[j] = (uint16_t)(g_row_start[j + 1u] + 1u);
            break;
        }
        case 1u + 3u:                                /* a col out of range */
            if (ne > 0u) {
                g_col[r % ne] = (uint8_t)(nz + (r >> 8) % (256u - nz));
            } else {
                g_spline.n_entries = 1u;             /* and a lying length */
            }
            break;
        case 1u + 4u:                                /* a col not increasing in its row */
            for (i = 0u; i < ns * nu; ++i) {
                if (g_row_start[i + 1u] >= g_row_start[i] + 2u) {
                    const uint32_t e = g_row_start[i] + 1u + r % (g_row_start[i + 1u] - g_row_start[i] - 1u);
                    g_col[e] = ((r >> 8) & 1u) ? g_col[e - 1u] : (uint8_t)(g_col[e - 1u] / 2u);
                    break;
                }
            }
            break;
        case 1u + 5u:                                /* coef_start inconsistent */
            g_coef_start[r % (ns + 1u)] += ((r >> 8) & 1u) ? 1u : (uint32_t)-1;
            break;
        case 1u + 6u: {                              /* a length lying (within the storage) */
            const uint32_t d = 1u + (r >> 2) % 8u;
            const int up = ((r >> 5) & 1u) != 0u;
            if ((r & 1u) != 0u) {
                g_spline.n_entries = up ? ne + d : ((ne > d) ? ne - d : 0u);
            } else {
                g_spline.n_coef = up ? nc + d : ((nc > d) ? nc - d : 0u);
            }
            break;
        }
        case 1u + 7u:                                /* a NULL array */
            switch (r % 6u) {
            case 0u: g_spline.span_log2 = NULL; break;
            case 1u: g_spline.row_start = NULL; break;
            case 2u: g_spline.col = NULL; break;
            case 3u: g_spline.shift = NULL; break;
            case 4u: g_spline.coef_start = NULL; break;
            default: g_spline.coef = NULL; break;
            }
            break;
        case 1u + 8u:                                /* per-tick gains next to the spline */
            switch (r % 3u) {
            case 0u: t->K = g_K; break;
            case 1u: t->k0 = g_k0; break;
            default: t->L = g_L; break;
            }
            break;
        case 1u + 9u:                                /* raw bits */
            switch (r % 3u) {
            case 0u: g_row_start[r % (ns * nu + 1u)] = (uint16_t)(r >> 8); break;
            case 1u: g_coef_start[r % (ns + 1u)] = fz_lcg(&seed); break;
            default: g_log2[r % ns] = (uint8_t)(r >> 8); break;
            }
            break;
        default:                                     /* valid */
            break;
        }
    }
    /* Declared lengths never beyond the storage (init's precondition). */
    if (g_spline.n_entries > FZ_SPL_ENTRIES) {
        g_spline.n_entries = FZ_SPL_ENTRIES;
    }
    if (g_spline.n_coef > FZ_SPL_COEF) {
        g_spline.n_coef = FZ_SPL_COEF;
    }
    return corrupt;
}

/* The spline arrays stsp_table_crc32() reads are there (its precondition). */
static int fz_spline_arrays_ok(void)
{
    return (g_spline.span_log2 != NULL) && (g_spline.row_start != NULL) &&
           (g_spline.col != NULL) && (g_spline.shift != NULL) &&
           (g_spline.coef_start != NULL) && (g_spline.coef != NULL);
}

/* A bit of a coefficient or a shift changed after the CRC. */
static void fz_spline_flip(fuzz_in_t *in)
{
    const uint32_t k = fuzz_u8(in), bit = fuzz_u8(in);
    if ((k & 1u) != 0u) {
        g_shift[(k >> 1) % FZ_SPL_ENTRIES] ^= (uint8_t)(1u << (bit % 8u));
    } else {
        fz_val_t *a = &g_coef[(k >> 1) % FZ_SPL_COEF];
        *a = (fz_val_t)(*a ^ (fz_val_t)(1u << (bit % (8u * sizeof *a - 1u))));
    }
}
#endif

#ifndef STSP_ARITH_FIXED_POINT
/* Whether a binary32 value is an integer (from its bits: no conversion). */
static int fz_f32_is_integer(float f)
{
    const uint32_t b = fz_f32_bits(f);
    const int32_t e = (int32_t)((b >> 23) & 0xFFu) - 127;
    if (e < 0) {
        return (b & 0x7FFFFFFFu) == 0u;
    }
    if (e >= 23) {
        return 1;
    }
    return (b & ((1u << (23 - e)) - 1u)) == 0u;
}

/* Whether the knots k[0..len) are a clamped knot vector for T ticks (the spec, written out
 * again here): four 0, strictly increasing integers in (0, T), four T. */
static int fz_knots_valid(const float *k, uint32_t len, uint32_t T)
{
    uint32_t i;
    if ((len < 8u) || (T >= 16777216u)) {
        return 0;
    }
    for (i = 0u; i < 4u; ++i) {
        if (!(k[i] == 0.0f) || !(k[len - 1u - i] == (float)T)) {
            return 0;
        }
    }
    for (i = 4u; i + 4u < len; ++i) {
        if (!(k[i] > k[i - 1u]) || !(k[i] < (float)T) || !fz_f32_is_integer(k[i])) {
            return 0;
        }
    }
    return 1;
}

/* init's verdict on a spline table's own arrays (the header's dimensions and stage layout
 * already valid): STSP_ERR_NULL, STSP_ERR_BAD_DIMS or STSP_OK (stsp_controller.h, stsp_spline_t). */
static stsp_status_t fz_spline_check(const stsp_table_t *t)
{
    const stsp_spline_t *p = t->spline;
    const uint32_t ns = t->n_stages, rows = ns * t->nu;
    const uint32_t nz = (uint32_t)t->nx + 1u + t->n_latch;
    uint32_t s, i;
    if ((p->knot_start == NULL) || (p->knot == NULL) || (p->row_start == NULL) ||
        (p->col == NULL) || (p->coef_start == NULL) || (p->coef == NULL)) {
        return STSP_ERR_NULL;
    }
    if ((p->knot_start[0] != 0u) || (p->knot_start[ns] != p->n_knots) ||
        (p->row_start[0] != 0u) || (p->row_start[rows] != p->n_entries) ||
        (p->coef_start[0] != 0u) || (p->coef_start[ns] != p->n_coef)) {
        return STSP_ERR_BAD_DIMS;
    }
    for (s = 0u; s < ns; ++s) {
        if ((p->knot_start[s + 1u] < p->knot_start[s]) ||
            (p->coef_start[s + 1u] < p->coef_start[s])) {
            return STSP_ERR_BAD_DIMS;
        }
    }
    for (i = 0u; i < rows; ++i) {
        if (p->row_start[i + 1u] < p->row_start[i]) {
            return STSP_ERR_BAD_DIMS;
        }
    }
    for (i = 0u; i < p->n_entries; ++i) {
        if (p->col[i] >= nz) {
            return STSP_ERR_BAD_DIMS;
        }
    }
    for (i = 0u; i < rows; ++i) {   /* operands increasing within a row */
        uint32_t e;
        for (e = (uint32_t)p->row_start[i] + 1u; e < p->row_start[i + 1u]; ++e) {
            if (p->col[e] <= p->col[e - 1u]) {
                return STSP_ERR_BAD_DIMS;
            }
        }
    }
    for (s = 0u; s < ns; ++s) {
        const uint32_t len = p->knot_start[s + 1u] - p->knot_start[s];
        const uint64_t entries = (uint64_t)p->row_start[(s + 1u) * t->nu] - p->row_start[s * t->nu];
        const uint64_t coefs = (uint64_t)p->coef_start[s + 1u] - p->coef_start[s];
        if ((len < 8u) || (coefs != entries * (len - 4u)) ||
            !fz_knots_valid(&p->knot[p->knot_start[s]], len,
                            t->stage_start[s + 1u] - t->stage_start[s])) {
            return STSP_ERR_BAD_DIMS;
        }
    }
    return STSP_OK;
}

static int fz_spline_coef_finite(const stsp_spline_t *p)
{
    uint32_t i;
    for (i = 0u; i < p->n_coef; ++i) {
        if (!fz_finite(p->coef[i])) {
            return 0;
        }
    }
    return 1;
}

/* What a step of a valid spline table at a tick that passes the range and order checks, with
 * a finite state, must do (from the contract, independently of the firmware's code): the
 * stage (searched from the last one), whether it latches (the first step, or a new stage with
 * stage_n_latch > 0) and the v it then uses (Lambda x + lambda0 in that order, zero beyond
 * stage_n_latch), and the command of the spline law at that tick, by The NURBS Book A2.2
 * literally (every operation its own statement: no contraction), the feed-forward folded into
 * one spline per input first (stsp_spline.c). */
typedef struct {
    uint32_t stage;
    int relatch;
    int v_finite;
    int y_finite;
    float v[FZ_MAX_NL];
    float y[FZ_MAX_NU];
} fz_spline_model_t;

static void fz_spline_model(const stsp_table_t *t, const stsp_ctrl_t *before, uint32_t tick,
                            const float *x, const float *band_v, fz_spline_model_t *m)
{
    const stsp_spline_t *sp = t->spline;
    const uint32_t nx = t->nx, nu = t->nu, n_latch = t->n_latch;
    uint32_t s = before->stage, i, j, r;
    const float *U;
    uint32_t n_spans, sigma = 0u, e0;
    float tau, N[4], left[4], right[4];
    while ((s + 1u < t->n_stages) && (t->stage_start[s + 1u] <= tick)) {
        ++s;
    }
    m->stage = s;
    m->relatch = (before->latched == 0u) || ((s != before->stage) && (t->stage_n_latch[s] > 0u));
    m->v_finite = 1;
    for (i = 0u; i < n_latch; ++i) {
        float v = before->v[i];
        if (m->relatch && (band_v != NULL)) {
            v = band_v[i];                 /* a spline band table's stage-0 latch */
        } else if (m->relatch) {
            v = 0.0f;
            if (i < t->stage_n_latch[s]) {
                const uint32_t row = s * n_latch + i;
                v = t->lambda0[row];
                for (j = 0u; j < nx; ++j) {
                    const float p = t->Lambda[row * nx + j] * x[j];
                    v = v + p;
                }
            }
        }
        m->v[i] = v;
        m->v_finite = m->v_finite && fz_finite(v);
    }
    U = &sp->knot[sp->knot_start[s]];
    n_spans = sp->knot_start[s + 1u] - sp->knot_start[s] - 7u;
    tau = (float)(tick - t->stage_start[s]);
    while ((sigma + 1u < n_spans) && !(tau < U[sigma + 4u])) {
        ++sigma;
    }
    N[0] = 1.0f;
    for (j = 1u; j <= 3u; ++j) {
        float saved = 0.0f;
        left[j] = tau - U[sigma + 3u + 1u - j];
        right[j] = U[sigma + 3u + j] - tau;
        for (r = 0u; r < j; ++r) {
            const float den = right[r + 1u] + left[j - r];
            const float temp = N[r] / den;
            const float p = right[r + 1u] * temp;
            N[r] = saved + p;
            saved = left[j - r] * temp;
        }
        N[j] = saved;
    }
    e0 = sp->row_start[s * nu];
    m->y_finite = 1;
    for (i = 0u; i < nu; ++i) {
        /* k0[i] + L[i] v folded into one spline (per coefficient +0 - c z over the entries
         * beyond x, in stored order); its value starts the command, then the gains of x. */
        float fold[4] = {0.0f, 0.0f, 0.0f, 0.0f}, acc, p;
        uint32_t e;
        for (e = sp->row_start[s * nu + i]; e < sp->row_start[s * nu + i + 1u]; ++e) {
            const float *c = &sp->coef[sp->coef_start[s] + (e - e0) * (n_spans + 3u) + sigma];
            const uint32_t col = sp->col[e];
            if (col >= nx) {
                const float z = (col == nx) ? 1.0f : m->v[col - nx - 1u];
                for (r = 0u; r < 4u; ++r) {
                    p = c[r] * z;
                    fold[r] = fold[r] - p;
                }
            }
        }
        acc = N[0] * fold[0];
        for (r = 1u; r < 4u; ++r) {
            p = N[r] * fold[r];
            acc = acc + p;
        }
        for (e = sp->row_start[s * nu + i]; e < sp->row_start[s * nu + i + 1u]; ++e) {
            const float *c = &sp->coef[sp->coef_start[s] + (e - e0) * (n_spans + 3u) + sigma];
            const uint32_t col = sp->col[e];
            if (col < nx) {
                float g = N[0] * c[0];
                p = N[1] * c[1];
                g = g + p;
                p = N[2] * c[2];
                g = g + p;
                p = N[3] * c[3];
                g = g + p;
                p = g * x[col];
                acc = acc - p;
            }
        }
        m->y[i] = acc;
        m->y_finite = m->y_finite && fz_finite(acc);
    }
}

/* A step of a spline table that the model covers: status, command (clamped, bit for bit),
 * stage, latch and saturation mask as the model says. */
static void fz_check_spline_step(const stsp_table_t *t, const stsp_ctrl_t *c, stsp_status_t st,
                                 stsp_status_t tick_st, const float *u,
                                 const fz_spline_model_t *m)
{
    uint32_t i, sat = 0u;
    if ((m->relatch && !m->v_finite) || !m->y_finite) {
        fuzz_check(st == STSP_ERR_NONFINITE_OUTPUT);
        return;
    }
    for (i = 0u; i < t->nu; ++i) {
        float want = m->y[i];
        if (want > t->u_max[i]) {
            want = t->u_max[i];
            sat |= 1u << i;
        } else if (want < t->u_min[i]) {
            want = t->u_min[i];
            sat |= 1u << i;
        } else {
            /* within the limits */
        }
        fuzz_check(fz_f32_bits(u[i]) == fz_f32_bits(want));
    }
    fuzz_check(st == ((sat != 0u) ? STSP_WARN_SATURATED : tick_st));
    if (sat != 0u) {
        fuzz_check(c->sat_mask == sat);
    }
    fuzz_check((c->latched != 0u) && (c->stage == m->stage));
    for (i = 0u; i < t->n_latch; ++i) {
        fuzz_check(fz_f32_bits(c->v[i]) == fz_f32_bits(m->v[i]));
    }
}
#endif

/* A table from the input: valid most of the time (so that the calls reach the law), with at
 * most one corruption chosen by a selector byte. */
static void fz_build_table(fuzz_in_t *in, stsp_table_t *t, fz_table_info_t *info)
{
    const uint32_t shape = fuzz_u8(in), lim = fuzz_u8(in), sel = fuzz_u8(in), bsel = fuzz_u8(in);
    const uint32_t ssel = fuzz_u8(in);
    /* Spline gains (one table in three; now and then with a band dual, a spline band table)
     * or a band dual (one in three). */
    const int spline = FZ_SPLINE_PICK(ssel);
    const int band = FZ_BAND_PICK(bsel) && (!spline || (ssel >= 240u));
    uint32_t band_corrupt = 0u;
    const uint32_t corrupt = (sel >= 160u) ? (sel % 10u) : 10u;  /* 10: none */
    uint32_t s, nt = 0u, i;
    memset(t, 0, sizeof *t);
    t->magic = STSP_TABLE_MAGIC;
    t->format_version = STSP_FORMAT_VERSION;
    t->scalar_kind = STSP_SCALAR_KIND;
    t->nx = (uint16_t)(1u + shape % FZ_MAX_NX);
    t->nu = (uint16_t)(1u + (shape / 8u) % FZ_MAX_NU);
    t->n_latch = (uint16_t)(fuzz_u8(in) % (FZ_GEN_NL + 1u));
    t->n_stages = (uint16_t)(1u + fuzz_u8(in) % FZ_MAX_NS);
    t->tick_hz = 1u + fuzz_u8(in);
    g_start[0] = 0u;
    for (s = 0u; s < FZ_MAX_NS; ++s) {
        nt += 1u + fuzz_u8(in) % FZ_MAX_STAGE_TICKS;
        g_start[s + 1u] = nt;
        g_stage_n_latch[s] = (uint16_t)(fuzz_u8(in) % (t->n_latch + 1u));
    }
    t->n_ticks = g_start[t->n_stages];
    t->stage_start = g_start;
    t->stage_n_latch = g_stage_n_latch;
    {
        uint32_t seed = fuzz_u32(in);
        const uint32_t special = (corrupt == 5u) ? 1u + fuzz_u8(in) : 0u;
        fz_fill(&seed, g_K, sizeof g_K / sizeof g_K[0], special);
        fz_fill(&seed, g_k0, sizeof g_k0 / sizeof g_k0[0], special);
        fz_fill(&seed, g_L, sizeof g_L / sizeof g_L[0], special);
        fz_fill(&seed, g_Lambda, sizeof g_Lambda / sizeof g_Lambda[0], special);
        fz_fill(&seed, g_lambda0, sizeof g_lambda0 / sizeof g_lambda0[0], special);
    }
    t->K = g_K;
    t->k0 = g_k0;
    t->L = g_L;
    t->Lambda = g_Lambda;
    t->lambda0 = g_lambda0;
#ifdef STSP_ARITH_FIXED_POINT
    for (i = 0u; i < FZ_MAX_NX; ++i) {
        g_xe[i] = (int8_t)((int32_t)(fuzz_u8(in) % 21u) - 10);
    }
    for (i = 0u; i < FZ_MAX_NU; ++i) {
        g_ue[i] = (int8_t)((int32_t)(fuzz_u8(in) % 21u) - 10);
    }
    for (i = 0u; i < FZ_MAX_NL; ++i) {
        g_ve[i] = (int8_t)((int32_t)(fuzz_u8(in) % 21u) - 10);
    }
    if (corrupt == 5u) {
        g_ue[fuzz_u8(in) % FZ_MAX_NU] = (int8_t)(int32_t)fuzz_u8(in); /* maybe beyond +-60 */
    }
    t->x_exp = g_xe;
    t->u_exp = g_ue;
    t->v_exp = g_ve;
    for (i = 0u; i < FZ_MAX_NU; ++i) {
        switch (lim % 4u) {
        case 0u: g_lo[i] = (fz_val_t)(-FZ_Q_ONE); g_hi[i] = (fz_val_t)(FZ_Q_ONE - 1); break;
        case 1u: g_lo[i] = (fz_val_t)(-(int64_t)(1u + fuzz_u8(in)) * (FZ_Q_ONE / 4096));
                 g_hi[i] = (fz_val_t)((int64_t)(1u + fuzz_u8(in)) * (FZ_Q_ONE / 4096)); break;
        case 2u: g_lo[i] = (fz_val_t)(-(int32_t)(fuzz_u8(in) % 3u)); g_hi[i] = (fz_val_t)(FZ_Q_ONE - 1);
                 break;
        default: g_lo[i] = fz_value(in); g_hi[i] = fz_value(in); break; /* maybe invalid */
        }
    }
#else
    for (i = 0u; i < FZ_MAX_NU; ++i) {
        switch (lim % 4u) {
        case 0u: g_lo[i] = -FLT_MAX; g_hi[i] = FLT_MAX; break;
        case 1u: g_lo[i] = -(float)(1u + fuzz_u8(in)) / 64.0f;
                 g_hi[i] = (float)(1u + fuzz_u8(in)) / 64.0f; break;
        case 2u: g_lo[i] = -(float)(fuzz_u8(in) % 3u); g_hi[i] = FLT_MAX; break;
        default: g_lo[i] = -fz_value(in); g_hi[i] = fz_value(in); break; /* maybe invalid */
        }
    }
#endif
    for (i = 0u; i < FZ_MAX_NU; ++i) {       /* the safe command: 0, a limit, or anything */
        switch (fuzz_u8(in) % 4u) {
        case 0u: g_hold[i] = (fz_val_t)0; break;
        case 1u: g_hold[i] = g_lo[i]; break;
        case 2u: g_hold[i] = g_hi[i]; break;
        default: g_hold[i] = fz_value(in); break;                 /* maybe invalid */
        }
    }
    t->u_min = g_lo;
    t->u_max = g_hi;
    t->u_hold = g_hold;
    memset(info, 0, sizeof *info);
    if (band) {
        band_corrupt = fz_build_band(in, t);
        info->band = 1u;
    }
    if (spline) {
        info->spline_corrupt = fz_build_spline(in, t);
        info->spline = 1u;
    }
    info->main_corrupt = (corrupt != 10u) ? 1u + corrupt : 0u; /* which one, for the Q model */
    switch (corrupt) {
    case 0u: t->magic = fuzz_u32(in); break;
    case 1u: t->format_version = (uint16_t)fuzz_u8(in); break;
    case 2u: t->nx = (uint16_t)(fuzz_u8(in) % (FZ_MAX_NX + 1u)); break;   /* maybe 0 */
    case 3u: t->nu = (uint16_t)(fuzz_u8(in) % (FZ_MAX_NU + 1u)); break;
    case 4u: /* break the layout, within the storage: n_ticks never exceeds FZ_MAX_NT */
        g_start[fuzz_u8(in) % (FZ_MAX_NS + 1u)] = fuzz_u8(in) % (FZ_MAX_NT + 1u);
        t->n_ticks = (fuzz_u8(in) & 1u) ? g_start[t->n_stages] : fuzz_u8(in) % (FZ_MAX_NT + 1u);
        break;
    case 5u: break;                                              /* special gains, above */
    case 6u: g_stage_n_latch[fuzz_u8(in) % FZ_MAX_NS] = (uint16_t)fuzz_u8(in); break;
    case 7u: t->n_stages = (uint16_t)(fuzz_u8(in) % (FZ_MAX_NS + 1u)); break;
    case 8u:
        switch (fuzz_u8(in) % 5u) {
        case 0u: t->K = NULL; break;
        case 1u: t->u_max = NULL; break;
        case 2u: t->L = NULL; break;
        case 4u: t->u_hold = NULL; break;
#ifdef STSP_ARITH_FIXED_POINT
        case 3u: t->v_exp = NULL; break;
#endif
        default: t->stage_n_latch = NULL; break;
        }
        break;
    default: break;
    }
    /* The CRC needs valid pointers and dimensions inside the storage; compute it when it can
     * be computed, then perhaps corrupt it. */
    if ((t->u_max != NULL) && (t->u_hold != NULL) && (t->stage_n_latch != NULL) &&
#ifdef STSP_ARITH_FIXED_POINT
        (t->v_exp != NULL) &&
#endif
        ((t->spline == NULL)
         ? ((t->K != NULL) && (t->L != NULL) && (t->n_ticks <= FZ_MAX_NT))
         : fz_spline_arrays_ok()) &&
        ((t->band_qp == NULL) ||
         ((g_band.Nt != NULL) && (g_band.mt != NULL) && (g_band.W != NULL) &&
          (g_band.lo != NULL) && (g_band.hi != NULL) && (g_band.q <= FZ_BAND_STORE) &&
          (g_band.nx <= FZ_BAND_STORE)))) {
        t->crc32 = stsp_table_crc32(t);
        info->band_crc_ok = 1u;
    }
    if (corrupt == 9u) {
        t->crc32 ^= 1u << (fuzz_u8(in) % 32u);
    }
    if (band_corrupt == 1u) {
        t->crc32 ^= 1u << (fuzz_u8(in) % 32u);
        info->band_crc_ok = 0u;
    } else if (band_corrupt == 2u) {
        const uint32_t k = fuzz_u8(in) % FZ_BAND_STORE;
        double *arr[5] = {g_bNt, g_bmt, g_bW, g_blo, g_bhi};
        double *a = arr[fuzz_u8(in) % 5u];
        uint64_t bits;
        memcpy(&bits, &a[k], sizeof bits);
        bits ^= 1ull << (fuzz_u8(in) % 64u);
        memcpy(&a[k], &bits, sizeof bits);
        /* Covered by the CRC only if k is within the declared sizes. */
        info->band_crc_ok = 0u;
    } else {
        /* CRC as computed */
    }
    if ((t->spline != NULL) && (fuzz_u8(in) >= 240u)) {
        /* A bit of the spline data changed after the CRC (covered by it when within the
         * declared lengths). */
        fz_spline_flip(in);
        info->band_crc_ok = 0u;
    }
}

#ifndef STSP_ARITH_FIXED_POINT
/* The status stsp_init() must return for a table without a main-table corruption, from the
 * documented order of its checks: dimensions and layout (a spline table without per-tick
 * gains and band dual; stage_n_latch within n_latch), the spline's arrays (NULL, layout,
 * knots), band arrays NULL, band dimensions and stage_n_latch, CRC, values (limits, spline
 * coefficients, band data). Returns 1 and the status in *st when the table is modelled. */
static int fz_expected_init(const stsp_table_t *t, const fz_table_info_t *info,
                            stsp_status_t *st)
{
    const stsp_bandqp_t *b = t->band_qp;
    uint32_t s, i;
    if (info->main_corrupt != 0u) {
        return 0;
    }
    if ((t->spline != NULL) && ((t->K != NULL) || (t->k0 != NULL) || (t->L != NULL))) {
        *st = STSP_ERR_BAD_DIMS;
        return 1;
    }
    for (s = 0u; s < t->n_stages; ++s) {
        if (t->stage_n_latch[s] > t->n_latch) {
            *st = STSP_ERR_BAD_DIMS;
            return 1;
        }
    }
    if (t->spline != NULL) {
        const stsp_status_t sp_st = fz_spline_check(t);
        if (sp_st != STSP_OK) {
            *st = sp_st;
            return 1;
        }
    }
    if (b != NULL) {
        if ((b->Nt == NULL) || (b->mt == NULL) || (b->W == NULL) || (b->lo == NULL) ||
            (b->hi == NULL)) {
            *st = STSP_ERR_NULL;
            return 1;
        }
        if ((b->q == 0u) || (b->q > STSP_BANDQP_MAX) || (b->nx != t->nx) ||
            (b->q != t->stage_n_latch[0])) {
            *st = STSP_ERR_BAD_DIMS;
            return 1;
        }
        for (s = 1u; s < t->n_stages; ++s) {
            if (t->stage_n_latch[s] != 0u) {
                *st = STSP_ERR_BAD_DIMS;
                return 1;
            }
        }
    }
    if (info->band_crc_ok == 0u) {
        /* A flipped CRC bit is a mismatch; a changed band value outside the declared sizes
         * is not covered: only "not OK unless the CRC still matches" can be said. */
        if (stsp_table_crc32(t) != t->crc32) {
            *st = STSP_ERR_BAD_CRC;
            return 1;
        }
    }
    *st = STSP_OK;
    for (i = 0u; i < t->nu; ++i) {
        if (!fz_finite(t->u_min[i]) || !fz_finite(t->u_max[i]) || !fz_finite(t->u_hold[i]) ||
            !(t->u_min[i] <= t->u_hold[i]) || !(t->u_max[i] >= t->u_hold[i])) {
            *st = STSP_ERR_BAD_VALUES;
        }
    }
    if ((t->spline != NULL) && !fz_spline_coef_finite(t->spline)) {
        *st = STSP_ERR_BAD_VALUES;
    }
    if (b != NULL) {
        const uint32_t q = b->q, nx = b->nx;
        for (i = 0u; i < q * nx; ++i) {
            if (!fz_finite_f64(b->Nt[i])) {
                *st = STSP_ERR_BAD_VALUES;
            }
        }
        for (i = 0u; i < q * q; ++i) {
            if (!fz_finite_f64(b->W[i])) {
                *st = STSP_ERR_BAD_VALUES;
            }
        }
        for (i = 0u; i < q; ++i) {
            if (!fz_finite_f64(b->mt[i]) || !fz_finite_f64(b->lo[i]) ||
                !fz_finite_f64(b->hi[i]) || !(b->lo[i] <= b->hi[i])) {
                *st = STSP_ERR_BAD_VALUES;
            }
        }
    }
    return 1;
}

/* 1 if the band dual is invalid by the contract (any of init's band checks fails). */
static int fz_band_invalid(const stsp_table_t *t)
{
    const stsp_bandqp_t *b = t->band_qp;
    uint32_t s, i;
    if (b == NULL) {
        return 0;
    }
    if ((b->Nt == NULL) || (b->mt == NULL) || (b->W == NULL) || (b->lo == NULL) ||
        (b->hi == NULL) || (b->q == 0u) || (b->q > STSP_BANDQP_MAX) || (b->nx != t->nx) ||
        (t->stage_n_latch == NULL) || (t->n_stages == 0u) || (t->n_stages > FZ_MAX_NS) ||
        (b->q != t->stage_n_latch[0])) {
        return 1;
    }
    for (s = 1u; s < t->n_stages; ++s) {
        if (t->stage_n_latch[s] != 0u) {
            return 1;
        }
    }
    for (i = 0u; i < (uint32_t)b->q * b->nx; ++i) {
        if (!fz_finite_f64(b->Nt[i])) {
            return 1;
        }
    }
    for (i = 0u; i < (uint32_t)b->q * b->q; ++i) {
        if (!fz_finite_f64(b->W[i])) {
            return 1;
        }
    }
    for (i = 0u; i < b->q; ++i) {
        if (!fz_finite_f64(b->mt[i]) || !fz_finite_f64(b->lo[i]) || !fz_finite_f64(b->hi[i]) ||
            !(b->lo[i] <= b->hi[i])) {
            return 1;
        }
    }
    return 0;
}

/* 1 if the spline gains are invalid by the contract (any of init's spline checks fails, with
 * the dimensions the header declares): init must then never return STSP_OK. */
static int fz_spline_invalid(const stsp_table_t *t)
{
    if (t->spline == NULL) {
        return 0;
    }
    return (t->K != NULL) || (t->k0 != NULL) || (t->L != NULL) ||
           (fz_spline_check(t) != STSP_OK) || !fz_spline_coef_finite(t->spline);
}
#else
__extension__ typedef __int128 fz_i128; /* clang: the spline model's exact arithmetic */

/* floor(a / 2^sh + 1/2), exact. */
static int64_t fz_round_shift(fz_i128 a, uint32_t sh)
{
    const fz_i128 one = (fz_i128)1 << sh;
    const fz_i128 n = a + (one >> 1);
    fz_i128 q = n / one;
    if ((n % one) < 0) {
        --q;
    }
    return (int64_t)q;
}

/* A gain of a fixed-point spline (stsp_qspline_t, written from the contract and the uniform
 * cubic B-spline's pieces in the power form, not the firmware's): at d of D = 2^k,
 * 6 D^3 N = ((D - d)^3, 3 d^3 - 6 d^2 D + 4 D^3, -3 d^3 + 3 d^2 D + 3 d D^2 + D^3, d^3). */
static int64_t fz_qgain(const fz_val_t *c, uint32_t k, uint32_t tau, uint32_t sh)
{
    const int64_t D = (int64_t)1 << k, d = (int64_t)(tau & ((1u << k) - 1u));
    const int64_t P[4] = {(D - d) * (D - d) * (D - d), 3 * d * d * d - 6 * d * d * D + 4 * D * D * D,
                          -3 * d * d * d + 3 * d * d * D + 3 * d * D * D + D * D * D, d * d * d};
    fz_i128 acc = 0;
    uint32_t r;
    for (r = 0u; r < 4u; ++r) {
        acc += (fz_i128)c[r] * P[r];
    }
    return fz_round_shift(acc, 3u * k + sh);
}

/* init's verdict on a fixed-point spline table's own arrays (the header's dimensions and
 * stage layout already valid), from stsp_controller.h (stsp_qspline_t): STSP_ERR_NULL,
 * STSP_ERR_BAD_DIMS or STSP_OK. */
static stsp_status_t fz_spline_check(const stsp_table_t *t)
{
    const stsp_qspline_t *p = t->spline;
    const uint32_t ns = t->n_stages, nu = t->nu, rows = ns * nu;
    const uint32_t nz = (uint32_t)t->nx + 1u + t->n_latch;
    uint32_t s, i;
    if ((p->span_log2 == NULL) || (p->row_start == NULL) || (p->col == NULL) ||
        (p->shift == NULL) || (p->coef_start == NULL) || (p->coef == NULL)) {
        return STSP_ERR_NULL;
    }
    if ((p->row_start[0] != 0u) || (p->row_start[rows] != p->n_entries) ||
        (p->coef_start[0] != 0u) || (p->coef_start[ns] != p->n_coef)) {
        return STSP_ERR_BAD_DIMS;
    }
    for (i = 0u; i < rows; ++i) {
        if (p->row_start[i + 1u] < p->row_start[i]) {
            return STSP_ERR_BAD_DIMS;
        }
    }
    for (s = 0u; s < ns; ++s) {
        if (p->coef_start[s + 1u] < p->coef_start[s]) {
            return STSP_ERR_BAD_DIMS;
        }
    }
    for (s = 0u; s < ns; ++s) {
        const uint32_t T = t->stage_start[s + 1u] - t->stage_start[s];
        const uint32_t k = p->span_log2[s];
        uint64_t spans, entries, coefs;
        if (k > 9u) {
            return STSP_ERR_BAD_DIMS;
        }
        spans = ((uint64_t)T + (1u << k) - 1u) >> k;
        entries = (uint64_t)p->row_start[(s + 1u) * nu] - p->row_start[s * nu];
        coefs = (uint64_t)p->coef_start[s + 1u] - p->coef_start[s];
        if (coefs != entries * (spans + 3u)) {
            return STSP_ERR_BAD_DIMS;
        }
    }
    for (i = 0u; i < rows; ++i) {
        uint32_t e;
        for (e = p->row_start[i]; e < p->row_start[i + 1u]; ++e) {
            if ((p->col[e] >= nz) || ((e > p->row_start[i]) && (p->col[e] <= p->col[e - 1u])) ||
                (p->shift[e] < 1u) || (p->shift[e] > 30u)) {
                return STSP_ERR_BAD_DIMS;
            }
        }
    }
    return STSP_OK;
}

/* Every row of gains, at every tick of a table whose layout passed fz_spline_check, within
 * |k0| + sum|K| + sum|L| <= 2^F - 1. */
static int fz_spline_rows_ok(const stsp_table_t *t)
{
    const stsp_qspline_t *p = t->spline;
    const uint32_t nu = t->nu;
    uint32_t s, tau, i, e;
    for (s = 0u; s < t->n_stages; ++s) {
        const uint32_t k = p->span_log2[s];
        const uint32_t T = t->stage_start[s + 1u] - t->stage_start[s];
        const uint32_t stride = ((T + (1u << k) - 1u) >> k) + 3u;
        for (tau = 0u; tau < T; ++tau) {
            for (i = 0u; i < nu; ++i) {
                int64_t sum = 0;
                for (e = p->row_start[s * nu + i]; e < p->row_start[s * nu + i + 1u]; ++e) {
                    const uint32_t at = p->coef_start[s] + (e - p->row_start[s * nu]) * stride +
                                        (tau >> k);
                    const int64_t g = fz_qgain(&p->coef[at], k, tau, p->shift[e]);
                    sum += (g < 0) ? -g : g;
                }
                if (sum > FZ_Q_ONE - 1) {
                    return 0;
                }
            }
        }
    }
    return 1;
}

/* The table's stage layout is the contract's (so the spline checks can be modelled). */
static int fz_stages_ok(const stsp_table_t *t)
{
    uint32_t s;
    if ((t->n_stages == 0u) || (t->n_stages > FZ_MAX_NS) || (t->stage_start == NULL) ||
        (t->stage_n_latch == NULL) || (t->nu == 0u) || (t->nu > FZ_MAX_NU) ||
        (t->stage_start[0] != 0u) || (t->stage_start[t->n_stages] != t->n_ticks)) {
        return 0;
    }
    for (s = 0u; s < t->n_stages; ++s) {
        if (t->stage_start[s + 1u] <= t->stage_start[s]) {
            return 0;
        }
    }
    return 1;
}

/* Fixed point: the layout check refuses any band_qp with STSP_ERR_BAD_DIMS, after magic,
 * version, dimensions, NULL main arrays and the stage layout, and before the CRC and the
 * values. So a band table gets exactly that status when its main part is valid, and also
 * with a broken dimension or layout (BAD_DIMS either way), special gains or exponents, or a
 * flipped CRC bit: every main corruption but magic (0), version (1) and NULL arrays (8),
 * which may come first. A spline table (stsp_qspline_t) without a main corruption: per-tick
 * gains next to it, stage_n_latch beyond n_latch (BAD_DIMS), its layout (fz_spline_check), the
 * CRC, then the values: exponents within +-60, every spline row at every tick, every latch
 * row within 2^F - 1, u_min <= u_hold <= u_max (BAD_VALUES). Other tables are not
 * modelled. */
static int fz_expected_init(const stsp_table_t *t, const fz_table_info_t *info,
                            stsp_status_t *st)
{
    uint32_t s, i, j;
    if ((t->band_qp != NULL) || (t->spline == NULL)) {
        if ((t->band_qp == NULL) || (info->main_corrupt == 1u + 0u) ||
            (info->main_corrupt == 1u + 1u) || (info->main_corrupt == 1u + 8u)) {
            return 0;
        }
        *st = STSP_ERR_BAD_DIMS;
        return 1;
    }
    if (info->main_corrupt != 0u) {
        return 0;
    }
    if ((t->K != NULL) || (t->k0 != NULL) || (t->L != NULL)) {
        *st = STSP_ERR_BAD_DIMS;
        return 1;
    }
    for (s = 0u; s < t->n_stages; ++s) {
        if (t->stage_n_latch[s] > t->n_latch) {
            *st = STSP_ERR_BAD_DIMS;
            return 1;
        }
    }
    *st = fz_spline_check(t);
    if (*st != STSP_OK) {
        return 1;
    }
    if ((info->band_crc_ok == 0u) && (stsp_table_crc32(t) != t->crc32)) {
        *st = STSP_ERR_BAD_CRC;
        return 1;
    }
    if (!fz_spline_rows_ok(t)) {
        *st = STSP_ERR_BAD_VALUES;
    }
    for (i = 0u; i < t->nx; ++i) {
        if ((t->x_exp[i] > 60) || (t->x_exp[i] < -60)) {
            *st = STSP_ERR_BAD_VALUES;
        }
    }
    for (i = 0u; i < t->nu; ++i) {
        if ((t->u_exp[i] > 60) || (t->u_exp[i] < -60) || (t->u_min[i] > t->u_hold[i]) ||
            (t->u_max[i] < t->u_hold[i])) {
            *st = STSP_ERR_BAD_VALUES;
        }
    }
    for (i = 0u; i < t->n_latch; ++i) {
        if ((t->v_exp[i] > 60) || (t->v_exp[i] < -60)) {
            *st = STSP_ERR_BAD_VALUES;
        }
    }
    for (i = 0u; i < (uint32_t)t->n_stages * t->n_latch; ++i) {
        int64_t sum = (t->lambda0[i] < 0) ? -(int64_t)t->lambda0[i] : t->lambda0[i];
        for (j = 0u; j < t->nx; ++j) {
            const int64_t a = t->Lambda[i * t->nx + j];
            sum += (a < 0) ? -a : a;
        }
        if (sum > FZ_Q_ONE - 1) {
            *st = STSP_ERR_BAD_VALUES;
        }
    }
    return 1;
}

/* Every band dual is invalid in a fixed-point build. */
static int fz_band_invalid(const stsp_table_t *t)
{
    return t->band_qp != NULL;
}

/* 1 if the spline gains are invalid by the contract (with the dimensions the header
 * declares): init must then never return STSP_OK. */
static int fz_spline_invalid(const stsp_table_t *t)
{
    if (t->spline == NULL) {
        return 0;
    }
    if ((t->band_qp != NULL) || (t->K != NULL) || (t->k0 != NULL) || (t->L != NULL)) {
        return 1;
    }
    if (!fz_stages_ok(t) || (t->nx == 0u) || (t->nx > FZ_MAX_NX) ||
        (t->n_latch > FZ_MAX_NL)) {
        return 0; /* init refuses the main table: not a spline question */
    }
    return (fz_spline_check(t) != STSP_OK) || !fz_spline_rows_ok(t);
}

/* What a step of a valid fixed-point spline table at a tick in range and order must do
 * (from the contract): the stage (searched from the last one), the latch (the first step, or
 * a new stage with stage_n_latch > 0: v = round(lambda0 2^F + Lambda x) / 2^F, zero beyond
 * stage_n_latch), and each input's command round((g_k0 2^F + sum g x + sum g v) / 2^F) with
 * the gains of fz_qgain, before the clamp. */
typedef struct {
    uint32_t stage;
    int relatch;
    fz_val_t v[FZ_MAX_NL];
    int64_t y[FZ_MAX_NU];
} fz_spline_model_t;

static void fz_spline_model(const stsp_table_t *t, const stsp_ctrl_t *before, uint32_t tick,
                            const fz_val_t *x, fz_spline_model_t *m)
{
    const stsp_qspline_t *p = t->spline;
    const uint32_t nx = t->nx, nu = t->nu, n_latch = t->n_latch;
    uint32_t s = before->stage, i, j, e;
    uint32_t k, T, stride, tau;
    while ((s + 1u < t->n_stages) && (t->stage_start[s + 1u] <= tick)) {
        ++s;
    }
    m->stage = s;
    m->relatch = (before->latched == 0u) || ((s != before->stage) && (t->stage_n_latch[s] > 0u));
    for (i = 0u; i < n_latch; ++i) {
        fz_val_t v = before->v[i];
        if (m->relatch) {
            v = 0;
            if (i < t->stage_n_latch[s]) {
                const uint32_t row = s * n_latch + i;
                fz_i128 acc = (fz_i128)t->lambda0[row] * FZ_Q_ONE;
                for (j = 0u; j < nx; ++j) {
                    acc += (fz_i128)t->Lambda[row * nx + j] * x[j];
                }
                v = (fz_val_t)fz_round_shift(acc, STSP_Q_FRAC_BITS);
            }
        }
        m->v[i] = v;
    }
    k = p->span_log2[s];
    T = t->stage_start[s + 1u] - t->stage_start[s];
    stride = ((T + (1u << k) - 1u) >> k) + 3u;
    tau = tick - t->stage_start[s];
    for (i = 0u; i < nu; ++i) {
        fz_i128 acc = 0;
        for (e = p->row_start[s * nu + i]; e < p->row_start[s * nu + i + 1u]; ++e) {
            const uint32_t at = p->coef_start[s] + (e - p->row_start[s * nu]) * stride + (tau >> k);
            const int64_t g = fz_qgain(&p->coef[at], k, tau, p->shift[e]);
            const uint32_t col = p->col[e];
            const int64_t z = (col < nx) ? (int64_t)x[col]
                              : (col == nx) ? FZ_Q_ONE : (int64_t)m->v[col - nx - 1u];
            acc += (fz_i128)g * z;
        }
        m->y[i] = fz_round_shift(acc, STSP_Q_FRAC_BITS);
    }
}

/* A step of a fixed-point spline table that the model covers: status, command (clamped, bit
 * for bit), stage, latch and saturation mask as the model says. */
static void fz_check_spline_step(const stsp_table_t *t, const stsp_ctrl_t *c, stsp_status_t st,
                                 stsp_status_t tick_st, const fz_val_t *u,
                                 const fz_spline_model_t *m)
{
    uint32_t i, sat = 0u;
    for (i = 0u; i < t->nu; ++i) {
        int64_t want = m->y[i];
        fuzz_check((want >= -(FZ_Q_ONE - 1)) && (want <= FZ_Q_ONE - 1));
        if (want > t->u_max[i]) {
            want = t->u_max[i];
            sat |= 1u << i;
        } else if (want < t->u_min[i]) {
            want = t->u_min[i];
            sat |= 1u << i;
        } else {
            /* within the limits */
        }
        fuzz_check((int64_t)u[i] == want);
    }
    fuzz_check(st == ((sat != 0u) ? STSP_WARN_SATURATED : tick_st));
    if (sat != 0u) {
        fuzz_check(c->sat_mask == sat);
    }
    fuzz_check((c->latched != 0u) && (c->stage == m->stage));
    for (i = 0u; i < t->n_latch; ++i) {
        fuzz_check(c->v[i] == m->v[i]);
    }
}
#endif



int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

#ifndef STSP_ARITH_FIXED_POINT
/* What the stage-0 latch of a band table must do for the finite state x at `tick`: the
 * solver's result (checked against its own contract), whether the controller falls back, the
 * latch v and the law's unclamped commands y. v and y are computed as the firmware computes
 * them on the host (no VFP: products rounded, then subtracted, in its order; the fuzzer runs
 * on x86-64, where clang has no fused multiply-add to contract into), so they are exact. */
typedef struct {
    stsp_bandqp_status_t solve_st;
    int fallback;
    int y_finite;
    double lam[STSP_BANDQP_MAX];
    float v[FZ_MAX_NL];
    float y[FZ_MAX_NU];
} fz_latch_t;

static void fz_band_latch_model(const stsp_table_t *t, uint32_t tick, const float *x,
                                fz_latch_t *m)
{
    const stsp_bandqp_t *b = t->band_qp;
    const uint32_t nx = t->nx, nu = t->nu, n_latch = t->n_latch;
    stsp_bandqp_work_t work;
    uint32_t cand = 0u, nband = 1u, i, j;
    int overflow = 0;
    /* e = Nt x + mt in the solver's order: finite data and state can still overflow. */
    for (i = 0u; i < b->q; ++i) {
        double acc = b->mt[i];
        for (j = 0u; j < b->nx; ++j) {
            acc += b->Nt[(i * b->nx) + j] * (double)x[j];
        }
        overflow = overflow || !fz_finite_f64(acc);
        if (!(b->lo[i] == b->hi[i])) {
            nband *= 3u;
        }
    }
    m->solve_st = stsp_bandqp_solve(b, x, m->lam, &work, &cand);
    if (overflow) {
        fuzz_check(m->solve_st == STSP_BANDQP_ERR_NONFINITE);
        fuzz_check(cand == 0u);
    } else {
        fuzz_check((m->solve_st == STSP_BANDQP_OK) || (m->solve_st == STSP_BANDQP_ERR_INFEASIBLE));
        fuzz_check((cand >= 1u) && (cand <= nband));
        if (m->solve_st != STSP_BANDQP_OK) {
            fuzz_check(cand == nband);
        }
    }
    m->fallback = (m->solve_st != STSP_BANDQP_OK);
    for (i = 0u; i < b->q; ++i) {
        if (m->solve_st != STSP_BANDQP_OK) {
            fuzz_check(fz_f64_is_pos_zero(m->lam[i]));
        } else if (!((m->lam[i] <= (double)FLT_MAX) && (m->lam[i] >= -(double)FLT_MAX))) {
            m->fallback = 1;                              /* no binary32 value */
        } else {
            /* within range */
        }
    }
    /* The latch: (float)lam, or on a fallback the design's affine map Lambda x + lambda0 of
     * stage 0; zero beyond q (= stage_n_latch[0]). */
    for (i = 0u; i < n_latch; ++i) {
        float v = 0.0f;
        if (i < b->q) {
            if (!m->fallback) {
                v = (float)m->lam[i];
            } else {
                v = t->lambda0[i];
                for (j = 0u; j < nx; ++j) {
                    v += t->Lambda[(i * nx) + j] * x[j];
                }
            }
        }
        m->v[i] = v;
    }
    /* The law with that v (the table stores -K, -k0, -L); a spline table's is its own model's
     * (fz_spline_model, with this v). */
    m->y_finite = 1;
    for (i = 0u; (i < nu) && (t->spline == NULL); ++i) {
        const float *K = &t->K[(tick * nu + i) * nx];
        float acc = (-(K[0] * x[0])) - t->k0[(tick * nu) + i];
        for (j = 1u; j < nx; ++j) {
            acc = acc - (K[j] * x[j]);
        }
        for (j = 0u; j < n_latch; ++j) {
            acc = acc - (t->L[((tick * nu + i) * n_latch) + j] * m->v[j]);
        }
        m->y[i] = acc;
        m->y_finite = m->y_finite && fz_finite(acc);
    }
}

/* A band table's stage-0 latch step: the status, the commands (the law clamped to the
 * limits, bit for bit) and the latch, all as the model says. */
static void fz_check_band_step(const stsp_table_t *t, const stsp_ctrl_t *c, stsp_status_t st,
                               stsp_status_t tick_st, const float *u, const fz_latch_t *m)
{
    uint32_t i, sat = 0u;
    if (!m->y_finite) {
        fuzz_check(st == STSP_ERR_NONFINITE_OUTPUT);
        return;
    }
    for (i = 0u; i < t->nu; ++i) {
        float want = m->y[i];
        if (want > t->u_max[i]) {
            want = t->u_max[i];
            sat |= 1u << i;
        } else if (want < t->u_min[i]) {
            want = t->u_min[i];
            sat |= 1u << i;
        } else {
            /* within the limits */
        }
        fuzz_check(fz_f32_bits(u[i]) == fz_f32_bits(want));
    }
    fuzz_check(st == ((sat != 0u) ? STSP_WARN_SATURATED
                    : m->fallback ? STSP_WARN_BAND_FALLBACK : tick_st));
    fuzz_check(c->sat_mask == sat);
    fuzz_check((c->latched != 0u) && (c->stage == 0u));
    for (i = 0u; i < t->n_latch; ++i) {
        fuzz_check(fz_f32_bits(c->v[i]) == fz_f32_bits(m->v[i]));
    }
}
#endif

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    fuzz_in_t in = {data, size};
    stsp_table_t t;
    stsp_ctrl_t c, before;
    fz_table_info_t info;
    stsp_status_t init_expected = STSP_OK;
    uint32_t call, model_next = 0u;
    int ready, modelled, band_invalid;
    fz_build_table(&in, &t, &info);
    modelled = fz_expected_init(&t, &info, &init_expected);
    band_invalid = fz_band_invalid(&t) || fz_spline_invalid(&t);
#ifdef FZ_STATS
    {
        static int registered = 0;
        if (!registered) {
            registered = 1;
            (void)atexit(fzs_print);
        }
        FZS(FZS_TABLES);
        if (info.band) {
            FZS(FZS_BAND_TABLES);
        }
        if (info.spline) {
            FZS(FZS_SPL_TABLES);
            if (info.spline_corrupt != 0u) {
                FZS(FZS_SPL_CORRUPT);
            }
            if (modelled) {
                switch (init_expected) {
                case STSP_OK: FZS(FZS_SPL_INIT_OK); break;
                case STSP_ERR_NULL: FZS(FZS_SPL_NULL); break;
                case STSP_ERR_BAD_DIMS: FZS(FZS_SPL_DIMS); break;
                case STSP_ERR_BAD_CRC: FZS(FZS_SPL_CRC); break;
                default: FZS(FZS_SPL_VALUES); break;
                }
            }
        }
        if (modelled) {
            FZS(FZS_INIT_MODELLED);
            if (init_expected == STSP_OK) {
                FZS(FZS_INIT_OK);
            }
            if (info.band) {
                switch (init_expected) {
                case STSP_OK: FZS(FZS_BAND_INIT_OK); break;
                case STSP_ERR_NULL: FZS(FZS_BAND_NULL); break;
                case STSP_ERR_BAD_DIMS: FZS(FZS_BAND_DIMS); break;
                case STSP_ERR_BAD_CRC: FZS(FZS_BAND_CRC); break;
                default: FZS(FZS_BAND_VALUES); break;
                }
            }
        }
    }
#endif
    memset(&c, 0xA5, sizeof c);                                   /* garbage before init */
    ready = 0;
    for (call = 0u; (call < FZ_MAX_CALLS) && (in.n > 0u); ++call) {
        const uint32_t op = fuzz_u8(&in);
        if (op < 12u) {                                           /* (re)init */
            const uint32_t want_nx = fuzz_u8(&in) % 8u, want_nu = fuzz_u8(&in) % 5u;
            const stsp_status_t st = ((op & 1u) != 0u)
                ? stsp_init_expect(&c, &t, want_nx, want_nu)
                : stsp_init(&c, &t);
            fuzz_check(fz_known_status(st) && (st <= STSP_OK));
            if (modelled) {
                stsp_status_t want = init_expected;
                if (((op & 1u) != 0u) && (want == STSP_OK) &&
                    ((t.nx != want_nx) || (t.nu != want_nu))) {
                    want = STSP_ERR_BAD_DIMS;
                }
                fuzz_check(st == want);
            }
            if (band_invalid) {
                fuzz_check(st != STSP_OK);
            }
            ready = (st == STSP_OK);
            model_next = 0u;
            if (ready && (t.spline != NULL)) {
                FZS(FZS_SPL_READY);
            }
            if (ready) {
                fuzz_check(c.next_tick == 0u);
            }
        } else if (op < 18u) {
            const stsp_status_t st = stsp_reset(&c);
            fuzz_check(st == (ready ? STSP_OK : STSP_ERR_NOT_INITIALIZED));
            model_next = 0u;
        } else if (op < 20u) {
            const stsp_status_t st = stsp_verify(&c);
            fuzz_check(st == (ready ? STSP_OK : STSP_ERR_NOT_INITIALIZED));
        } else {                                                  /* step */
            const uint32_t how = fuzz_u8(&in) % 8u;
            fz_val_t x[FZ_MAX_NX + 1u], u[STSP_MAX_NU + 1u];
            const uint32_t nx = ready ? t.nx : FZ_MAX_NX, nu = ready ? t.nu : FZ_MAX_NU;
            uint32_t tick, i;
            int finite = 1;
            stsp_status_t st, tick_st;
            int spline_step = 0;
            fz_spline_model_t sm;
#ifndef STSP_ARITH_FIXED_POINT
            int band_latch = 0;
            fz_latch_t latch;
#endif
            switch (how) {
            case 0u: case 1u: case 2u: tick = model_next; break;
            case 3u: tick = model_next - 1u; break;               /* repeat (or wrap) */
            case 4u: tick = model_next + 1u + fuzz_u8(&in) % 4u; break;
            case 5u: tick = ready ? fuzz_u32(&in) % (t.n_ticks + 2u) : fuzz_u8(&in); break;
            case 6u: tick = ready ? t.n_ticks + fuzz_u8(&in) % 2u : 0u; break;
            default: tick = fuzz_u32(&in); break;
            }
            for (i = 0u; i < nx; ++i) {
                x[i] = fz_value(&in);
                finite = finite && fz_finite(x[i]);
            }
            for (i = 0u; i <= STSP_MAX_NU; ++i) {
                u[i] = FZ_SENTINEL;
            }
            memcpy(&before, &c, sizeof c);
            if (((op & 0xF0u) == 0xF0u) && ((op & 7u) != 7u)) {     /* NULL arguments */
                st = stsp_step((op & 1u) ? &c : NULL, tick, (op & 2u) ? x : NULL,
                               (op & 4u) ? u : NULL);
                fuzz_check(fz_known_status(st) && (st < STSP_OK));
                fuzz_check(memcmp(&c, &before, sizeof c) == 0);
                continue;
            }
#ifndef STSP_ARITH_FIXED_POINT
            /* A stage-0 latch of a band table (tick in range and order, x finite): what the
             * solver says for this x decides between its multipliers and the fallback. */
            if (ready && (t.band_qp != NULL) && finite && (tick < t.stage_start[1]) &&
                !((model_next > 0u) && (tick + 1u < model_next)) &&
                ((before.latched == 0u) || (before.stage != 0u))) {
                band_latch = 1;
                fz_band_latch_model(&t, tick, x, &latch);
            }
#endif
            /* A spline table's step at a tick in range and order with a finite state: the
             * model says what it must do. */
            if (ready && (t.spline != NULL) && finite && (tick < t.n_ticks) &&
                !((model_next > 0u) && (tick + 1u < model_next))) {
                spline_step = 1;
#ifndef STSP_ARITH_FIXED_POINT
                fz_spline_model(&t, &before, tick, x, band_latch ? latch.v : NULL, &sm);
#else
                fz_spline_model(&t, &before, tick, x, &sm);
#endif
            }
            st = stsp_step(&c, tick, x, u);
            fuzz_check(fz_known_status(st));
#ifndef STSP_ARITH_FIXED_POINT
            if (band_latch) {
                FZS(FZS_LATCH);
                FZS((latch.solve_st == STSP_BANDQP_OK) ? FZS_LATCH_OK
                    : (latch.solve_st == STSP_BANDQP_ERR_NONFINITE) ? FZS_LATCH_OVERFLOW
                    : FZS_LATCH_INFEASIBLE);
                if ((latch.solve_st == STSP_BANDQP_OK) && latch.fallback) {
                    FZS(FZS_LATCH_BEYOND_FLT);
                }
                if (st == STSP_WARN_BAND_FALLBACK) {
                    FZS(FZS_FALLBACK);
                }
                if (st < STSP_OK) {
                    FZS(FZS_LATCH_ERR);
                }
                if (t.band_qp->q == 8u) {
                    FZS(FZS_LATCH_Q8);
                }
            }
#endif
            fuzz_check(u[STSP_MAX_NU] == FZ_SENTINEL); /* nothing past the buffer */
            if (!ready) {
                fuzz_check(st == STSP_ERR_NOT_INITIALIZED);
                fuzz_check(u[0] == FZ_SENTINEL);                        /* u not written */
                continue;
            }
            fuzz_check(nu <= STSP_MAX_NU);
            for (i = nu; i < STSP_MAX_NU; ++i) {
                fuzz_check(u[i] == FZ_SENTINEL);
            }
            if (st < STSP_OK) {
                for (i = 0u; i < nu; ++i) {                /* the safe command, bit for bit */
                    fuzz_check(memcmp(&u[i], &t.u_hold[i], sizeof u[i]) == 0);
                }
                fuzz_check(memcmp(&c, &before, sizeof c) == 0);
            } else {
                for (i = 0u; i < nu; ++i) {
                    fuzz_check(fz_finite(u[i]));
                    fuzz_check((u[i] >= t.u_min[i]) && (u[i] <= t.u_max[i]));
                    if ((st == STSP_WARN_SATURATED) && ((c.sat_mask >> i) & 1u)) {
                        fuzz_check((u[i] == t.u_min[i]) || (u[i] == t.u_max[i]));
                    }
                }
                if (st == STSP_WARN_SATURATED) {
                    fuzz_check(c.sat_mask != 0u);
                }
            }
            /* The tick bookkeeping, in the documented order of checks. */
            tick_st = ((model_next > 0u) && (tick + 1u == model_next)) ? STSP_WARN_TICK_REPEATED
                      : (tick > model_next) ? STSP_WARN_TICK_SKIPPED : STSP_OK;
#ifndef STSP_ARITH_FIXED_POINT
            if (band_latch && !spline_step) {
                fz_check_band_step(&t, &c, st, tick_st, u, &latch);
            }
#endif
            if (spline_step) {
                FZS(FZS_SPL_STEPS);
                if (sm.relatch) {
                    FZS(FZS_SPL_LATCH);
                }
                if (st == STSP_WARN_SATURATED) {
                    FZS(FZS_SPL_SAT);
                }
                if (st == STSP_ERR_NONFINITE_OUTPUT) {
                    FZS(FZS_SPL_OVERFLOW);
                }
                if (t.stage_start[sm.stage + 1u] - t.stage_start[sm.stage] > 4096u) {
                    FZS(FZS_SPL_LONG);
                }
#ifndef STSP_ARITH_FIXED_POINT
                fz_check_spline_step(&t, &c, st,
                                     (band_latch && latch.fallback) ? STSP_WARN_BAND_FALLBACK
                                                                    : tick_st,
                                     u, &sm);
#else
                fz_check_spline_step(&t, &c, st, tick_st, u, &sm);
#endif
            }
            if (tick >= t.n_ticks) {
                fuzz_check(st == STSP_ERR_TICK_RANGE);
            } else if ((model_next > 0u) && (tick + 1u < model_next)) {
                fuzz_check(st == STSP_ERR_TICK_ORDER);
            } else if (!finite) {
                fuzz_check(st == STSP_ERR_NONFINITE_STATE);
            } else if (st >= STSP_OK) {
                if (st != STSP_WARN_SATURATED) {
#ifndef STSP_ARITH_FIXED_POINT
                    fuzz_check(st == ((band_latch && latch.fallback) ? STSP_WARN_BAND_FALLBACK
                                                                   : tick_st));
#else
                    fuzz_check(st == tick_st);
#endif
                }
                if (tick + 1u > model_next) {
                    model_next = tick + 1u;
                }
            } else {
                fuzz_check(st == STSP_ERR_NONFINITE_OUTPUT);
            }
            fuzz_check(c.next_tick == model_next);
        }
    }
    return 0;
}
