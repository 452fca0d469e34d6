/* Shared by tests/c/test_params.c and tests/c/test_params_spline.c: the hash of a command,
 * the states of the references (tests/c/params_reference.py) and one run over every tick of
 * the parameter table P on the gain table T. Before including it, define NX, NU, N_TICKS, T,
 * P, N_CHECKED and CHECKED_TICKS (the run's kept ticks), and in a fixed-point build QMAX. */
#ifndef PARAMS_RUN_H
#define PARAMS_RUN_H

/* A command as the references hash it: a binary32's bits (a zero as +0, the C's sign of zero
 * may differ), or a Q integer's int32 two's complement. */
static uint32_t word(stsp_scalar_t v)
{
#ifdef STSP_ARITH_FIXED_POINT
    return (uint32_t)(int32_t)v;
#else
    uint32_t b;
    v = v + 0.0f;
    memcpy(&b, &v, sizeof b);
    return b;
#endif
}

static uint32_t fnv1a(uint32_t h, uint32_t w)
{
    uint32_t i;
    for (i = 0u; i < 4u; ++i) {
        h = (h ^ ((w >> (8u * i)) & 0xFFu)) * 0x01000193u;
    }
    return h;
}

/* The state of tick j, as params_reference.params_state() (float32) or
 * params_q_reference.params_q_state() (fixed point: over most of the Q range). */
static void state(uint32_t j, stsp_scalar_t x[NX])
{
    uint32_t c;
    for (c = 0u; c < NX; ++c) {
#ifdef STSP_ARITH_FIXED_POINT
        const int32_t step = (int32_t)(((int64_t)QMAX + 1) / 20 - 1);
        x[c] = (stsp_scalar_t)(((int32_t)((7u * j + 13u * c) % 41u) - 20) * step);
#else
        x[c] = (float)((7u * j + 13u * c) % 41u) * 0.05f - 1.0f;
#endif
    }
}

/* A run over every tick: theta0 set before tick 0 (NULL: the nominal), theta1 before tick
 * `at` (NULL: none); returns the hash of the commands, run A's checked ticks into checked. */
static uint32_t run(const float *theta0, uint32_t at, const float *theta1,
                    uint32_t checked[N_CHECKED][2])
{
    stsp_param_t pc;
    stsp_scalar_t x[NX];
    stsp_scalar_t u[NU];
    uint32_t h = 0x811C9DC5u;
    uint32_t j;
    uint32_t k = 0u;
    assert_int_equal(stsp_param_init(&pc, T, P), STSP_OK);
    if (theta0 != NULL) {
        assert_int_equal(stsp_set_params(&pc, theta0), STSP_OK);
    }
    for (j = 0u; j < N_TICKS; ++j) {
        stsp_status_t st;
        if ((theta1 != NULL) && (j == at)) {
            assert_int_equal(stsp_set_params(&pc, theta1), STSP_OK);
        }
        state(j, x);
        st = stsp_param_step(&pc, j, x, u);
        assert_true((st == STSP_OK) || (st == STSP_WARN_SATURATED));
        h = fnv1a(fnv1a(h, word(u[0])), word(u[1]));
        if ((checked != NULL) && (k < N_CHECKED) && (CHECKED_TICKS[k] == j)) {
            checked[k][0] = word(u[0]);
            checked[k][1] = word(u[1]);
            ++k;
        }
    }
    return h;
}

#endif /* PARAMS_RUN_H */
