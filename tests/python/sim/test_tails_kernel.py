"""The fourth-moment oracle's C loop (oracle/tails_kernel.c) against its numpy reference
(oracle.tails with STOSPLINE_ORACLE_KERNEL=numpy): the step's map on symmetric tensors, and
the whole evaluation on the robot, on loops with noise on the command, with several plant
steps per tick and with a band table's latch; and the numpy loop where the module cannot be
built (a FallbackWarning)."""
import numpy as np
import pytest

from stospline.cache import FallbackWarning
from stospline.design.zoh import design_zoh
from stospline.errors import KernelBuildError
from stospline.oracle import kernel, tails, tails_kernel
from stospline.pipeline import design_problem
from stospline.problem import load_problem, parse_problem
from stospline.table.format import table_of

from conftest import EXAMPLES

RTOL = 1e-12


def _input_noise():
    """Two states, noise on the velocity and on the command (two channels), a constrained
    and a penalised knot."""
    return parse_problem({
        "name": "input_noise", "t0": 0.0, "x0": [1.0, -0.5], "tick_hz": 50,
        "dynamics": {"A": [[0.0, 1.0], [0.0, -0.3]], "B": [[0.0], [1.0]],
                     "noise": [{"state": 1, "G": [[0.0, 0.0], [0.8, 0.0]]},
                               {"input": 0, "G": [[0.0, 0.0], [0.24, 0.4]]}]},
        "cost": {"Q": [[0.2, 0.0], [0.0, 0.1]], "R": [[0.5]]},
        "knots": [{"t": 0.3, "constraint": {"C": [[1.0, 0.0]], "value": [0.4]}},
                  {"t": 0.5, "penalty": {"C": [[1.0, 0.0], [0.0, 1.0]], "target": [0.0, 0.0],
                                         "weight": 2.0}}]})


def _both(problem, table, substeps, monkeypatch):
    out = {}
    for name in ("numpy", "c"):
        monkeypatch.setenv("STOSPLINE_ORACLE_KERNEL", name)
        out[name] = tails.evaluate_tails(problem, table, substeps=substeps, check=False)
    return out["numpy"], out["c"]


def _assert_close(ref, got):
    assert got.J == pytest.approx(ref.J, rel=RTOL)
    assert got.cost_var == pytest.approx(ref.cost_var, rel=RTOL)
    for k in range(len(ref.knot_mean)):
        # raw moments are what the loops carry: central ones relative to their scale
        scale2 = np.abs(ref.knot_cov[k] + np.outer(ref.knot_mean[k], ref.knot_mean[k])).max()
        scale4 = max(np.abs(ref.knot_mu4[k]).max(), np.max(ref.knot_mean[k] ** 4))
        np.testing.assert_allclose(got.knot_mean[k], ref.knot_mean[k], rtol=0,
                                   atol=RTOL * max(1.0, np.abs(ref.knot_mean[k]).max()))
        np.testing.assert_allclose(got.knot_cov[k], ref.knot_cov[k], rtol=0,
                                   atol=RTOL * scale2)
        np.testing.assert_allclose(got.knot_mu4[k], ref.knot_mu4[k], rtol=0,
                                   atol=RTOL * scale4)


@pytest.mark.parametrize("example, mode", [("robot_corridor", "stagewise"),
                                           ("quadrotor_altimeter", "stagewise"),
                                           ("robot_bands", "joint")])
def test_c_loop_equals_numpy_on_examples(example, mode, monkeypatch):
    problem = load_problem(EXAMPLES / f"{example}.toml")
    table = design_problem(problem, mode=mode).table
    assert tails.tails_unsupported(problem, table) is None
    ref, got = _both(problem, table, 1, monkeypatch)
    _assert_close(ref, got)


@pytest.mark.parametrize("substeps", [1, 3])
def test_c_loop_equals_numpy_with_command_noise_and_substeps(substeps, monkeypatch):
    problem = _input_noise()
    table = table_of(design_zoh(problem), quantize=False)
    ref, got = _both(problem, table, substeps, monkeypatch)
    _assert_close(ref, got)
    assert got.cost_var > 0


@pytest.mark.parametrize("order", [2, 4])
def test_operator_equals_numpy(order):
    """The step's map on compressed tensors, on random sparse nodes: the same sums in the
    same order."""
    rng = np.random.default_rng(order)
    d = 6
    s = tails._Sym(d, order)
    nodes = []
    for i in range(3):
        M = rng.standard_normal((d, d)) * (rng.random((d, d)) < 0.4)
        M[-1] = np.eye(d)[-1]
        nodes.append((rng.random(), M))
    ct = tails_kernel.CompiledTails(kernel.load_kernel(), 2, 1, 2, tails._Sym(d, 4),
                                    tails._Sym(d, 2), tails._Sym, tails.step_matrix)
    np.testing.assert_allclose(ct.operator(s, nodes), s.operator(nodes), rtol=1e-14,
                               atol=1e-15)


def test_without_a_compiler_the_numpy_loop_runs_with_a_warning(monkeypatch):
    problem = _input_noise()
    table = table_of(design_zoh(problem), quantize=False)
    monkeypatch.setenv("STOSPLINE_ORACLE_KERNEL", "numpy")
    ref = tails.evaluate_tails(problem, table, substeps=2, check=False)
    monkeypatch.setenv("STOSPLINE_ORACLE_KERNEL", "c")

    def missing():
        raise KernelBuildError("cannot build tails_kernel.c: no C compiler")
    monkeypatch.setattr(kernel, "load_kernel", missing)
    with pytest.warns(FallbackWarning, match="numpy loop"):
        got = tails.evaluate_tails(problem, table, substeps=2, check=False)
    assert got.J == ref.J and got.cost_var == ref.cost_var
