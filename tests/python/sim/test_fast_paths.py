"""The fast paths of the CLI agree with their references: the numpy matrix exponential with
scipy's, and the C tick loop of the oracle (oracle/tick_kernel.c) with the numpy loop, the
moments of an output at every tick (the corridors' exit bounds) included."""
import numpy as np
import pytest
import scipy.linalg

from stospline.oracle import evaluate as oracle
from stospline.expm import expm
from stospline.pipeline import design_problem
from stospline.problem import load_problem

from conftest import EXAMPLES


@pytest.mark.parametrize("scale", [0.0, 1e-6, 1e-3, 0.1, 1.0, 5.0])
@pytest.mark.parametrize("n", [1, 2, 7, 28])
def test_expm_matches_scipy(n, scale):
    A = np.random.default_rng(n).standard_normal((n, n)) * scale / np.sqrt(n)
    ref = scipy.linalg.expm(A)
    np.testing.assert_allclose(expm(A), ref, rtol=0, atol=1e-14 * max(1.0, np.abs(ref).max()))


def test_expm_of_nilpotent_and_diagonal():
    N = np.array([[0.0, 1.0], [0.0, 0.0]])
    np.testing.assert_array_equal(expm(N), [[1.0, 1.0], [0.0, 1.0]])
    D = np.diag([-30.0, 0.0, 2.0])
    np.testing.assert_allclose(np.diag(expm(D)), np.exp([-30.0, 0.0, 2.0]), rtol=1e-13)
    with pytest.raises(ValueError):
        expm(np.ones((2, 3)))


@pytest.mark.parametrize("example, mode", [("robot_corridor", "stagewise"),
                                           ("robot_bands", "joint"),
                                           ("robot_narrow_corridor", "joint")])
@pytest.mark.parametrize("propagator", ["exact", "euler"])
@pytest.mark.parametrize("path", [False, True])
def test_oracle_kernel_matches_numpy(example, mode, propagator, path, monkeypatch):
    p = load_problem(EXAMPLES / f"{example}.toml")
    d = design_problem(p, mode=mode)
    runs = {}
    Cy = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0], [0, 1.0, 0, 1.0]])   # the exit bounds' outputs
    for kernel in ("numpy", "c"):
        monkeypatch.setenv("STOSPLINE_ORACLE_KERNEL", kernel)
        runs[kernel] = oracle.evaluate_table(p, d.table, path=path, propagator=propagator,
                                             output=Cy)
    a, b = runs["numpy"], runs["c"]
    for name in ("path_y_mean", "path_y_cov"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.shape == y.shape and len(x) == d.table.n_ticks + 1, name
        np.testing.assert_allclose(y, x, rtol=0, atol=1e-11 * max(1.0, np.abs(x).max()))
    if path:     # every tick's state and command moments (the Q scales read them)
        for name in ("path_t", "path_mean", "path_var", "path_u_mean", "path_u_var"):
            x, y = getattr(a, name), getattr(b, name)
            assert x.shape == y.shape and x.size, name
            np.testing.assert_allclose(y, x, rtol=0, atol=1e-11 * max(1.0, np.abs(x).max()))
    assert b.J == pytest.approx(a.J, rel=1e-12)
    for x, y in zip(a.knot_mean + a.knot_cov + a.knot_constraint,
                    b.knot_mean + b.knot_cov + b.knot_constraint):
        np.testing.assert_allclose(y, x, rtol=0, atol=1e-11 * max(1.0, np.abs(x).max()))
    # the C path really ran: the numpy one is the reference, not the code under test
    monkeypatch.setenv("STOSPLINE_ORACLE_KERNEL", "c")
    assert oracle._c_kernel() is not None


@pytest.mark.parametrize("seed", range(3))
def test_noise_free_tick_maps_equal_the_van_loan_map(seed):
    """Without noise the oracle takes a tick's moment map as Phi ⊗ Phi and its cost row from a
    2d-square exponential (`_noise_free_tick`): equal to rounding to the 2d²-square Van Loan
    exponential of `moments.exact_tick`, drift and cross weights included."""
    from stospline.design.moments import exact_tick, running_cost_matrix
    from stospline.problem.build import problem_from_arrays
    from stospline.oracle.tick_moments import _noise_free_tick
    rng = np.random.default_rng(seed)
    n, m, h = 3, 2, 0.02
    Q = rng.normal(size=(n, n))
    stage = problem_from_arrays(
        x0=rng.normal(size=n), A=rng.normal(size=(n, n)), B=rng.normal(size=(n, m)),
        R=np.eye(m), Q=Q @ Q.T + np.eye(n), S=0.1 * rng.normal(size=(n, m)), q=rng.normal(size=n),
        f=rng.normal(size=n), tick_hz=50,
        knots=[{"t": 1.0, "penalty": {"C": np.eye(n), "target": np.zeros(n), "weight": 1.0}}]
    ).stages[0]
    prop, row = _noise_free_tick(stage, n, m, h)
    ref = exact_tick(stage, m + 1, h)
    ref_row = running_cost_matrix(stage, n, m, n + m + 1, n).ravel() @ ref.Psi
    np.testing.assert_allclose(prop.Phi, ref.Phi, rtol=0, atol=1e-14 * np.abs(ref.Phi).max())
    np.testing.assert_allclose(row, ref_row, rtol=0, atol=1e-14 * np.abs(ref_row).max())


@pytest.mark.parametrize("path", [False, True])
@pytest.mark.parametrize("seed", range(2))
def test_factored_noise_free_loop_equals_the_packed_loop(seed, path, monkeypatch):
    """Without noise the C loop applies a tick as ``F E ww' F'`` (`oracle/tick_kernel.c`):
    equal to rounding to the packed moment map's loop (`oracle_kernel.c`) and to the numpy
    loop, with latched multipliers, cross weights and a penalty knot."""
    from stospline.problem.build import problem_from_arrays
    rng = np.random.default_rng(seed)
    n, m = 6, 3
    Q = rng.normal(size=(n, n))
    p = problem_from_arrays(
        x0=rng.normal(size=n), A=rng.normal(size=(n, n)) / 2, B=rng.normal(size=(n, m)),
        R=np.eye(m), Q=Q @ Q.T + np.eye(n), S=0.1 * rng.normal(size=(n, m)),
        q=rng.normal(size=n), tick_hz=100,
        knots=[{"t": 0.5, "constraint": {"C": np.eye(n)[:2], "value": [1.0, -1.0]}},
               {"t": 1.0, "penalty": {"C": np.eye(n), "target": np.zeros(n), "weight": 3.0}}])
    assert not any(st.noise_tensor.any() for st in p.stages)
    table = design_problem(p).table
    calls = []
    factored = oracle._factored_kernel()
    assert factored is not None

    def counted(*args, **kw):
        calls.append(1)
        return factored(*args, **kw)
    monkeypatch.setattr(oracle, "_factored_kernel", lambda: counted)
    Cy = np.eye(n)[:3] + 0.5 * np.eye(n, k=1)[:3]
    a = oracle.evaluate_table(p, table, path=path, output=Cy)
    assert len(calls) == len(p.stages)
    monkeypatch.setattr(oracle, "_factored_kernel", lambda: None)
    b = oracle.evaluate_table(p, table, path=path, output=Cy)
    monkeypatch.setenv("STOSPLINE_ORACLE_KERNEL", "numpy")
    c = oracle.evaluate_table(p, table, path=path, output=Cy)
    for ref in (b, c):
        assert a.J == pytest.approx(ref.J, rel=1e-13)
        for name in ("path_y_mean", "path_y_cov"):
            x, y = getattr(ref, name), getattr(a, name)
            assert x.shape == y.shape and len(x) == table.n_ticks + 1, name
            scale = max(1.0, np.abs(x).max(), np.abs(ref.path_y_mean).max() ** 2)
            np.testing.assert_allclose(y, x, rtol=0, atol=1e-13 * scale)
        for x, y in zip(ref.knot_mean + ref.knot_cov, a.knot_mean + a.knot_cov):
            np.testing.assert_allclose(y, x, rtol=0, atol=1e-13 * max(1.0, np.abs(x).max()))
        if path:
            for name in ("path_mean", "path_var", "path_u_mean", "path_u_var"):
                x, y = getattr(ref, name), getattr(a, name)
                assert x.shape == y.shape and x.size, name
                # variances are differences E x² - (E x)²: scaled by the second moment
                scale = max(1.0, np.abs(x).max(), np.abs(ref.path_mean).max() ** 2)
                np.testing.assert_allclose(y, x, rtol=0, atol=1e-13 * scale)
