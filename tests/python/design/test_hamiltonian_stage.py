"""A continuous design's stage with constant data and no noise is solved exactly from the
Hamiltonian's exponential (`continuous.HamiltonianSolution`), and the oracle evaluates its law
on the stage's own plant from the same flow: both equal the DOP853 integrations (the design at
a tighter tolerance than its default, the oracle's moment ODE) to about 1e-12."""
import numpy as np
import pytest

from stospline.design import continuous
from stospline.oracle import evaluate as oracle
from stospline.problem.build import problem_from_arrays


def _problem(seed: int, n: int = 5, m: int = 2):
    """Two stages: a constraint knot (a latched multiplier) and a penalty knot; drift f and
    cross weights S, r, q so that every block of the augmented equation is exercised."""
    rng = np.random.default_rng(seed)
    Q = rng.normal(size=(n, n))
    return problem_from_arrays(
        x0=rng.normal(size=n), A=rng.normal(size=(n, n)) / 2, B=rng.normal(size=(n, m)),
        R=np.diag(rng.uniform(0.5, 2.0, m)), Q=Q @ Q.T + np.eye(n),
        S=0.1 * rng.normal(size=(n, m)), q=rng.normal(size=n), r=0.1 * rng.normal(size=m),
        f=0.3 * rng.normal(size=n), tick_hz=200,
        knots=[{"t": 0.6, "constraint": {"C": np.eye(n)[:2], "value": [1.0, -0.5]}},
               {"t": 1.5, "penalty": {"C": np.eye(n), "target": np.zeros(n), "weight": 4.0}}])


def _integrated(problem, monkeypatch, **kw):
    with monkeypatch.context() as mp:
        mp.setattr(continuous, "_solved_exactly", lambda stage, noise: False)
        return continuous.design_continuous(problem, **kw)


@pytest.mark.parametrize("mode", ["stagewise", "joint"])
@pytest.mark.parametrize("seed", range(2))
def test_exact_stages_equal_the_tight_integration(seed, mode, monkeypatch):
    p = _problem(seed)
    exact = continuous.design_continuous(p, mode=mode)
    assert all(isinstance(st._sol, continuous.HamiltonianSolution) for st in exact.stages)
    ref = _integrated(p, monkeypatch, mode=mode, rtol=3e-14, atol=1e-18)
    assert exact.J0 == pytest.approx(ref.J0, rel=1e-12)
    for a, b in zip(exact.tick_gains()[1], ref.tick_gains()[1]):
        for x, y in zip(a, b):
            scale = max(1.0, np.abs(y).max(initial=0.0))
            np.testing.assert_allclose(x, y, rtol=0, atol=1e-11 * scale)
    # between ticks too (the oracle's steps): gains_at against the dense output
    for st, sr in zip(exact.stages, ref.stages):
        for t in np.linspace(st.t_start, st.t_end, 7)[:-1] + 1.3e-3:
            for x, y in zip(st.gains_at(t), sr.gains_at(t)):
                np.testing.assert_allclose(x, y, rtol=0,
                                           atol=1e-11 * max(1.0, np.abs(y).max(initial=0.0)))


@pytest.mark.parametrize("seed", range(2))
def test_the_exact_closed_loop_equals_the_moment_integration(seed, monkeypatch):
    p = _problem(seed)
    d = continuous.design_continuous(p)
    exact = oracle.evaluate_continuous(p, d)
    monkeypatch.setattr(oracle, "_exact_flow", lambda st: False)     # integrate every stage
    ref = oracle.evaluate_continuous(p, d)
    assert exact.J == pytest.approx(ref.J, rel=1e-11)
    assert exact.J == pytest.approx(d.J0, rel=1e-11)
    for x, y in zip(ref.knot_mean + ref.knot_cov + ref.knot_constraint,
                    exact.knot_mean + exact.knot_cov + exact.knot_constraint):
        np.testing.assert_allclose(y, x, rtol=0, atol=1e-10 * max(1.0, np.abs(x).max(initial=0.0)))


def test_a_noisy_plant_is_integrated(monkeypatch):
    """Designed without noise (Remark 2) on a plant with noise: the stage is solved exactly,
    but its oracle integrates the moments with the diffusion."""
    p = _problem(0)
    noisy = problem_from_arrays(
        x0=p.x0, A=p.stages[0].A, B=p.stages[0].B, R=p.stages[0].R, Q=p.stages[0].Q,
        S=p.stages[0].S, q=p.stages[0].q, r=p.stages[0].r, f=p.stages[0].f, tick_hz=200,
        noise=[{"state": 0, "G": 0.3 * np.eye(5)[:, :1]}],
        knots=[{"t": 1.5, "penalty": {"C": np.eye(5), "target": np.zeros(5), "weight": 4.0}}])
    d = continuous.design_continuous(noisy, noise=False)
    assert isinstance(d.stages[0]._sol, continuous.HamiltonianSolution)
    m = oracle.evaluate_continuous(noisy, d)
    assert m.J > d.J0 * (1 + 1e-6)       # the diffusion costs: the moments saw it


def test_a_stage_stiff_for_one_tick_is_integrated(monkeypatch):
    """|Hm| h > 2 (fast dynamics, a slow tick): the stage is integrated (DOP853)."""
    rng = np.random.default_rng(3)
    n = 3
    p = problem_from_arrays(x0=np.ones(n), A=-40.0 * np.eye(n) + rng.normal(size=(n, n)),
                            B=np.eye(n), R=np.eye(n), Q=np.eye(n), tick_hz=10,
                            knots=[{"t": 1.0, "penalty": {"C": np.eye(n), "target": np.zeros(n),
                                                          "weight": 1.0}}])
    d = continuous.design_continuous(p)
    assert not isinstance(d.stages[0]._sol, continuous.HamiltonianSolution)
    assert d.J0 == pytest.approx(_integrated(p, monkeypatch).J0, rel=1e-15)


def test_overflow_is_reported_as_before():
    """A mode the input cannot reach grows beyond floating point: the exact solution is not
    finite, so the stage is integrated and the DesignError names the knot, as for any stage."""
    from stospline.errors import DesignError
    p = problem_from_arrays(x0=np.ones(2), A=np.diag([400.0, 0.0]), B=[[0.0], [1.0]],
                            R=np.eye(1), Q=np.eye(2), tick_hz=10000,
                            knots=[{"t": 3.0, "penalty": {"C": [[1.0, 0.0]], "target": [0.0],
                                                          "weight": 1.0}}])
    with pytest.raises(DesignError, match="no bounded solution"):
        continuous.design_continuous(p)
