"""Every edit of the hostile generator's parameters family (`hostile.PARAMETER_EDITS`) on every
base problem: the valid parameter is read (on a problem with bands too), every broken one is
refused with one line naming a key under ``parameters``; and through the CLI, status 2 and
nothing on disk."""
import copy

import pytest
from hostile import BASES, PARAMETER_EDITS, parameters_doc, to_toml

from stospline.cli import main
from stospline.errors import ProblemError
from stospline.problem.reader import parse_problem


@pytest.mark.parametrize("base", sorted(BASES))
@pytest.mark.parametrize("edit", sorted(PARAMETER_EDITS))
def test_each_parameter_edit_is_read_or_refused_by_its_key(base, edit):
    doc = parameters_doc(copy.deepcopy(BASES[base]), edit)
    if edit == "valid":
        (par,) = parse_problem(doc).parameters
        assert (par.name, par.nominal) == ("p0", doc["x0"][0])
        return
    with pytest.raises(ProblemError) as err:
        parse_problem(doc)
    assert err.value.field.startswith("parameters"), str(err.value)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("edit", ["range_misses_nominal", "sets_band_limit", "set_twice"])
def test_the_cli_refuses_a_broken_parameter_in_one_line(edit, tmp_path, capsys):
    path = tmp_path / "p.toml"
    path.write_text(to_toml(parameters_doc(copy.deepcopy(BASES["noisy"]), edit)))
    out = tmp_path / "out"
    assert main(["design", str(path), "--out", str(out)]) == 2
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert len(err.splitlines()) == 1 and ": parameters[0]" in err, err
    assert captured.out == ""
    assert not out.exists()
