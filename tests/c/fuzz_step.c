/* libFuzzer target on the init/step API (built by CMakeLists.txt with clang,
 * -fsanitize=fuzzer,address,undefined; the test fuzz_step runs it for a bounded time).
 *
 * Each input describes a table and a sequence of calls. The table: dimensions (some invalid),
 * stage layout, gains (small values or raw bit patterns, so NaN/Inf/subnormal appear), limits
 * (none, finite, or invalid), the CRC (correct, or flipped), and NULL pointers now and then.
 * Its arrays always have room for the dimensions it declares: that is the documented
 * precondition of stsp_init() (the generated tables satisfy it by construction). The calls:
 * init, init_expect, reset, verify and step, with ticks in order, repeated, skipped, backwards
 * or past the end, states with NaN/Inf/huge/subnormal entries, and NULL arguments.
 *
 * Any sanitizer report, crash, or broken invariant (abort) is a finding. The invariants are
 * the contract of stsp_controller.h: a known status; before init u untouched; on an error u
 * all +0.0 and the instance byte-for-byte unchanged; otherwise u finite, within
 * [u_min, u_max], and saturated inputs exactly at a limit; nothing written past u[nu]; the
 * tick bookkeeping as documented (range, order, non-finite state detected first).
 *
 * Built once per arithmetic variant (fuzz_step, fuzz_step_q15, fuzz_step_q31): in the Q15/Q31
 * builds the tables, states and commands are integers (gains small enough for valid row sums,
 * or full-range ones that break the row bound), the scale exponents are fuzzed as well, and
 * there is no non-finite value. */
#include <float.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "stospline/stsp_controller.h"

#define FZ_MAX_NX 7u
#define FZ_MAX_NU 4u
#define FZ_MAX_NL 5u
#define FZ_MAX_NS 5u
#define FZ_MAX_STAGE_TICKS 8u
#define FZ_MAX_NT (FZ_MAX_NS * FZ_MAX_STAGE_TICKS)
#define FZ_MAX_CALLS 64u

#ifdef STSP_ARITH_FIXED
typedef stsp_scalar_t fz_val_t;
#define FZ_Q_ONE ((int64_t)1 << STSP_Q_FRAC_BITS)
#define FZ_SENTINEL ((stsp_scalar_t)12345)
#else
typedef float fz_val_t;
#define FZ_SENTINEL 1234.5f
#endif

typedef struct {
    const uint8_t *p;
    size_t n;
} fz_in_t;

static uint32_t fz_u8(fz_in_t *in)
{
    uint32_t v = 0u;
    if (in->n > 0u) {
        v = in->p[0];
        ++in->p;
        --in->n;
    }
    return v;
}

static uint32_t fz_u32(fz_in_t *in)
{
    uint32_t v = fz_u8(in);
    v |= fz_u8(in) << 8;
    v |= fz_u8(in) << 16;
    v |= fz_u8(in) << 24;
    return v;
}

#ifdef STSP_ARITH_FIXED
static int fz_finite(fz_val_t v)
{
    (void)v;
    return 1;
}

static int fz_is_zero(fz_val_t v)
{
    return v == 0;
}

/* Mostly modest values; a selector byte picks the range ends, 0 or a raw bit pattern. */
static fz_val_t fz_value(fz_in_t *in)
{
    const uint32_t sel = fz_u8(in);
    if (sel < 200u) {
        return (fz_val_t)(((int64_t)fz_u8(in) - 128) * (FZ_Q_ONE / 256));
    }
    switch (sel % 4u) {
    case 0u: return (fz_val_t)(-FZ_Q_ONE);
    case 1u: return (fz_val_t)(FZ_Q_ONE - 1);
    case 2u: return 0;
    default: return (fz_val_t)(int64_t)(((int64_t)fz_u32(in) % (2 * FZ_Q_ONE)) - FZ_Q_ONE);
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

static int fz_is_zero(float f)
{
    return fz_f32_bits(f) == 0u;
}

/* Mostly modest values; a selector byte picks specials or a raw bit pattern. */
static float fz_value(fz_in_t *in)
{
    const uint32_t sel = fz_u8(in);
    if (sel < 200u) {
        return ((float)(int32_t)fz_u8(in) - 128.0f) / 16.0f;
    }
    switch (sel % 8u) {
    case 0u: return fz_bits_f32(0x7FC00000u);          /* NaN */
    case 1u: return fz_bits_f32(0x7F800000u);          /* +Inf */
    case 2u: return fz_bits_f32(0xFF800000u);          /* -Inf */
    case 3u: return fz_bits_f32(0x7F7FFFFFu);          /* FLT_MAX */
    case 4u: return fz_bits_f32(0xFF7FFFFFu);          /* -FLT_MAX */
    case 5u: return fz_bits_f32(0x00000001u);          /* smallest subnormal */
    case 6u: return fz_bits_f32(0x80000000u);          /* -0 */
    default: return fz_bits_f32(fz_u32(in));           /* anything */
    }
}
#endif

static void fz_check_at(int ok, int line)
{
    if (!ok) {
        (void)fprintf(stderr, "fuzz_step: invariant broken at tests/c/fuzz_step.c:%d\n", line);
        abort();
    }
}
#define fz_check(ok) fz_check_at((ok), __LINE__)

static int fz_known_status(stsp_status_t st)
{
    return (st >= STSP_ERR_BAD_VALUES) && (st <= STSP_WARN_SATURATED);
}

/* Storage with room for every dimension the input can declare. */
static uint32_t g_start[FZ_MAX_NS + 1u];
static uint16_t g_np[FZ_MAX_NS];
static fz_val_t g_K[FZ_MAX_NT * FZ_MAX_NU * FZ_MAX_NX];
static fz_val_t g_k0[FZ_MAX_NT * FZ_MAX_NU];
static fz_val_t g_L[FZ_MAX_NT * FZ_MAX_NU * FZ_MAX_NL];
static fz_val_t g_Lambda[FZ_MAX_NS * FZ_MAX_NL * FZ_MAX_NX];
static fz_val_t g_lambda0[FZ_MAX_NS * FZ_MAX_NL];
static fz_val_t g_lo[FZ_MAX_NU], g_hi[FZ_MAX_NU];
#ifdef STSP_ARITH_FIXED
static int8_t g_xe[FZ_MAX_NX], g_ue[FZ_MAX_NU], g_ve[FZ_MAX_NL];
#endif

/* Gains from a generator seeded by the input (so that a short input describes a whole table
 * and most bytes drive calls); `special` in 1..255 makes about one value in `special` a
 * special one (NaN, Inf, FLT_MAX, subnormal, -0), 0 none. */
#ifdef STSP_ARITH_FIXED
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

/* A table from the input: valid most of the time (so that the calls reach the law), with at
 * most one corruption chosen by a selector byte. */
static void fz_build_table(fz_in_t *in, stsp_table_t *t)
{
    const uint32_t shape = fz_u8(in), lim = fz_u8(in), sel = fz_u8(in);
    const uint32_t corrupt = (sel >= 160u) ? (sel % 10u) : 10u;  /* 10: none */
    uint32_t s, nt = 0u, i;
    memset(t, 0, sizeof *t);
    t->magic = STSP_TABLE_MAGIC;
    t->format_version = STSP_FORMAT_VERSION;
    t->scalar_kind = STSP_SCALAR_KIND;
    t->nx = (uint16_t)(1u + shape % FZ_MAX_NX);
    t->nu = (uint16_t)(1u + (shape / 8u) % FZ_MAX_NU);
    t->n_latch = (uint16_t)(fz_u8(in) % (FZ_MAX_NL + 1u));
    t->n_stages = (uint16_t)(1u + fz_u8(in) % FZ_MAX_NS);
    t->tick_hz = 1u + fz_u8(in);
    g_start[0] = 0u;
    for (s = 0u; s < FZ_MAX_NS; ++s) {
        nt += 1u + fz_u8(in) % FZ_MAX_STAGE_TICKS;
        g_start[s + 1u] = nt;
        g_np[s] = (uint16_t)(fz_u8(in) % (t->n_latch + 1u));
    }
    t->n_ticks = g_start[t->n_stages];
    t->stage_start = g_start;
    t->stage_np = g_np;
    {
        uint32_t seed = fz_u32(in);
        const uint32_t special = (corrupt == 5u) ? 1u + fz_u8(in) : 0u;
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
#ifdef STSP_ARITH_FIXED
    for (i = 0u; i < FZ_MAX_NX; ++i) {
        g_xe[i] = (int8_t)((int32_t)(fz_u8(in) % 21u) - 10);
    }
    for (i = 0u; i < FZ_MAX_NU; ++i) {
        g_ue[i] = (int8_t)((int32_t)(fz_u8(in) % 21u) - 10);
    }
    for (i = 0u; i < FZ_MAX_NL; ++i) {
        g_ve[i] = (int8_t)((int32_t)(fz_u8(in) % 21u) - 10);
    }
    if (corrupt == 5u) {
        g_ue[fz_u8(in) % FZ_MAX_NU] = (int8_t)(int32_t)fz_u8(in); /* maybe beyond +-60 */
    }
    t->x_exp = g_xe;
    t->u_exp = g_ue;
    t->v_exp = g_ve;
    for (i = 0u; i < FZ_MAX_NU; ++i) {
        switch (lim % 4u) {
        case 0u: g_lo[i] = (fz_val_t)(-FZ_Q_ONE); g_hi[i] = (fz_val_t)(FZ_Q_ONE - 1); break;
        case 1u: g_lo[i] = (fz_val_t)(-(int64_t)(1u + fz_u8(in)) * (FZ_Q_ONE / 4096));
                 g_hi[i] = (fz_val_t)((int64_t)(1u + fz_u8(in)) * (FZ_Q_ONE / 4096)); break;
        case 2u: g_lo[i] = (fz_val_t)(-(int32_t)(fz_u8(in) % 3u)); g_hi[i] = (fz_val_t)(FZ_Q_ONE - 1);
                 break;
        default: g_lo[i] = fz_value(in); g_hi[i] = fz_value(in); break; /* maybe invalid */
        }
    }
#else
    for (i = 0u; i < FZ_MAX_NU; ++i) {
        switch (lim % 4u) {
        case 0u: g_lo[i] = -FLT_MAX; g_hi[i] = FLT_MAX; break;
        case 1u: g_lo[i] = -(float)(1u + fz_u8(in)) / 64.0f;
                 g_hi[i] = (float)(1u + fz_u8(in)) / 64.0f; break;
        case 2u: g_lo[i] = -(float)(fz_u8(in) % 3u); g_hi[i] = FLT_MAX; break;
        default: g_lo[i] = -fz_value(in); g_hi[i] = fz_value(in); break; /* maybe invalid */
        }
    }
#endif
    t->u_min = g_lo;
    t->u_max = g_hi;
    switch (corrupt) {
    case 0u: t->magic = fz_u32(in); break;
    case 1u: t->format_version = (uint16_t)fz_u8(in); break;
    case 2u: t->nx = (uint16_t)(fz_u8(in) % (FZ_MAX_NX + 1u)); break;   /* maybe 0 */
    case 3u: t->nu = (uint16_t)(fz_u8(in) % (FZ_MAX_NU + 1u)); break;
    case 4u: /* break the layout, within the storage: n_ticks never exceeds FZ_MAX_NT */
        g_start[fz_u8(in) % (FZ_MAX_NS + 1u)] = fz_u8(in) % (FZ_MAX_NT + 1u);
        t->n_ticks = (fz_u8(in) & 1u) ? g_start[t->n_stages] : fz_u8(in) % (FZ_MAX_NT + 1u);
        break;
    case 5u: break;                                              /* special gains, above */
    case 6u: g_np[fz_u8(in) % FZ_MAX_NS] = (uint16_t)fz_u8(in); break;
    case 7u: t->n_stages = (uint16_t)(fz_u8(in) % (FZ_MAX_NS + 1u)); break;
    case 8u:
        switch (fz_u8(in) % 4u) {
        case 0u: t->K = NULL; break;
        case 1u: t->u_max = NULL; break;
        case 2u: t->L = NULL; break;
#ifdef STSP_ARITH_FIXED
        case 3u: t->v_exp = NULL; break;
#endif
        default: t->stage_np = NULL; break;
        }
        break;
    default: break;
    }
    /* The CRC needs valid pointers and dimensions inside the storage; compute it when it can
     * be computed, then perhaps corrupt it. */
    if ((t->K != NULL) && (t->u_max != NULL) && (t->L != NULL) && (t->stage_np != NULL) &&
#ifdef STSP_ARITH_FIXED
        (t->v_exp != NULL) &&
#endif
        (t->n_ticks <= FZ_MAX_NT)) {
        t->crc32 = stsp_table_crc32(t);
    }
    if (corrupt == 9u) {
        t->crc32 ^= 1u << (fz_u8(in) % 32u);
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    fz_in_t in = {data, size};
    stsp_table_t t;
    stsp_ctrl_t c, before;
    uint32_t call, model_next = 0u;
    int ready;
    fz_build_table(&in, &t);
    memset(&c, 0xA5, sizeof c);                                   /* garbage before init */
    ready = 0;
    for (call = 0u; (call < FZ_MAX_CALLS) && (in.n > 0u); ++call) {
        const uint32_t op = fz_u8(&in);
        if (op < 12u) {                                           /* (re)init */
            const stsp_status_t st = ((op & 1u) != 0u)
                ? stsp_init_expect(&c, &t, fz_u8(&in) % 8u, fz_u8(&in) % 5u)
                : stsp_init(&c, &t);
            fz_check(fz_known_status(st) && (st <= STSP_OK));
            ready = (st == STSP_OK);
            model_next = 0u;
            if (ready) {
                fz_check(c.next_tick == 0u);
            }
        } else if (op < 18u) {
            const stsp_status_t st = stsp_reset(&c);
            fz_check(st == (ready ? STSP_OK : STSP_ERR_NOT_INITIALIZED));
            model_next = 0u;
        } else if (op < 20u) {
            const stsp_status_t st = stsp_verify(&c);
            fz_check(st == (ready ? STSP_OK : STSP_ERR_NOT_INITIALIZED));
        } else {                                                  /* step */
            const uint32_t how = fz_u8(&in) % 8u;
            fz_val_t x[FZ_MAX_NX + 1u], u[STSP_MAX_NU + 1u];
            const uint32_t nx = ready ? t.nx : FZ_MAX_NX, nu = ready ? t.nu : FZ_MAX_NU;
            uint32_t tick, i;
            int finite = 1;
            stsp_status_t st;
            switch (how) {
            case 0u: case 1u: case 2u: tick = model_next; break;
            case 3u: tick = model_next - 1u; break;               /* repeat (or wrap) */
            case 4u: tick = model_next + 1u + fz_u8(&in) % 4u; break;
            case 5u: tick = fz_u8(&in); break;
            case 6u: tick = ready ? t.n_ticks + fz_u8(&in) % 2u : 0u; break;
            default: tick = fz_u32(&in); break;
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
                fz_check(fz_known_status(st) && (st < STSP_OK));
                fz_check(memcmp(&c, &before, sizeof c) == 0);
                continue;
            }
            st = stsp_step(&c, tick, x, u);
            fz_check(fz_known_status(st));
            fz_check(u[STSP_MAX_NU] == FZ_SENTINEL);                  /* nothing past the buffer */
            if (!ready) {
                fz_check(st == STSP_ERR_NOT_INITIALIZED);
                fz_check(u[0] == FZ_SENTINEL);                        /* u not written */
                continue;
            }
            fz_check(nu <= STSP_MAX_NU);
            for (i = nu; i < STSP_MAX_NU; ++i) {
                fz_check(u[i] == FZ_SENTINEL);
            }
            if (st < STSP_OK) {
                for (i = 0u; i < nu; ++i) {
                    fz_check(fz_is_zero(u[i]));
                }
                fz_check(memcmp(&c, &before, sizeof c) == 0);
            } else {
                for (i = 0u; i < nu; ++i) {
                    fz_check(fz_finite(u[i]));
                    fz_check((u[i] >= t.u_min[i]) && (u[i] <= t.u_max[i]));
                    if ((st == STSP_WARN_SATURATED) && ((c.sat_mask >> i) & 1u)) {
                        fz_check((u[i] == t.u_min[i]) || (u[i] == t.u_max[i]));
                    }
                }
                if (st == STSP_WARN_SATURATED) {
                    fz_check(c.sat_mask != 0u);
                }
            }
            /* The tick bookkeeping, in the documented order of checks. */
            if (tick >= t.n_ticks) {
                fz_check(st == STSP_ERR_TICK_RANGE);
            } else if ((model_next > 0u) && (tick + 1u < model_next)) {
                fz_check(st == STSP_ERR_TICK_ORDER);
            } else if (!finite) {
                fz_check(st == STSP_ERR_NONFINITE_STATE);
            } else if (st >= STSP_OK) {
                if (st != STSP_WARN_SATURATED) {
                    const stsp_status_t tick_st =
                        ((model_next > 0u) && (tick + 1u == model_next)) ? STSP_WARN_TICK_REPEATED
                        : (tick > model_next) ? STSP_WARN_TICK_SKIPPED : STSP_OK;
                    fz_check(st == tick_st);
                }
                if (tick + 1u > model_next) {
                    model_next = tick + 1u;
                }
            } else {
                fz_check(st == STSP_ERR_NONFINITE_OUTPUT);
            }
            fz_check(c.next_tick == model_next);
        }
    }
    return 0;
}
