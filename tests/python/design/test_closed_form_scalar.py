"""A scalar problem with a closed-form solution (derivation: docs/theory/closed-form.md).

    dX = a X dt + b u dt + g X dZ   on [t0, T],
    minimise E{ w (X(T) - rho)^2 + int r u^2 dt }   subject to   E X(T) = zeta.

With alpha = 2a + g^2, beta = b^2 / r, s = T - t and D(s) = e^{-alpha s} + w beta phi(s),
phi(s) = (1 - e^{-alpha s}) / alpha:

    P = w / D,   N = e^{-(a + g^2) s} / D,   p = -w rho N,
    W = beta I(s),   I(s) = int_0^s e^{-2(a + g^2) sigma} / D(sigma)^2 d sigma,
    m = -zeta + w rho W,   c = w rho^2 - w^2 rho^2 W,

gains K = b P / r, k0 = b p / r, L = b N / r, latch v = (N x + m) / W, and
J0 = P x0^2 + 2 p x0 + c + (N x0 + m)^2 / W. I(s) is elementary for a = 0 and for w = 0, and
a Gauss hypergeometric function in general.
"""
import math

import numpy as np
import pytest
from scipy.special import hyp2f1

from stospline.design.continuous import design_continuous
from stospline.oracle.evaluate import evaluate_continuous
from stospline.problem import parse_problem

B, R = 1.3, 0.8
X0 = 0.9
TIMES = [0.5, 2.5]             # t0, T


def closed_form(a, g, w, rho, zeta, t, *, b=B, r=R, T=TIMES[1]):
    """P, p, c, N, W, m of the backward equations at time t (see docs/theory/closed-form.md);
    ``zeta=None``: no constraint (then W and m are not needed, nor is I(s) if rho = 0)."""
    al, be = 2 * a + g * g, b * b / r
    s = T - t
    E = math.exp(-al * s)
    phi = -math.expm1(-al * s) / al if al else s
    D = E + w * be * phi
    P = w / D
    N = math.exp(-(a + g * g) * s) / D
    p = -w * rho * N
    if zeta is None and rho == 0:               # W, m unused and c = 0: I(s) not needed
        I = math.nan
    elif w == 0:                                # D = e^{-alpha s}, N = e^{a s}
        I = math.expm1(2 * a * s) / (2 * a) if a else s
    elif a == 0:                                # alpha = g^2, D = c1 E + c0
        c0 = w * be / (g * g)
        c1 = 1.0 - c0
        I = (c0 * (1.0 - 1.0 / D) - math.log(D)) / (g * g * c1 * c1)
    else:                                       # u = e^{-alpha sigma}: an incomplete beta
        assert al > 0, "the hypergeometric form below needs alpha = 2a + g^2 > 0"
        c0 = w * be / al
        c1 = 1.0 - c0
        gam = 2 * (a + g * g) / al
        F = lambda u: u ** gam / (gam * c0 * c0) * hyp2f1(2, gam, gam + 1, -c1 * u / c0)
        I = (F(1.0) - F(E)) / al
    W = be * I
    m = None if zeta is None else -zeta + w * rho * W
    c = w * rho * rho * (1.0 - w * W) if rho else 0.0
    return dict(P=P, p=p, c=c, N=N, W=W, m=m)


def scalar_problem(a, g, w=None, rho=0.0, zeta=None):
    knot = {"t": TIMES[1]}
    if w is not None:
        knot["penalty"] = {"C": [[1.0]], "target": [rho], "weight": w}
    if zeta is not None:
        knot["constraint"] = {"C": [[1.0]], "value": [zeta]}
    return parse_problem({
        "name": "scalar", "t0": TIMES[0], "x0": [X0], "tick_hz": 10,
        "dynamics": {"A": [[a]], "B": [[B]], "noise": [{"state": 0, "G": [[g]]}]},
        "cost": {"R": [[R]]}, "knots": [knot]})


def J0_closed_form(v, constrained=True):
    J = v["P"] * X0 ** 2 + 2 * v["p"] * X0 + v["c"]
    if constrained:
        J += (v["N"] * X0 + v["m"]) ** 2 / v["W"]
    return J


SAMPLE_T = np.array([0.5, 0.9, 1.7, 2.2, 2.5])


def check_against_closed_form(problem, a, g, w, rho, zeta, mode="stagewise"):
    constrained = zeta is not None
    design = design_continuous(problem, mode=mode)
    st = design.stages[0]
    ref = [closed_form(a, g, w, rho, zeta, t) for t in SAMPLE_T]
    v0 = ref[0]
    # Cost-to-go from (t0, x0).
    assert design.J0 == pytest.approx(J0_closed_form(v0, constrained), rel=1e-9, abs=1e-12)
    # The backward solution and the gains u = -K x - k0 - L v along the stage.
    P, p, c, N, W, m = st.riccati(SAMPLE_T)
    np.testing.assert_allclose(P[0, 0], [v["P"] for v in ref], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(p[0], [v["p"] for v in ref], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(c, [v["c"] for v in ref], rtol=1e-9, atol=1e-12)
    K, k0, L = st.gains(SAMPLE_T)
    np.testing.assert_allclose(K[:, 0, 0], [B * v["P"] / R for v in ref], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(k0[:, 0], [B * v["p"] / R for v in ref], rtol=1e-9, atol=1e-12)
    if constrained:
        np.testing.assert_allclose(N[0, 0], [v["N"] for v in ref], rtol=1e-9)
        np.testing.assert_allclose(W[0, 0], [v["W"] for v in ref], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(m[0], [v["m"] for v in ref], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(L[:, 0, 0], [B * v["N"] / R for v in ref], rtol=1e-9)
        # The latch map v = Lambda x + lambda0 = (N x + m) / W at t0.
        assert st.Lambda.shape == (1, 1)
        assert st.Lambda[0, 0] == pytest.approx(v0["N"] / v0["W"], rel=1e-9)
        assert st.lambda0[0] == pytest.approx(v0["m"] / v0["W"], rel=1e-9)
        assert design.latch(0, problem.x0)[0] == pytest.approx(
            (v0["N"] * X0 + v0["m"]) / v0["W"], rel=1e-9)
    else:
        assert L.shape == (len(SAMPLE_T), 1, 0) and st.Lambda.shape == (0, 1)
    # The law, run through the exact moment oracle, costs what the closed form says.
    moments = evaluate_continuous(problem, design)
    assert moments.J == pytest.approx(J0_closed_form(v0, constrained), rel=1e-9)
    if constrained:
        assert moments.knot_constraint[0][0] == pytest.approx(zeta, abs=1e-9)
    return design


@pytest.mark.parametrize("mode", ["stagewise", "joint"])
def test_penalty_and_constraint_driftless(mode):
    """a = 0: the full problem in elementary functions."""
    a, g, w, rho, zeta = 0.0, 0.7, 2.0, 1.1, -0.6
    check_against_closed_form(scalar_problem(a, g, w, rho, zeta), a, g, w, rho, zeta, mode)


def test_penalty_and_constraint_with_drift_hypergeometric():
    """a != 0: I(s) through the Gauss hypergeometric function."""
    a, g, w, rho, zeta = 0.3, 0.5, 1.5, 1.1, -0.6
    check_against_closed_form(scalar_problem(a, g, w, rho, zeta), a, g, w, rho, zeta)


@pytest.mark.parametrize("a", [0.5, -0.4])
def test_interpolation_only(a):
    """w = 0: P = p = c = 0, N = e^{a s}, W = beta (e^{2 a s} - 1) / (2 a), m = -zeta; the
    control is open loop, so the cost does not depend on the noise at all."""
    g, zeta = 0.6, 1.7
    design = check_against_closed_form(scalar_problem(a, g, zeta=zeta), a, g, 0.0, 0.0, zeta)
    quiet = design_continuous(scalar_problem(a, 0.0, zeta=zeta))
    assert design.J0 == pytest.approx(quiet.J0, rel=1e-10)
    s = TIMES[1] - TIMES[0]
    assert design.J0 == pytest.approx(
        (math.exp(a * s) * X0 - zeta) ** 2 * 2 * a * R / (B * B * math.expm1(2 * a * s)),
        rel=1e-9)


@pytest.mark.parametrize("a, rho", [(0.0, 1.1), (0.3, 1.1), (-0.4, 0.0)])
def test_smoothing_only(a, rho):
    """No constraint: J0 = P x0^2 + 2 p x0 + c (c needs I(s) unless rho = 0)."""
    g, w = 0.7, 2.0
    check_against_closed_form(scalar_problem(a, g, w, rho), a, g, w, rho, None)
