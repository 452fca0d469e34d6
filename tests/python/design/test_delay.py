"""A one-tick computation delay designed for (``[design] delay_ticks = 1``): the command
computed from the state at tick j is applied at tick j+1, the law acts on ``[x; a]`` (a: the
command being applied). Checked against independent evaluations: the exact oracle (which
never sees a Riccati solution) gives the cost the design predicts and meets its constraints;
no perturbation of the law, and not the ordinary law run a tick late (the delay fault), costs
less; the C tick kernel equals the numpy reference on the augmented tick data; ``delay_ticks
= 0`` is the ordinary design, bit for bit; bad values are refused naming the key."""
import sys
import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import stospline
from stospline.design.zoh import design_zoh
from stospline.errors import DesignError, ProblemError
from stospline.problem.faults import Faults
from stospline.problem.reader import parse_problem
from stospline.oracle.faults import evaluate_with_faults
from stospline.oracle.evaluate import evaluate_table
from stospline.table.format import table_of

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from support.problems import BASE, edit  # noqa: E402

# BASE with penalties only (no constraint): the delayed design is then optimal among all
# causal laws that see the state one tick late, the ordinary law under a delay among them.
PENALTY_ONLY = edit(BASE, ("constraint = { C = [[1, 0]], value = [1.0] }\n", ""),
                    ("constraint = { C = [[1, 0], [0, 1]], value = [0.0, 0.0] }",
                     "penalty = { C = [[1, 0], [0, 1]], target = [0.0, 0.0], weight = 5.0 }"))


@pytest.fixture(scope="module")
def robot100(robot_problem):
    return replace(robot_problem, tick_hz=100)


def _exact_table(problem, **kw):
    d = design_zoh(problem, **kw)
    return d, table_of(d, quantize=False)


@pytest.mark.parametrize("mode", ["stagewise", "joint"])
def test_predicted_cost_is_the_oracle_cost_and_constraints_hold(robot100, mode):
    d, t = _exact_table(robot100, mode=mode, delay_ticks=1)
    assert t.dims[0] == robot100.n + robot100.m and t.delay_ticks == 1
    mom = evaluate_table(robot100, t, path=False)
    assert mom.J == pytest.approx(d.J0, rel=1e-9)
    for k, kn in enumerate(robot100.knots):
        np.testing.assert_allclose(mom.knot_constraint[k], kn.constraint.value, atol=1e-9)


def test_the_ordinary_law_run_a_tick_late_costs_more_and_misses(robot100):
    """On the robot at 100 Hz: designing for the delay beats ignoring it (the ordinary table
    with the delay fault), in cost and in the constraints."""
    d1, t1 = _exact_table(robot100, delay_ticks=1)
    _, t0 = _exact_table(robot100)
    late = evaluate_with_faults(robot100, t0, Faults(delay_ticks=1))
    assert evaluate_table(robot100, t1, path=False).J < late.J - 0.02
    assert np.abs(late.knot_constraint[1] - robot100.knots[1].constraint.value).max() > 1e-3


def test_no_perturbation_of_the_delayed_law_costs_less():
    """Optimality against the oracle alone, on a penalty-only problem (no constraint to keep):
    the delayed law's cost is a minimum over its gains (random directions, both signs), and
    the ordinary law run a tick late (one point of that class: K' = [K, 0]) is no better."""
    p = parse_problem(tomllib.loads(PENALTY_ONLY))
    d, t = _exact_table(p, delay_ticks=1)
    J = evaluate_table(p, t, path=False).J
    assert J == pytest.approx(d.J0, rel=1e-9)
    rng = np.random.default_rng(7)
    for _ in range(4):
        dK, dk0 = rng.standard_normal(t.K.shape), rng.standard_normal(t.k0.shape)
        for eps in (1e-2, -1e-2):
            moved = replace(t, K=t.K + eps * dK, k0=t.k0 + eps * dk0)
            assert evaluate_table(p, moved, path=False).J > J
    _, t0 = _exact_table(p)
    late = evaluate_with_faults(p, t0, Faults(delay_ticks=1)).J
    assert J < late
    # The ordinary law with a zero column for the applied command, in the delayed loop, is
    # the ordinary law under the delay fault: two derivations of the same loop.
    K = np.concatenate([t0.K, np.zeros(t0.K.shape[:2] + (p.m,))], axis=2)
    embedded = replace(t, K=K, k0=t0.k0, L=np.zeros(t0.K.shape[:2] + (t.L.shape[2],)))
    assert evaluate_table(p, embedded, path=False).J == pytest.approx(late, rel=1e-12)


def test_the_c_kernel_runs_the_augmented_recursion(robot100):
    c = design_zoh(robot100, delay_ticks=1, kernel="c")
    ref = design_zoh(robot100, delay_ticks=1, kernel="numpy")
    assert c.J0 == pytest.approx(ref.J0, rel=1e-12)
    for a, b in zip(c.stages, ref.stages):
        np.testing.assert_allclose(a.K, b.K, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(a.L, b.L, rtol=1e-9, atol=1e-12)


def test_the_last_tick_outputs_the_safe_command():
    """Its command would be applied after the plan: the law outputs u_hold there."""
    p = parse_problem(tomllib.loads(edit(BASE, ("tick_hz = 10", "tick_hz = 10\nu_hold = 0.5"))))
    _, t = _exact_table(p, delay_ticks=1)
    assert not np.any(t.K[-1]) and not np.any(t.L[-1])
    np.testing.assert_array_equal(t.k0[-1], [-0.5])


def test_no_delay_is_the_ordinary_design_bit_for_bit(robot_problem):
    a, b = design_zoh(robot_problem), design_zoh(robot_problem, delay_ticks=0)
    assert a.J0 == b.J0 and b.delay_ticks == 0
    for sa, sb in zip(a.stages, b.stages):
        for name in ("K", "k0", "L", "Lambda", "lambda0"):
            np.testing.assert_array_equal(getattr(sa, name), getattr(sb, name))
    assert table_of(b).delay_ticks == 0 and b.summary_terms() == {}


def test_the_problem_file_key_is_read_written_back_and_used():
    p = parse_problem(tomllib.loads(BASE + "\n[design]\ndelay_ticks = 1\n"))
    assert p.options["delay_ticks"] == 1
    back = parse_problem(tomllib.loads(p.to_toml()))
    assert back.options == p.options
    d = stospline.design_problem(p)             # the file's delay, by default
    assert d.table.delay_ticks == 1 and d.table.dims[0] == 3
    assert d.implemented.J == pytest.approx(d.design.J0, rel=1e-6)
    s = stospline.design_summary(d)
    assert s["delay_ticks"] == 1 and s["controller_state"] == ["x0", "x1", "u0_applied"]
    assert stospline.design_problem(p, delay_ticks=0).table.dims[0] == 2


@pytest.mark.parametrize("value", ["2", "-1", "true", "1.0", '"1"'])
def test_bad_values_are_refused_naming_the_key(value):
    with pytest.raises(ProblemError) as exc:
        parse_problem(tomllib.loads(BASE + f"\n[design]\ndelay_ticks = {value}\n"))
    assert exc.value.field == "design.delay_ticks" and "0 or 1" in exc.value.reason


def test_unsupported_designs_are_refused_naming_the_key(robot_problem):
    with pytest.raises(DesignError) as exc:
        stospline.design_problem(robot_problem, discretization="continuous", delay_ticks=1)
    assert exc.value.field == "design.delay_ticks"
    with pytest.raises(DesignError) as exc:
        design_zoh(robot_problem, delay_ticks=2)
    assert exc.value.field == "design.delay_ticks"
    band = parse_problem(tomllib.loads(edit(
        BASE, ("constraint = { C = [[1, 0]], value = [1.0] }",
               "constraint = { C = [[1, 0]], lower = [0.9], upper = [1.1] }"))))
    with pytest.raises(DesignError) as exc:
        stospline.design_problem(band, mode="joint", delay_ticks=1)
    assert exc.value.field == "design.delay_ticks"


@pytest.mark.parametrize("where", ["file", "option"])
def test_the_command_line_refuses_a_bad_delay_in_one_line(tmp_path, capsys, where):
    from stospline.cli import main
    f = tmp_path / "di.toml"
    f.write_text(BASE + ("\n[design]\ndelay_ticks = 3\n" if where == "file" else ""))
    args = ["design", str(f)] + (["--delay-ticks", "3"] if where == "option" else [])
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    key = "design.delay_ticks" if where == "file" else "--delay-ticks"
    assert len(err) == 1 and key in err[0] and "0 or 1" in err[0]
