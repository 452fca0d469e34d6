"""The exact fourth moments of the plant scheme (oracle.tails) and the verdict's exact
standard errors: against a brute-force Kronecker recursion, against a seeded Monte Carlo of a
light-tailed loop, and the verdict on the robot for the right and a wrong controller."""
import itertools

import numpy as np
import pytest

from stospline.design.moments import augmented_drift, running_cost_matrix
from stospline.design.zoh import design_zoh
from stospline.expm import expm
from stospline.harness.controller import build_controller
from stospline.harness.montecarlo import compare_to_oracle, simulate
from stospline.oracle.evaluate import evaluate_table
from stospline.oracle.tails import evaluate_tails
from stospline.oracle.tick_moments import _latch_transform
from stospline.problem import parse_problem
from stospline.table.format import table_of


def _tiny(g: float, hz: int = 10):
    """Two states (position, velocity), multiplicative noise on the velocity and on the
    command, a penalised and a constrained knot."""
    return parse_problem({
        "name": "tiny", "t0": 0.0, "x0": [1.0, -0.5], "tick_hz": hz,
        "dynamics": {"A": [[0.0, 1.0], [0.0, -0.3]], "B": [[0.0], [1.0]],
                     "noise": [{"state": 1, "G": [[0.0, 0.0], [g, 0.0]]},
                               {"input": 0, "G": [[0.0, 0.0], [0.3 * g, 0.5 * g]]}]},
        "cost": {"Q": [[0.2, 0.0], [0.0, 0.1]], "R": [[0.5]]},
        "knots": [{"t": 0.3, "constraint": {"C": [[1.0, 0.0]], "value": [0.4]}},
                  {"t": 0.5, "penalty": {"C": [[1.0, 0.0], [0.0, 1.0]], "target": [0.0, 0.0],
                                         "weight": 2.0}}]})


def _noise_expectation(A, N, dt, order):
    """``E (A + sum_k xi_k N_k)^{(x)order}`` as (weight, matrices) terms, xi ~ N(0, dt I), by
    Isserlis' theorem (pairings of the noise factors)."""
    terms = []
    for pick in itertools.product(range(len(N) + 1), repeat=order):
        noisy = [p - 1 for p in pick if p > 0]
        if len(noisy) % 2:
            continue
        pairings = _pairings(noisy)
        coef = sum(all(a == b for a, b in pr) for pr in pairings) * dt ** (len(noisy) // 2)
        if coef:
            terms.append((coef, [A if p == 0 else N[p - 1] for p in pick]))
    return terms


def _pairings(items):
    if not items:
        return [[]]
    first, rest = items[0], items[1:]
    out = []
    for i, other in enumerate(rest):
        for pr in _pairings(rest[:i] + rest[i + 1:]):
            out.append([(first, other)] + pr)
    return out


def _apply(T, mats):
    for M in mats:
        T = np.tensordot(T, M, axes=([0], [1]))
    return T


def _brute(problem, table, substeps):
    """Forward recursion of the full tensors E q^(x)4, E J q q' and E J^2."""
    n, m, n_latch = table.dims
    h = 1.0 / table.tick_hz
    dt = h / substeps
    dq = n + m + n_latch + 1
    dy = n + n_latch + 1
    y0 = np.concatenate([problem.x0, np.zeros(n_latch), [1.0]])
    T4 = np.einsum("i,j,k,l->ijkl", y0, y0, y0, y0)
    P = np.zeros((dy, dy))
    J2 = 0.0
    out = []
    back = np.r_[0:n, n + m:dq]
    for k in range(table.n_stages):
        st = problem.stages[k]
        if k == 0 or table.stage_n_latch[k] > 0:
            T = _latch_transform(n, n_latch, table.Lambda[k].astype(float),
                                 table.lambda0[k].astype(float), dy)
            T4, P = _apply(T4, [T] * 4), T @ P @ T.T
        Ad = expm(augmented_drift(st, m + 1) * dt)
        A = np.eye(dq)
        A[:n, np.r_[0:n + m, dq - 1]] = Ad[:n]
        G = st.noise_tensor
        N = [np.zeros((dq, dq)) for _ in range(G.shape[2])]
        for c in range(G.shape[2]):
            N[c][:n, :n + m] = G[:, :, c].T
        L = np.zeros((dq, dq))
        idx = np.r_[0:n + m, dq - 1]
        L[np.ix_(idx, idx)] = running_cost_matrix(st, n, m, n + m + 1, n)
        e4 = _noise_expectation(A, N, dt, 4)
        e2 = _noise_expectation(A, N, dt, 2)
        for j in range(int(table.stage_start[k]), int(table.stage_start[k + 1])):
            Tq = np.zeros((dq, dy))
            Tq[:n, :n] = np.eye(n)
            Tq[n + m:, n:] = np.eye(n_latch + 1)
            Tq[n:n + m] = np.hstack([-table.K[j], -table.L[j], -table.k0[j][:, None]])
            Q4, Q2 = _apply(T4, [Tq] * 4), Tq @ P @ Tq.T
            for _ in range(substeps):
                J2 += 2 * dt * np.sum(L * Q2) + dt * dt * np.einsum("ij,kl,ijkl->", L, L, Q4)
                Q2 = Q2 + dt * np.einsum("ij,ijab->ab", L, Q4)
                Q2 = sum(c * mats[0] @ Q2 @ mats[1].T for c, mats in e2)
                Q4 = sum(c * _apply(Q4, mats) for c, mats in e4)
            T4, P = Q4[np.ix_(back, back, back, back)], Q2[np.ix_(back, back)]
        kn = problem.knots[k]
        if kn.penalty is not None:
            C, rho, w = kn.penalty.C, kn.penalty.target, kn.penalty.weight
            Pen = np.zeros((dy, dy))
            Pen[:n, :n] = w * C.T @ C
            Pen[:n, -1] = Pen[-1, :n] = -w * C.T @ rho
            Pen[-1, -1] = w * rho @ rho
            J2 += 2 * np.sum(Pen * P) + np.einsum("ij,kl,ijkl->", Pen, Pen, T4)
            P = P + np.einsum("ij,ijab->ab", Pen, T4)
        mu = T4[:n, -1, -1, -1]
        i = np.arange(n)
        # Central fourth moments by shifting the state to its mean.
        S = np.eye(dy)
        S[:n, -1] = -mu
        out.append(_apply(T4, [S] * 4)[i, i, i, i])
    return P[-1, -1], J2 - P[-1, -1] ** 2, out


def test_fourth_moments_equal_a_brute_force_kronecker_recursion():
    problem = _tiny(0.8)
    table = table_of(design_zoh(problem, 10), quantize=False)
    tails = evaluate_tails(problem, table, substeps=3)     # checks its second moments too
    J, var, mu4 = _brute(problem, table, 3)
    assert tails.J == pytest.approx(J, rel=1e-12)
    assert tails.cost_var == pytest.approx(var, rel=1e-9)
    for k in range(2):
        np.testing.assert_allclose(tails.knot_mu4[k], mu4[k], rtol=1e-8, atol=1e-14)
    assert tails.cost_var > 0 and all((m > 0).all() for m in mu4)


def test_exact_variances_match_a_seeded_monte_carlo():
    """A light-tailed loop (small noise): the cost's variance and each knot component's
    variance and fourth central moment from a seeded run of the C controller lie within 4.5
    of their standard errors (estimated from the same run) of the exact ones."""
    problem = _tiny(0.3)
    table = table_of(design_zoh(problem, 10), quantize=False)
    tails = evaluate_tails(problem, table, substeps=4)
    mc = simulate(problem, build_controller(table), paths=40_000, seed=5, substeps=4,
                  per_path=True)
    N = mc.paths
    c = mc.cost - mc.cost.mean()
    var = c.var(ddof=1)
    se = np.sqrt((np.mean(c ** 4) - np.mean(c ** 2) ** 2) / N)
    assert abs(var - tails.cost_var) < 4.5 * se, (var, tails.cost_var, se)
    for k in range(2):
        dev = mc.knot_states[k] - mc.knot_states[k].mean(axis=0)
        m4 = np.mean(dev ** 4, axis=0)
        se4 = np.sqrt((np.mean(dev ** 8, axis=0) - m4 ** 2) / N)
        assert (np.abs(m4 - tails.knot_mu4[k]) < 4.5 * se4).all(), (k, m4, tails.knot_mu4[k])
        s2 = dev.var(axis=0, ddof=1)
        assert (np.abs(s2 - np.diag(tails.knot_cov[k]))
                < 4.5 * tails.knot_var_se(k, N)).all()


@pytest.fixture(scope="module")
def robot_10hz(robot_problem):
    table = table_of(design_zoh(robot_problem, 10))
    substeps = 20
    scheme = evaluate_table(robot_problem, table, propagator="euler", substeps=substeps,
                            path=False)
    tails = evaluate_tails(robot_problem, table, substeps=substeps, check=scheme)
    return robot_problem, table, scheme, tails, substeps


def _verdict(problem, table, scheme, tails, substeps, seed, K_scale=1.0):
    wrong = table
    if K_scale != 1.0:
        wrong = table_of(design_zoh(problem, 10))
        wrong.K[:] = (wrong.K * K_scale).astype(wrong.K.dtype)
    mc = simulate(problem, build_controller(wrong), paths=4000, seed=seed, substeps=substeps)
    return compare_to_oracle(mc, scheme.J, scheme.knot_mean, knot_covs=scheme.knot_cov,
                             exact_se=tails)


def test_exact_verdict_passes_the_right_controller_and_fails_a_wrong_one(robot_10hz):
    problem, table, scheme, tails, substeps = robot_10hz
    right = _verdict(problem, table, scheme, tails, substeps, seed=11)
    assert right.standard_errors == "exact"
    assert right.ok, (right.verdict.max_abs_z, right.verdict.max_abs_z_of)
    wrong = _verdict(problem, table, scheme, tails, substeps, seed=11, K_scale=1.02)
    assert not wrong.ok, (wrong.verdict.max_abs_z, wrong.verdict.max_abs_z_of)
