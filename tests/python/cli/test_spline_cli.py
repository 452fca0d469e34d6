"""`stospline design --table spline`: the spline table's files and certificate, the options'
checks, and the refusals (one line naming the field, exit status 2, nothing on disk)."""
import json

import pytest

from stospline.cli import main
from stospline.table.flash import flash_bytes

from conftest import EXAMPLES

ROBOT = str(EXAMPLES / "robot_corridor.toml")


def test_robot_spline_files_and_certificate(capsys, tmp_path, robot_zoh):
    assert main(["design", ROBOT, "--table", "spline", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "robot_corridor_spline.c", "robot_corridor_spline.h", "robot_corridor_spline.json"]
    cert = json.loads((tmp_path / "robot_corridor_spline.json").read_text())["table"]
    # The targets: <= 4 KB (>= 100x), cost within 1e-6 of the uncompressed law's.
    assert cert["kind"] == "spline" and cert["flash_bytes"] <= 4096
    assert cert["per_tick_flash_bytes"] == flash_bytes(robot_zoh.table)
    assert cert["compression_ratio"] >= 100
    assert abs(cert["excess_over_law"]) <= 1e-6 and abs(cert["excess_over_J0"]) <= 1e-6
    assert cert["constraint_residual"] <= 1e-7 and cert["knot_cov_change"] <= 1e-6
    assert "J of the spline table" in out and "smaller than per-tick" in out
    source = (tmp_path / "robot_corridor_spline.c").read_text()
    assert "robot_corridor_spline_K" not in source and "&robot_corridor_spline_spline" in source


@pytest.mark.parametrize("arith", ["q15", "q31"])
def test_robot_fixed_point_spline_files_and_certificate(capsys, tmp_path, arith):
    """`--arith q15|q31 --table spline`: <name>_<arith>_spline.{c,h,json}; the certificate of
    the table as the firmware evaluates it, its error bound computed, its flash (the target
    for Q15: at most 3 KB)."""
    assert main(["design", ROBOT, "--arith", arith, "--table", "spline",
                 "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    stem = f"robot_corridor_{arith}_spline"
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"{stem}.{s}" for s in ("c", "h", "json")]
    summary = json.loads((tmp_path / f"{stem}.json").read_text())
    cert, fixed = summary["table"], summary["fixed"]
    assert cert["kind"] == "spline" and cert["arith"] == arith
    assert cert["flash_bytes"] < cert["per_tick_flash_bytes"] / 50
    if arith == "q15":
        assert cert["flash_bytes"] <= 3072
    assert abs(cert["excess_over_law"]) <= 1e-3 and cert["knot_cov_change"] <= 1e-3
    assert cert["u_error_bound"] == fixed["u_error_bound"] and len(cert["u_error_bound"]) == 2
    assert f"{arith} spline table" in out and "error bound" in out
    source = (tmp_path / f"{stem}.c").read_text()
    assert f"{stem}_K" not in source and f"&{stem}_spline" in source
    assert "stsp_qspline_t" in source and "&stsp_spline_ops" in source


def test_file_option_selects_the_spline(tmp_path, capsys):
    text = (EXAMPLES / "robot_corridor.toml").read_text().replace(
        'tick_hz = 1000\n', 'tick_hz = 1000\n\n[design]\ntable = "spline"\n'
        'spline_tolerance = 1e-3\n', 1)
    f = tmp_path / "robot.toml"
    f.write_text(text)
    assert main(["design", str(f), "--json"]) == 0
    cert = json.loads(capsys.readouterr().out)["table"]
    assert cert["spline_tolerance"] == 1e-3 and cert["kind"] == "spline"


def test_file_options_select_the_fixed_point_spline(tmp_path, capsys):
    text = (EXAMPLES / "robot_corridor.toml").read_text().replace(
        'tick_hz = 1000\n', 'tick_hz = 1000\n\n[design]\narith = "q15"\ntable = "spline"\n', 1)
    f = tmp_path / "robot.toml"
    f.write_text(text)
    assert main(["design", str(f), "--out", str(tmp_path / "out")]) == 0
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [
        f"robot_corridor_q15_spline.{s}" for s in ("c", "h", "json")]
    cert = json.loads((tmp_path / "out" / "robot_corridor_q15_spline.json").read_text())["table"]
    assert cert["kind"] == "spline" and cert["arith"] == "q15"


@pytest.mark.parametrize("value", ["abc", "0", "1", "nan", "-1e-5"])
def test_bad_tolerance_option(capsys, tmp_path, value):
    out = tmp_path / "out"
    assert main(["design", ROBOT, "--table", "spline", f"--spline-tolerance={value}",
                 "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "--spline-tolerance" in err
    assert not out.exists()


@pytest.mark.parametrize("key, value, field", [
    ("table", '"splines"', "design.table"),
    ("spline_tolerance", '"small"', "design.spline_tolerance"),
    ("spline_tolerance", "true", "design.spline_tolerance"),
    ("spline_tolerance", "0.5", "design.spline_tolerance"),
])
def test_bad_file_options(capsys, tmp_path, key, value, field):
    text = (EXAMPLES / "robot_corridor.toml").read_text().replace(
        'tick_hz = 1000\n', f'tick_hz = 1000\n\n[design]\n{key} = {value}\n', 1)
    f = tmp_path / "robot.toml"
    f.write_text(text)
    assert main(["design", str(f), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and field in err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("example, extra, field", [
    # A table that latches the state (bands beyond the 8 rows of a band dual): float32 only
    ("robot_narrow_corridor", ["--arith", "q15"], "design.table"),
    ("robot_corridor", ["--spline-tolerance", "1e-9"], "--spline-tolerance"),
])
def test_refused_spline_tables(capsys, tmp_path, example, extra, field):
    out = tmp_path / "out"
    assert main(["design", str(EXAMPLES / f"{example}.toml"), "--table", "spline", *extra,
                 "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and field in err, err
    assert not out.exists() or not any(out.iterdir())
