"""Actuator limits from the problem file (top-level ``u_min``/``u_max``): parsed, carried into
the gain table, the generated C and the JSON summaries, and enforced by the compiled firmware in
``stospline simulate``, which reports how often it saturated. Bad values: test_problem_errors.py.
"""
import json
import tomllib

import numpy as np
import pytest

from stospline.cli import main
from stospline.table.codegen import generate_c
from stospline.design.zoh import design_zoh
from stospline.pipeline import design_problem, design_summary
from stospline.problem import load_problem, parse_problem
from stospline.table.format import F32_MAX, table_of
from stospline.design.continuous import design_continuous

from support.problems import BASE, edit

# Two inputs, so per-input vectors and the scalar broadcast can be told apart.
TWO_INPUTS = edit(BASE, ("B = [[0], [1]]", "B = [[0, 0], [1, 0.5]]"),
                  ("R = [[1]]", "R = [[1, 0], [0, 1]]"))


def with_limits(text: str, limits: str) -> str:
    return edit(text, ("tick_hz = 10", "tick_hz = 10\n" + limits))


def parse(text: str):
    return parse_problem(tomllib.loads(text))


def test_no_limits_by_default():
    p = parse(BASE)
    assert p.u_min is None and p.u_max is None
    d = design_problem(p)
    assert not d.table.limited
    np.testing.assert_array_equal(d.table.u_min, np.float32([-F32_MAX]))
    assert "actuator_limits" not in design_summary(d)


@pytest.mark.parametrize("limits, lo, hi", [
    ("u_min = [-1.5, -0.25]\nu_max = [2.0, 0.1]", [-1.5, -0.25], [2.0, 0.1]),
    ("u_min = -3\nu_max = 4.5", [-3.0, -3.0], [4.5, 4.5]),          # scalar broadcast
    ("u_max = [1.0, 0]", None, [1.0, 0.0]),                         # one side only
    ("u_min = 0", [0.0, 0.0], None),
    ("u_min = [-3.4028235e38, -1]", [-3.4028235e38, -1.0], None),  # FLT_MAX: unlimited
])
def test_limits_parse(limits, lo, hi):
    p = parse(with_limits(TWO_INPUTS, limits))
    for got, want in ((p.u_min, lo), (p.u_max, hi)):
        if want is None:
            assert got is None
        else:
            np.testing.assert_array_equal(got, np.array(want))
    assert p.without_noise().u_min is p.u_min and p.without_noise().u_max is p.u_max


def test_every_table_of_the_problem_carries_its_limits():
    p = parse(with_limits(TWO_INPUTS, "u_min = [-1.5, -0.25]\nu_max = 0.1"))
    lo, hi = np.float32([-1.5, -0.25]), np.float32([0.1, 0.1])
    tables = [table_of(design_zoh(p)), table_of(design_zoh(p), quantize=False),
              table_of(design_continuous(p)), design_problem(p).table,
              design_problem(p, discretization="continuous", mode="joint").table]
    for t in tables:
        assert t.limited
        np.testing.assert_array_equal(t.u_min, lo)
        np.testing.assert_array_equal(t.u_max, hi)
    # One side given: the other stays unlimited.
    t = design_problem(parse(with_limits(TWO_INPUTS, "u_max = 0.1"))).table
    np.testing.assert_array_equal(t.u_min, np.float32([-F32_MAX, -F32_MAX]))
    np.testing.assert_array_equal(t.u_max, hi)
    # 3.4028235e38 rounds to FLT_MAX, the table's "unlimited".
    t = design_problem(parse(with_limits(TWO_INPUTS, "u_min = [-3.4028235e38, -1]"))).table
    np.testing.assert_array_equal(t.u_min, np.float32([-F32_MAX, -1.0]))


def test_design_writes_limits_into_c_and_json(tmp_path, capsys):
    path = tmp_path / "di.toml"
    path.write_text(with_limits(TWO_INPUTS, "u_min = [-1.5, -0.25]\nu_max = 0.1"))
    out = tmp_path / "gains"
    assert main(["design", str(path), "--out", str(out)]) == 0
    src = (out / "di.c").read_text()
    assert "di_u_min[2] = {\n    -1.5e+00f, -2.5e-01f,\n};" in src
    assert "di_u_max[2] = {\n    1.0e-01f, 1.0e-01f,\n};" in src
    d = design_problem(load_problem(path))
    assert src == generate_c(d.table, source_name="di.toml")[1]
    s = json.loads((out / "di.json").read_text())
    lim = s["actuator_limits"]
    assert lim["u_min"] == [-1.5, -0.25]
    assert lim["u_max"] == [pytest.approx(0.1, rel=1e-7)] * 2     # float32 0.1, as stored
    assert "ignores the limits" in lim["note"]
    one_side = path.with_name("one.toml")
    one_side.write_text(with_limits(TWO_INPUTS, "u_max = 2"))
    capsys.readouterr()
    assert main(["design", str(one_side), "--json"]) == 0
    lim = json.loads(capsys.readouterr().out)["actuator_limits"]
    assert lim["u_min"] is None and lim["u_max"] == [2.0, 2.0]


def simulate_json(tmp_path, capsys, text: str, name: str, *args) -> tuple[dict, str]:
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    capsys.readouterr()
    assert main(["simulate", str(path), "--paths", "400", "--seed", "5", "--json", *args]) == 0
    cap = capsys.readouterr()
    return json.loads(cap.out), cap.err


def test_tight_limits_saturate_and_the_c_commands_stay_within(tmp_path, capsys):
    """The unlimited law needs |u| up to ~6 on the double integrator; limits of -2/+2.5 clamp
    on most ticks. The compiled controller's commands stay within the float32 limits over all
    paths and ticks, and the run warns that the oracle's numbers assume no saturation."""
    free, free_err = simulate_json(tmp_path, capsys, BASE, "free")
    assert free_err == ""
    assert not free["saturation"]["limited"] and free["saturation"]["tick_fraction"] == 0
    assert free["saturation"]["u_high"][0] > 2.5 and free["saturation"]["u_low"][0] < -2.0

    s, err = simulate_json(tmp_path, capsys, with_limits(BASE, "u_min = -2\nu_max = [2.5]"),
                           "tight")
    sat = s["saturation"]
    assert sat["limited"]
    assert 0.1 < sat["tick_fraction"] < 1 and sat["path_fraction"] == 1.0
    assert -2.0 <= sat["u_low"][0] and sat["u_high"][0] <= 2.5
    assert sat["u_low"][0] == -2.0 and sat["u_high"][0] == 2.5      # the clamp was reached
    assert s["worst_status"] == 0                                    # a warning, not an error
    assert "warning: the controller saturated (STSP_WARN_SATURATED)" in err
    assert "assume no saturation" in err
    # The oracle's prediction no longer describes the clipped controller.
    assert abs(s["cost"]["z"]) > 10

    # The text report says the same.
    path = tmp_path / "tight.toml"
    assert main(["simulate", str(path), "--paths", "50", "--seed", "5"]) == 0
    cap = capsys.readouterr()
    assert "actuator limits: saturated on" in cap.out and "assume no saturation" in cap.err


def test_loose_limits_reproduce_the_unlimited_numbers_exactly(tmp_path, capsys):
    """Limits never reached: the firmware's commands are bit-for-bit the unlimited ones, so
    every Monte Carlo number is identical, and there is no warning."""
    free, _ = simulate_json(tmp_path, capsys, BASE, "free")
    loose, err = simulate_json(tmp_path, capsys, with_limits(BASE, "u_min = -1e6\nu_max = 1e6"),
                               "loose")
    assert err == ""
    assert loose["saturation"]["limited"] and loose["saturation"]["tick_fraction"] == 0
    assert loose.pop("actuator_limits")["u_max"] == [1e6]
    free_sat, loose_sat = free.pop("saturation"), loose.pop("saturation")
    assert free_sat["u_low"] == loose_sat["u_low"] and free_sat["u_high"] == loose_sat["u_high"]
    assert loose == free


def test_safe_command_u_hold_from_the_file_to_the_firmware(capsys):
    """``u_hold``: a minimum command (u_min > 0, a thrust that must never be cut) is allowed
    once the safe command is given; it reaches the table, the C text, the summary and the
    written-back file, and the compiled controller commands it on a refused step."""
    text = with_limits(TWO_INPUTS, "u_min = [0.5, -1]\nu_max = [9, 1]\nu_hold = [4.9, 0]")
    p = parse(text)
    np.testing.assert_array_equal(p.u_hold, [4.9, 0.0])
    assert parse(p.to_toml()).u_hold.tolist() == [4.9, 0.0]
    d = design_problem(p)
    np.testing.assert_array_equal(d.table.u_hold, np.float32([4.9, 0.0]))
    _, source = generate_c(d.table)
    assert f"static const stsp_f32_t {p.name}_u_hold[2] = {{" in source
    assert design_summary(d)["actuator_limits"]["u_hold"] == pytest.approx([4.9, 0.0])
    from stospline.harness.controller import STATUS, build_controller
    step = build_controller(d.table).stepper(1)
    U, status = step(0, np.float32([[np.nan, 0.0]]))
    assert status[0] == STATUS["ERR_NONFINITE_STATE"]
    np.testing.assert_array_equal(U[0], np.float32([4.9, 0.0]))
    # Without u_hold the same limits are refused: 0 is not a valid command for input 0.
    with pytest.raises(Exception, match="give u_hold"):
        parse(with_limits(TWO_INPUTS, "u_min = [0.5, -1]\nu_max = [9, 1]"))
