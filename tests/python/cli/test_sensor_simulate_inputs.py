"""`simulate` of a problem with [measurement] (the sensor loop): every case of the hostile
generator's sensor family (`hostile.SENSOR_SIMULATE_CASES`) is refused with exit status 2,
one line naming its option or key, stdout empty and nothing on disk; the control case runs
and prints strict JSON with the estimation error at every knot, its verdict by the exact
standard errors (with faults and a sampled V too; time-varying stage data: the sample's)."""
import json

import pytest
from hostile import SENSOR_SIMULATE_CASES, sensor_simulate_doc, to_toml

from stospline.cli import main

BASES_OF = {name: case[0] for name, case in SENSOR_SIMULATE_CASES.items()}


def _tree(root):
    return sorted(str(p.relative_to(root)) for p in root.rglob("*"))


@pytest.mark.parametrize("name", sorted(SENSOR_SIMULATE_CASES))
def test_each_sensor_loop_case_is_run_or_refused_by_name(name, tmp_path, monkeypatch, capsys):
    doc, extra, field = sensor_simulate_doc(name)
    (tmp_path / "p.toml").write_text(to_toml(doc))
    monkeypatch.chdir(tmp_path)
    before = _tree(tmp_path)
    rc = main(["simulate", "p.toml", "--paths", "200", "--json", "--quiet", *extra])
    out, err = capsys.readouterr()
    assert _tree(tmp_path) == before
    if field is None:
        assert rc == 0, err
        s = json.loads(out, parse_constant=lambda c: pytest.fail(f"{c} in the JSON"))
        assert s["measurement"]["every"] == 2
        for kn in s["knots"]:
            e = kn["estimation_error"]
            assert set(e) >= {"mc_mean", "mc_cov", "oracle_mean", "oracle_cov"}
        assert s["verdict"]["statistics"] >= 1
        # exact standard errors with faults and a sampled V; time-varying stage data: sample
        varying = "varying" in BASES_OF.get(name, "")
        assert s["standard_errors"]["used"] == ("sample" if varying else "exact"), (
            s["standard_errors"])
        if "faults" in doc:           # the verdict is against the oracle of the faulty loop
            f = s["faults"]
            assert set(f["levels"]) == set(doc["faults"]) and f["exact_oracle"]
            assert f["oracle_cost"] == s["cost"]["oracle_implemented"] != f["nominal_cost"]
        return
    assert rc == 2 and out == "", (rc, out, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert f"error in p.toml: {field}:" in lines[0] or f"error: {field}:" in lines[0], err


def test_a_problem_without_measurement_keeps_the_full_state_path(tmp_path, monkeypatch, capsys):
    """The same problem without its sensor: the full-state summary, no measurement key."""
    doc, _, _ = sensor_simulate_doc("valid")
    del doc["measurement"]
    (tmp_path / "p.toml").write_text(to_toml(doc))
    monkeypatch.chdir(tmp_path)
    assert main(["simulate", "p.toml", "--paths", "200", "--json", "--quiet"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert "measurement" not in s and "estimation_error" not in s["knots"][0]


def test_the_report_of_a_sensor_loop_shows_the_estimate_and_its_error_band(tmp_path, monkeypatch,
                                                                          capsys):
    doc, _, _ = sensor_simulate_doc("valid")
    (tmp_path / "p.toml").write_text(to_toml(doc))
    monkeypatch.chdir(tmp_path)
    assert main(["report", "p.toml", "--out", "page.html", "--paths", "200", "--quiet"]) == 0
    page = (tmp_path / "page.html").read_text()
    for part in ('id="sensor"', 'id="estimation-error"', 'alt="true state and estimate"',
                 'alt="estimation error band"', 'id="verdict"'):
        assert part in page, part
    assert page.count("data:image/png;base64,") == 3


def test_a_refused_sensor_report_writes_nothing(tmp_path, monkeypatch, capsys):
    doc, extra, field = sensor_simulate_doc("fault_option")
    (tmp_path / "p.toml").write_text(to_toml(doc))
    monkeypatch.chdir(tmp_path)
    assert main(["report", "p.toml", "--out", "page.html", "--paths", "200", *extra]) == 2
    out, err = capsys.readouterr()
    assert out == "" and len(err.strip().splitlines()) == 1 and f"{field}:" in err
    assert not (tmp_path / "page.html").exists()
