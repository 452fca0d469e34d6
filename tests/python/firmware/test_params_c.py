"""Runtime parameters in the firmware (stsp_params.h): the expected values of the C test
(tests/c/params_expected.h) are the float32 specification's (`stospline.table.params_spec`),
and the specification is the parametric law `ParametricTable.at(theta)` to float32 rounding."""
import sys

import numpy as np

from conftest import EXAMPLES, REPO
from stospline import design_problem, load_problem
from stospline.oracle.parametric import design_parametric
from stospline.table.params_spec import ParamSpec
from stospline.table.parametric_c import flash_columns

sys.path.insert(0, str(REPO / "tests" / "c"))
import params_reference  # noqa: E402


def test_expected_header_is_the_specification():
    assert (REPO / "tests/c/params_expected.h").read_text() == params_reference.expected(), \
        "regenerate tests/c/params_expected.h with tests/c/params_reference.py"


def test_specification_is_the_parametric_law():
    """At a theta in the range, the float32 commands of the specification equal the law of
    the double-precision table at theta within a few float32 roundings of its terms."""
    problem = load_problem(EXAMPLES / "robot_goal.toml")
    table = design_problem(problem).table
    pt = design_parametric(problem).table
    theta = np.array(params_reference.THETA_A)
    spec = ParamSpec(table, flash_columns(pt), 1)
    spec.set(theta)
    exact = pt.at(theta)
    n, m, nl = table.dims
    v = np.zeros(nl)
    worst = 0.0
    for j in range(table.n_ticks):
        x = params_reference.params_state(j, n)
        u = spec.step(j, x)[0].astype(float)
        k = table.stage_of_tick(j)
        if j == int(table.stage_start[k]) and (k == 0 or table.stage_n_latch[k] > 0):
            v = np.where(np.arange(nl) < table.stage_n_latch[k],
                         exact.lambda0[k] + exact.Lambda[k] @ x[0], 0.0)
        terms = (np.abs(exact.k0[j]) + np.abs(exact.K[j]) @ np.abs(x[0])
                 + np.abs(exact.L[j]) @ np.abs(v))
        want = np.clip(-(exact.k0[j] + exact.K[j] @ x[0] + exact.L[j] @ v),
                       table.u_min, table.u_max)
        worst = max(worst, float(np.max(np.abs(u - want) / (terms + 1e-30))))
    # float32 storage of every entry and one rounding per operation: O(10) units of 2^-24
    assert worst < 64 * 2.0 ** -24, worst
