"""Every edit of the hostile generator's measurement family (`hostile.MEASUREMENT_EDITS`) on
every base problem: the valid sensor is read back as written, every broken one is refused with
one line naming a key of [measurement]; and through the CLI, status 2 and nothing on disk."""
import copy

import pytest
from hostile import BASES, MEASUREMENT_EDITS, _sensor, to_toml

from stospline.cli import main
from stospline.errors import ProblemError
from stospline.problem.reader import parse_problem


def _doc(base: str, edit: str) -> dict:
    doc = copy.deepcopy(BASES[base])
    n = len(doc["x0"])
    sensor = _sensor(n)
    MEASUREMENT_EDITS[edit](sensor, n)
    doc["measurement"] = sensor.get("__replace__", sensor)
    return doc


@pytest.mark.parametrize("base", sorted(BASES))
@pytest.mark.parametrize("edit", sorted(MEASUREMENT_EDITS))
def test_each_measurement_edit_is_read_or_refused_by_its_key(base, edit):
    doc = _doc(base, edit)
    if edit == "valid":
        meas = parse_problem(doc).measurement
        assert meas.as_dict() == doc["measurement"]
        return
    with pytest.raises(ProblemError) as err:
        parse_problem(doc)
    assert err.value.field.startswith("measurement"), str(err.value)
    assert "\n" not in str(err.value)


def test_no_measurement_table_is_the_full_state_loop():
    assert parse_problem(copy.deepcopy(BASES["noisy"])).measurement is None


@pytest.mark.parametrize("edit", ["V_not_psd", "every_zero", "noise_state"])
def test_the_cli_refuses_a_broken_sensor_in_one_line(edit, tmp_path, capsys):
    path = tmp_path / "p.toml"
    path.write_text(to_toml(_doc("noisy", edit)))
    out = tmp_path / "out"
    assert main(["design", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "measurement." in err, err
    assert not out.exists() or not any(out.iterdir())
