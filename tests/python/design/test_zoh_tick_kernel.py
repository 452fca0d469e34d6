"""The compiled tick kernel of the exact ZOH design against the numpy reference loop, and the
packed tick map against the Van Loan exponential it replaces."""
from dataclasses import replace

import numpy as np
import pytest

from stospline.design import zoh as dz
from stospline.design.continuous import DesignError
from stospline.design.kernels import build_kernels, zoh_stage_ticks
from stospline.problem import parse_problem
from stospline.design.tick_reference import van_loan_tick_data

RTOL = 1e-12     # C vs numpy: the same recursion, rounded differently


def random_problem(seed: int, n: int = 6, m: int = 2, hz: int = 50):
    """A seeded random n-state problem: state and input noise, every cost term, equality
    constraints of different widths and a trailing knot with a penalty only."""
    rng = np.random.default_rng(seed)
    A = rng.normal(scale=0.6, size=(n, n))
    B = rng.normal(size=(n, m))
    Z = rng.normal(size=(n + m, n + m))
    M = 0.3 * Z @ Z.T + np.diag(np.r_[np.zeros(n), np.ones(m)])   # [[Q, S], [S', R]] > 0
    noise = [{"state": int(i), "G": rng.normal(scale=0.25, size=(n, 2)).tolist()}
             for i in rng.choice(n, size=3, replace=False)]
    noise.append({"input": 0, "G": rng.normal(scale=0.15, size=(n, 2)).tolist()})

    def rows(p):
        return rng.normal(size=(p, n)).tolist()

    knots = [{"t": 1.0, "constraint": {"C": rows(2), "value": rng.normal(size=2).tolist()}},
             {"t": 1.6, "penalty": {"C": rows(3), "target": rng.normal(size=3).tolist(),
                                    "weight": 2.0}},
             {"t": 2.4, "constraint": {"C": rows(1), "value": [0.7]},
              "penalty": {"C": np.eye(n).tolist(), "target": np.zeros(n).tolist(),
                          "weight": 0.5}},
             {"t": 3.0, "penalty": {"C": rows(2), "target": [1.0, -1.0], "weight": 4.0}}]
    return parse_problem({
        "name": "rand6", "x0": rng.normal(size=n).tolist(), "tick_hz": hz,
        "dynamics": {"A": A.tolist(), "B": B.tolist(), "noise": noise},
        "cost": {"Q": M[:n, :n].tolist(), "S": M[:n, n:].tolist(), "R": M[n:, n:].tolist(),
                 "q": rng.normal(size=n).tolist(), "r": rng.normal(size=m).tolist(),
                 "rho": 0.3},
        "knots": knots})


def _close(a, b, what):
    a, b = np.asarray(a, float), np.asarray(b, float)
    assert a.shape == b.shape, what
    scale = max(np.abs(b).max(initial=0.0), 1.0)
    err = np.abs(a - b).max(initial=0.0) / scale
    assert err <= RTOL, f"{what}: relative error {err:.2e}"


def _same_design(c, ref):
    _close(c.J0, ref.J0, "J0")
    for sc, sr in zip(c.stages, ref.stages):
        for f in ("K", "k0", "L", "P0", "p0", "c0", "N0", "W0", "m0", "Lambda", "lambda0"):
            _close(getattr(sc, f), getattr(sr, f), f"stage {sr.index} {f}")


@pytest.mark.parametrize("hz", [10, 1000])
@pytest.mark.parametrize("mode", ["stagewise", "joint"])
def test_robot_c_kernel_matches_numpy_reference(robot_problem, mode, hz):
    c = dz.design_zoh(robot_problem, hz, mode=mode, kernel="c")
    ref = dz.design_zoh(robot_problem, hz, mode=mode, kernel="numpy")
    _same_design(c, ref)


@pytest.mark.parametrize("seed", [1, 2])
@pytest.mark.parametrize("mode", ["stagewise", "joint"])
def test_random_6_state_c_kernel_matches_numpy_reference(seed, mode):
    problem = random_problem(seed)
    c = dz.design_zoh(problem, mode=mode, kernel="c")
    ref = dz.design_zoh(problem, mode=mode, kernel="numpy")
    _same_design(c, ref)
    assert [s.L.shape[2] for s in c.stages] == [s.L.shape[2] for s in ref.stages]


@pytest.mark.parametrize("h", [1e-3, 0.05, 0.5])
@pytest.mark.parametrize("which", ["robot", "random", "noise-free"])
def test_packed_tick_map_equals_van_loan(robot_problem, which, h):
    """The packed tick map (from the packed generator's exponential, or without noise from
    ``Phi = exp(Ahat h)``: ``H = G' V G``) equals Van Loan's 2d²-square exponential."""
    stage = robot_problem.stages[0] if which == "robot" else random_problem(3).stages[0]
    if which == "noise-free":
        stage = replace(stage, G=np.zeros_like(stage.G), H=None)
        assert not stage.noise_tensor.any()
    td = dz._tick_data(stage, h)
    A2, Hc, F = van_loan_tick_data(stage, h)
    n = stage.A.shape[0]
    rng = np.random.default_rng(4)
    Z = rng.normal(size=(n + 1, n + 1))
    V = Z @ Z.T
    ref = A2 @ V.ravel()
    np.testing.assert_allclose(td.A2 @ V.ravel(), ref, rtol=0, atol=1e-13 * np.abs(ref).max())
    np.testing.assert_allclose(td.Hc, Hc, rtol=0, atol=1e-13 * max(np.abs(Hc).max(), 1e-300))
    np.testing.assert_array_equal(td.F, F)
    # The packed forms the C kernel reads are the same numbers.
    d = n + stage.B.shape[1] + 1
    iu, ju = np.triu_indices(d)
    ia, ib = np.triu_indices(n + 1)
    Vs = V[ia, ib]                               # packed V: the upper triangle
    np.testing.assert_allclose(td.A2sT.T @ Vs, ref.reshape(d, d)[iu, ju], rtol=0,
                               atol=1e-13 * np.abs(ref).max())
    np.testing.assert_array_equal(td.Hcs, td.Hc[iu, ju])


def test_kernel_reports_indefinite_huu_and_design_raises(robot_problem, monkeypatch):
    stage = robot_problem.stages[0]
    td = dz._tick_data(stage, 0.1)
    n, m = 4, 2
    V = -1e3 * np.eye(n + 1)                     # a concave value: Huu = R h - Gamma' V Gamma
    N, W, mv = np.zeros((n, 0)), np.zeros((0, 0)), np.zeros(0)
    with pytest.raises(np.linalg.LinAlgError, match="not positive definite at tick 4"):
        zoh_stage_ticks(td.A2sT, td.Hcs, td.F, V, N, W, mv, 5, m)
    # Through the designer: the same DesignError the numpy reference raises for a singular Huu.
    real = dz._tick_data

    def flipped(stage, h):
        t = real(stage, h)
        return replace(t, Hc=-t.Hc, Hcs=-t.Hcs)

    monkeypatch.setattr(dz, "_tick_data", flipped)
    with pytest.raises(DesignError, match="lost positive definiteness") as exc:
        dz.design_zoh(robot_problem, 10, kernel="c")
    assert exc.value.field == "knots[1].t"


def test_kernel_leaves_inputs_alone_and_checks_shapes(robot_problem):
    td = dz._tick_data(robot_problem.stages[1], 0.01)
    rng = np.random.default_rng(5)
    Z = rng.normal(size=(5, 5))
    V, N, W, mv = Z @ Z.T, rng.normal(size=(4, 3)), np.eye(3), rng.normal(size=3)
    keep = [a.copy() for a in (V, N, W, mv)]
    out = zoh_stage_ticks(td.A2sT, td.Hcs, td.F, V, N, W, mv, 7, 2)
    ref = dz._stage_ticks_numpy(td, V, N, W, mv, 7, 2)
    for a, b in zip(keep, (V, N, W, mv)):
        np.testing.assert_array_equal(a, b)
    for a, b, what in zip(out, ref, ["K", "k0", "L", "V", "N", "W", "mv"]):
        _close(a, b, what)
    with pytest.raises(ValueError, match="W has shape"):
        zoh_stage_ticks(td.A2sT, td.Hcs, td.F, V, N, np.eye(2), mv, 7, 2)


def test_kernel_switch(monkeypatch):
    monkeypatch.setenv("STOSPLINE_ZOH_KERNEL", "numpy")
    assert dz._pick_kernel(None) is dz._stage_ticks_numpy
    assert dz._pick_kernel("c") is dz._stage_ticks_c
    monkeypatch.delenv("STOSPLINE_ZOH_KERNEL")
    assert dz._pick_kernel(None) is dz._stage_ticks_c
    with pytest.raises(ValueError, match="kernel must be one of"):
        dz._pick_kernel("fortran")


def test_build_is_cached_by_source_hash(tmp_path):
    first = build_kernels(tmp_path)
    assert first.parent.parent == tmp_path and first.exists()
    assert build_kernels(tmp_path) == first


def test_stage_cache_key_sees_control_noise():
    stage = random_problem(1).stages[0]
    other = replace(stage, H=2 * stage.H)
    assert dz._stage_key(stage, 0.1) != dz._stage_key(other, 0.1)
