"""Every bad problem file gets a clear error: the CLI exits 2, names the field and the reason on
stderr, and writes nothing into the output directory.

Each case edits a small valid problem (a noisy double integrator, two knots) in one place and
states the field path and a substring of the reason it must produce. The same file is also
checked exactly: the message is ``stospline: error in FILE: FIELD: REASON``.

Finite escape
-------------
`design_continuous` (and `design_zoh`, per tick) has a branch for a Riccati solution that does
not stay bounded. A true finite escape cannot be reached from a file the parser accepts: the
parser enforces R > 0 and ``[[Q, S], [S', R]] >= 0`` (the paper's condition (3)), and every
terminal value and jump adds a positive semidefinite term (penalty weights are >= 0, and
``N W^-1 N'`` with W > 0, which `stospline.design.stage_values.check_latch` enforces). Then on each stage ``P(t)`` is the
optimal cost-to-go of a stochastic LQ problem with a nonnegative running cost, so
``0 <= P(t) <= P_F(t)`` for any fixed feedback ``u = -F x``, where ``P_F`` solves the
*linear* equation
``-dP_F/dt = A_F' P_F + P_F A_F + Pi(P_F) + [I; -F]' [[Q, S], [S', R]] [I; -F]``
(``A_F = A - B F``), whose solution exists on every finite interval (over finitely many ticks
the same bound holds for the exact sampled-data recursion). A positive noise term or a large A
only makes P grow exponentially, never escape in finite time. What *is* reachable is
exponential growth beyond the floating-point range: a mode that the input cannot stabilise
(here an unstable state that B does not reach, growing like exp(800 t)) over a long enough
stage. The ``riccati_overflow`` cases below drive the branch that way, with either design.
"""
import subprocess
import sys

import pytest

from stospline.cli import main

from support.problems import BASE, STAGES, edit

T1 = "[[knots]]\nt = 1.0\n"
T2 = "[[knots]]\nt = 2.0\n"
PEN = "penalty = { C = [[1, 0]], target = [1.0], weight = 2.0 }"
CON0 = "constraint = { C = [[1, 0]], value = [1.0] }"
CON1 = "constraint = { C = [[1, 0], [0, 1]], value = [0.0, 0.0] }"
NOISE = "noise = [{ state = 1, G = [[0], [0.3]] }]"
STAGE0 = "[[stages]]\ncost = { R = [[2]] }\n"
STAGE1 = "dynamics = { A = [[0, 1], [0, -1]] }"

# Design-level cases run with each discretization the CLI offers.
DISC = [("", ()), ("_continuous", ("--discretization", "continuous"))]

# (id, problem text, field, substring of the reason[, extra CLI arguments...])
CASES = [
    # --- the file as a whole -------------------------------------------------------------
    ("empty_file", "", "<file>", "is empty"),
    ("toml_syntax", edit(BASE, ("tick_hz = 10", "tick_hz = = 10")), "<file>",
     "not valid TOML"),
    ("missing_tick_hz", edit(BASE, ("tick_hz = 10\n", "")), "tick_hz", "is required"),
    ("unknown_top_level_key", edit(BASE, ("tick_hz = 10", "tick_hz = 10\ntickhz = 10")),
     "tickhz", "did you mean 'tick_hz'"),
    ("name_not_c_identifier", edit(BASE, ('name = "di"', 'name = "double-integrator"')),
     "name", "C identifier"),
    ("name_c_keyword", edit(BASE, ('name = "di"', 'name = "double"')), "name", "C keyword"),
    ("name_reserved", edit(BASE, ('name = "di"', 'name = "__di"')), "name", "reserved"),
    # --- knot times and the tick rate ----------------------------------------------------
    ("knot_times_not_increasing", edit(BASE, (T2, "[[knots]]\nt = 0.5\n")), "knots[1].t",
     "must be later than knots[0].t"),
    ("knot_at_t0", edit(BASE, (T1, "[[knots]]\nt = 0.0\n")), "knots[0].t",
     "must be later than t0"),
    ("tick_does_not_divide_stage", edit(BASE, (T1, "[[knots]]\nt = 1.05\n")), "knots[0].t",
     "whole number of ticks"),
    ("tick_hz_zero", edit(BASE, ("tick_hz = 10", "tick_hz = 0")), "tick_hz",
     "an integer in 1.."),
    ("tick_hz_float", edit(BASE, ("tick_hz = 10", "tick_hz = 10.0")), "tick_hz",
     "an integer in 1.."),
    # --- dimensions ----------------------------------------------------------------------
    ("A_not_square", edit(BASE, ("A = [[0, 1], [0, 0]]", "A = [[0, 1, 0], [0, 0, 1]]")),
     "dynamics.A", "must be square"),
    ("x0_vs_A", edit(BASE, ("x0 = [0.0, 0.0]", "x0 = [0.0, 0.0, 0.0]")), "dynamics.A",
     "x0 has 3 entries"),
    ("B_rows", edit(BASE, ("B = [[0], [1]]", "B = [[0], [1], [0]]")), "dynamics.B",
     "has 3 rows, expected 2"),
    ("noise_G_rows", edit(BASE, ("G = [[0], [0.3]]", "G = [[0], [0.3], [0]]")),
     "dynamics.noise[0].G", "has 3 rows, expected 2"),
    ("noise_G_widths_differ", edit(BASE, (NOISE, "noise = [{ state = 0, G = [[0], [0.1]] }, "
                                                 "{ state = 1, G = [[0, 0], [0.3, 0]] }]")),
     "dynamics.noise[1].G", "one column per Brownian component"),
    ("penalty_C_width", edit(BASE, ("C = [[1, 0]], target", "C = [[1, 0, 0]], target")),
     "knots[0].penalty.C", "has 3 columns, expected 2"),
    ("constraint_C_width", edit(BASE, (CON1, "constraint = { C = [[1], [0]], "
                                             "value = [0.0, 0.0] }")),
     "knots[1].constraint.C", "has 1 columns, expected 2"),
    ("penalty_target_length", edit(BASE, ("target = [1.0]", "target = [1.0, 2.0]")),
     "knots[0].penalty.target", "has length 2, expected 1"),
    ("constraint_value_length", edit(BASE, ("value = [0.0, 0.0]", "value = [0.0]")),
     "knots[1].constraint.value", "has length 1, expected 2"),
    # --- numbers -------------------------------------------------------------------------
    ("nan_in_A", edit(BASE, ("A = [[0, 1], [0, 0]]", "A = [[0, nan], [0, 0]]")),
     "dynamics.A[0][1]", "must be finite"),
    ("inf_in_target", edit(BASE, ("target = [1.0]", "target = [inf]")),
     "knots[0].penalty.target[0]", "must be finite"),
    ("string_for_number", edit(BASE, ("t0 = 0.0", 't0 = "0"')), "t0",
     "must be a number, got a string"),
    ("bool_for_number", edit(BASE, ("weight = 2.0", "weight = true")),
     "knots[0].penalty.weight", "must be a number, got a boolean"),
    ("negative_weight", edit(BASE, ("weight = 2.0", "weight = -2.0")),
     "knots[0].penalty.weight", "must be >= 0"),
    # --- cost matrices -------------------------------------------------------------------
    ("R_not_symmetric", edit(BASE, ("B = [[0], [1]]", "B = [[0, 0], [1, 1]]"),
                             ("R = [[1]]", "R = [[1, 0.5], [0, 1]]")),
     "cost.R", "must be symmetric"),
    ("R_not_positive_definite", edit(BASE, ("R = [[1]]", "R = [[0]]")), "cost.R",
     "must be positive definite"),
    ("Q_not_symmetric", edit(BASE, ("Q = [[0, 0], [0, 0]]", "Q = [[1, 1], [0, 1]]")),
     "cost.Q", "must be symmetric"),
    ("condition_3_not_psd", edit(BASE, ("Q = [[0, 0], [0, 0]]",
                                        "Q = [[1, 0], [0, 0]]\nS = [[2], [0]]")),
     "cost", "condition (3)"),
    # --- unknown and missing keys --------------------------------------------------------
    ("unknown_key_dynamics", edit(BASE, (NOISE, NOISE.replace("noise", "noize"))),
     "dynamics.noize", "did you mean 'noise'"),
    ("unknown_key_cost", edit(BASE, ("R = [[1]]", "R = [[1]]\nrh0 = 1.0")), "cost.rh0",
     "did you mean 'rho'"),
    ("unknown_key_knots", edit(BASE, (PEN, PEN.replace("penalty", "penality"))),
     "knots[0].penality", "did you mean 'penalty'"),
    ("unknown_key_penalty", edit(BASE, ("weight = 2.0", "weigth = 2.0")),
     "knots[0].penalty.weigth", "did you mean 'weight'"),
    ("unknown_key_constraint", edit(BASE, (CON0, CON0.replace("value", "values"))),
     "knots[0].constraint.values", "did you mean 'value'"),
    ("unknown_key_stages", edit(STAGES, (STAGE0, "[[stages]]\ncosts = { R = [[2]] }\n")),
     "stages[0].costs", "did you mean 'cost'"),
    ("stage_key_outside_its_table", edit(STAGES, (STAGE0, "[[stages]]\nR = [[2]]\n")),
     "stages[0].R", "goes in its cost table"),
    ("missing_R", edit(BASE, ("R = [[1]]\n", "")), "cost.R", "is required"),
    ("missing_knot_time", edit(BASE, (T1, "[[knots]]\n")), "knots[0].t", "is required"),
    # --- noise ---------------------------------------------------------------------------
    ("noise_state_out_of_range", edit(BASE, ("state = 1", "state = 2")),
     "dynamics.noise[0].state", "an integer in 0..1"),
    ("noise_state_duplicated", edit(BASE, (NOISE, "noise = [{ state = 1, G = [[0], [0.3]] }, "
                                                  "{ state = 1, G = [[0], [0.1]] }]")),
     "dynamics.noise[1].state", "state 1 already has a noise entry"),
    # --- per-stage data ------------------------------------------------------------------
    ("stages_count", edit(STAGES, ("[[stages]]\n" + STAGE1, "")), "stages",
     "exactly one [[stages]] entry per knot"),
    ("stage_A_size", edit(STAGES, (STAGE1, "dynamics = { A = [[0, 1, 0], [0, 0, 1], "
                                           "[0, 0, 0]] }")),
     "stages[1].dynamics.A", "x0 has 2 entries"),
    ("stage_R_not_positive_definite", edit(STAGES, ("R = [[2]]", "R = [[-1]]")),
     "stages[0].cost.R", "must be positive definite"),
    ("stage_condition_3", edit(STAGES, ("R = [[2]]", "S = [[3], [0]]")), "stages[0].cost",
     "here Q is cost.Q, S is stages[0].cost.S, R is cost.R"),
    ("stage_inputs_m_differ", edit(STAGES, (STAGE1, "dynamics = { B = [[0, 0], [1, 1]] }")),
     "stages[1].dynamics.B", "same number of inputs m"),
    ("stage_noise_mz_differs", edit(STAGES, (STAGE1, "dynamics = { noise = [{ state = 0, "
                                                     "G = [[0, 0], [0.1, 0.2]] }] }")),
     "stages[1].dynamics.noise[0].G", "same number of Brownian components"),
    # --- actuator limits (top-level u_min / u_max) --------------------------------------
    ("limits_wrong_length", edit(BASE, ("tick_hz = 10", "tick_hz = 10\nu_min = [-1.0, -1.0]")),
     "u_min", "has length 2, expected 1 (m, one entry per input"),
    ("limits_empty_array", edit(BASE, ("tick_hz = 10", "tick_hz = 10\nu_max = []")),
     "u_max", "got an empty array"),
    ("limits_nan", edit(BASE, ("tick_hz = 10", "tick_hz = 10\nu_min = [nan]")),
     "u_min[0]", "must be finite"),
    ("limits_inf", edit(BASE, ("tick_hz = 10", "tick_hz = 10\nu_max = [inf]")),
     "u_max[0]", "omit u_max for no limit on any input"),
    ("limits_scalar_minus_inf", edit(BASE, ("tick_hz = 10", "tick_hz = 10\nu_min = -inf")),
     "u_min", "must be finite"),
    ("limits_beyond_float32", edit(BASE, ("tick_hz = 10", "tick_hz = 10\nu_max = 1e39")),
     "u_max", "within the float32 range of the gain table"),
    ("limits_min_above_max", edit(BASE, ("tick_hz = 10",
                                         "tick_hz = 10\nu_min = [1.0]\nu_max = [0.5]")),
     "u_min[0]", "input 0: u_min = 1 > u_max = 0.5; the range of commands is empty"),
    ("limits_min_positive", edit(BASE, ("tick_hz = 10", "tick_hz = 10\nu_min = 0.5")),
     "u_min", "is 0.5, so 0 is not a valid command: give u_hold, the safe command within the "
              "limits"),
    ("limits_max_negative", edit(BASE, ("tick_hz = 10", "tick_hz = 10\nu_max = [-0.5]")),
     "u_max[0]", "input 0: is -0.5, so 0 is not a valid command: give u_hold"),
    ("hold_below_min", edit(BASE, ("tick_hz = 10", "tick_hz = 10\nu_min = 0.5\nu_hold = 0.25")),
     "u_hold", "0.25 is < u_min = 0.5; the firmware commands the safe value u_hold"),
    ("hold_above_max", edit(BASE, ("tick_hz = 10", "tick_hz = 10\nu_max = [2]\nu_hold = [3]")),
     "u_hold[0]", "input 0: 3 is > u_max = 2"),
    ("hold_nan", edit(BASE, ("tick_hz = 10", "tick_hz = 10\nu_hold = nan")),
     "u_hold", "must be finite"),
    ("hold_length", edit(BASE, ("tick_hz = 10", "tick_hz = 10\nu_hold = [1, 2]")),
     "u_hold", "has length 2, expected 1"),
    ("hold_huge", edit(BASE, ("tick_hz = 10", "tick_hz = 10\nu_hold = 1e39")),
     "u_hold", "within the float32 range of the gain table (|value| <= 3.4028235e+38), got 1e+39"),
    ("limits_string", edit(BASE, ("tick_hz = 10", 'tick_hz = 10\nu_min = "-1"')),
     "u_min", "must be a number (the same limit for every input) or an array with one "
              "number per input (m = 1), got a string"),
    ("limits_bool_entry", edit(BASE, ("tick_hz = 10", "tick_hz = 10\nu_max = [true]")),
     "u_max[0]", "must be a number, got a boolean"),
    ("limits_nested_array", edit(BASE, ("tick_hz = 10", "tick_hz = 10\nu_max = [[1.0]]")),
     "u_max[0]", "must be a number, got an array"),
    ("limits_after_a_table", edit(BASE, ("R = [[1]]", "R = [[1]]\nu_max = [1.0]")),
     "cost.u_max", "top-level keys go before the first [table] header"),
    # --- infeasible designs: DesignError from stage_values.check_latch and Riccati checks,
    # through the default exact sampled-data design and through the continuous one ---------
    ("constraint_rows_dependent", edit(BASE, (CON1, "constraint = { C = [[1, 0], [2, 0]], "
                                                    "value = [0.0, 0.0] }")),
     "knots[1].constraint.C", "rows [0, 1] are linearly dependent"),
    ("constraint_more_rows_than_states", edit(BASE, (CON1, "constraint = { C = [[1, 0], "
                                                           "[0, 1], [1, 1]], "
                                                           "value = [0.0, 0.0, 0.0] }")),
     "knots[1].constraint.C", "(3 rows but only n = 2 states)"),
    ("constraint_zero_row", edit(BASE, (CON1, "constraint = { C = [[1, 0], [0, 0]], "
                                              "value = [0.0, 0.0] }")),
     "knots[1].constraint.C", "row 1 is zero"),
    *[(f"constraint_B_zero_on_stage{tag}",
       edit(STAGES, (STAGE0, "[[stages]]\ndynamics = { B = [[0], [0]] }\n")),
       "knots[0].constraint.C", "the input has no effect", *args) for tag, args in DISC],
    *[(f"constraint_direction_unreachable{tag}",
       edit(STAGES, (STAGE1, "dynamics = { A = [[0, 0], [0, 0]] }")),
       "knots[1].constraint.C", "cannot steer the output combination +1*row 0", *args)
      for tag, args in DISC],
    *[(f"riccati_overflow{tag}",
       edit(STAGES, (STAGE1, "dynamics = { A = [[400, 0], [0, 0]] }"),
            (CON1, "penalty = { C = [[1, 0]], target = [0.0], weight = 1.0 }")),
       "knots[1].t", "has no bounded solution", *args) for tag, args in DISC],
]


@pytest.mark.parametrize("text, field, reason, args", [(*c[1:4], c[4:]) for c in CASES],
                         ids=[c[0] for c in CASES])
def test_bad_input_exits_2_and_writes_nothing(tmp_path, capsys, text, field, reason, args):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    out = tmp_path / "out"
    assert main(["design", str(path), "--out", str(out), *args]) == 2
    err = capsys.readouterr().err
    prefix = f"stospline: error in {path}: "
    assert err.startswith(prefix), err
    got_field, _, got_reason = err[len(prefix):].partition(": ")
    assert got_field == field, err
    assert reason in got_reason, err
    assert not out.exists() or not any(out.iterdir())


def test_case_ids_are_unique_and_many():
    ids = [c[0] for c in CASES]
    assert len(set(ids)) == len(ids) >= 30


@pytest.mark.parametrize("text", [BASE, STAGES], ids=["base", "stages"])
def test_base_problems_are_valid(tmp_path, capsys, text):
    """The cases differ from a valid problem by their edit: the base designs and writes."""
    path = tmp_path / "ok.toml"
    path.write_text(text)
    assert main(["design", str(path), "--out", str(tmp_path / "out")]) == 0
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["di.c", "di.h", "di.json"]


def test_console_script_exit_status(tmp_path):
    """The installed entry point, not only `main`, exits 2 with the message on stderr."""
    path = tmp_path / "bad.toml"
    path.write_text(edit(BASE, ("R = [[1]]", "R = [[0]]")))
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "stospline.cli", "design", str(path),
                        "--out", str(out)], capture_output=True, text=True)
    assert r.returncode == 2
    assert "cost.R: must be positive definite" in r.stderr
    assert "Traceback" not in r.stderr and r.stdout == ""
    assert not out.exists()
