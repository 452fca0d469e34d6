"""``--substeps auto`` on a [plant] model (`nonlinear.simulate.choose_model_substeps`): on the
unicycle the count is the first (1, 2, 4, ...) whose pilot bound on the scheme's bias is below
the tolerance in Monte Carlo standard errors of the planned run; a tighter tolerance or more
paths need more substeps; no count up to the cap is refused naming --substeps."""
import pytest
from conftest import EXAMPLES

from stospline.errors import ProblemError
from stospline.nonlinear.iterate import load_plant_problem
from stospline.nonlinear.simulate import choose_model_substeps, plant_simulation
from stospline.pipeline import design_problem


@pytest.fixture(scope="module")
def unicycle():
    problem, fit = load_plant_problem(EXAMPLES / "nonlinear" / "robot_unicycle.toml")
    return design_problem(problem), fit.model


def test_auto_takes_the_first_count_below_the_tolerance(unicycle):
    d, model = unicycle
    loose = choose_model_substeps(d, model, paths=40, seed=1)
    tight = choose_model_substeps(d, model, paths=40, seed=1, tolerance=0.05)
    for c in (loose, tight):
        counts = [n for n, _ in c.tried]
        assert counts == [2 ** i for i in range(len(counts))] and counts[-1] == c.substeps
        assert c.tried[-1][1] <= c.tolerance
        assert all(r > c.tolerance for _, r in c.tried[:-1])
    assert loose.substeps == 1 and tight.substeps > 1
    # The bound falls as the scheme refines.
    assert tight.tried[-1][1] < tight.tried[0][1]
    # The run uses the count chosen, and the summary says how it was chosen.
    s = plant_simulation(d, model, paths=40, seed=1, substeps="auto")
    assert s["plant"]["substeps"] == loose.substeps
    assert s["plant"]["tried"] == [{"substeps": n, "bias_over_stderr": pytest.approx(r)}
                                   for n, r in loose.tried]


def test_no_count_up_to_the_cap_is_refused(unicycle):
    d, model = unicycle
    with pytest.raises(ProblemError) as err:
        choose_model_substeps(d, model, paths=40, seed=1, tolerance=0.05, limit=1)
    assert err.value.field == "--substeps"
    assert "no substep count up to 1" in err.value.reason
