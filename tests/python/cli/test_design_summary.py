"""`stospline design` prints a short human summary (J0, the oracle's cost of the float32 table,
ticks, stages, flash per arithmetic, worst constraint residual); `--json` prints the JSON only
and formats no C; `--version`. The flash figures equal the sizes of the compiled tables."""
import re
import shutil
import subprocess

import pytest

import stospline
from stospline.cli import main
from stospline.table.flash import flash_bytes
from stospline.report.summary_text import worst_constraint_residual

from conftest import EXAMPLES, GAINS, REPO

ROBOT = str(EXAMPLES / "robot_corridor.toml")


def test_summary_by_default(capsys, robot_zoh):
    assert main(["design", ROBOT]) == 0
    out = capsys.readouterr().out
    d = robot_zoh
    assert f"J0 (designed)                  {d.design.J0:.10g}" in out
    assert f"{d.implemented.J:.10g}" in out
    assert "6000 at 1000 Hz" in out and "2 stages" in out
    for arith in ("float32", "q15", "q31"):
        assert re.search(rf"{arith}\*? {flash_bytes(d.table, arith):,} B", out), arith
    r, k, i = worst_constraint_residual(d)
    assert f"{r:.3g}   (knot {k}, row {i}" in out
    assert len(out.splitlines()) <= 8


def test_summary_then_written_files(capsys, tmp_path):
    assert main(["design", ROBOT, "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "J0 (designed)" in out and out.count("wrote ") == 3


def test_json_formats_no_c(monkeypatch, capsys):
    import json
    import stospline.pipeline as pipeline
    def refuse(*a, **k):
        raise AssertionError("C text formatted for --json without --out")
    monkeypatch.setattr(pipeline, "generate_c", refuse)
    assert main(["design", ROBOT, "--json"]) == 0
    assert "J0" in json.loads(capsys.readouterr().out)


def test_version(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"stospline {stospline.__version__}"


def symbol_bytes(c_file, defines, tmp_path) -> int:
    """Bytes of every object the generated C file defines, compiled for a Cortex-M4."""
    obj = tmp_path / "t.o"
    subprocess.run(["arm-none-eabi-gcc", "-mcpu=cortex-m4", "-mthumb", "-std=c99", "-c",
                    *defines, f"-I{REPO / 'firmware' / 'include'}", f"-I{c_file.parent}",
                    str(c_file), "-o", str(obj)], check=True)
    nm = subprocess.run(["arm-none-eabi-nm", "-S", str(obj)], capture_output=True, text=True,
                        check=True).stdout
    return sum(int(line.split()[1], 16) for line in nm.splitlines() if len(line.split()) == 4)


@pytest.mark.skipif(shutil.which("arm-none-eabi-gcc") is None, reason="no arm-none-eabi-gcc")
@pytest.mark.parametrize("name, arith", [("robot_corridor", "float32"),
                                         ("robot_corridor_q15", "q15"),
                                         ("robot_corridor_q31", "q31"),
                                         ("robot_bands", "float32"),
                                         ("robot_corridor_spline", "float32"),
                                         ("robot_patrol_60s_spline", "float32"),
                                         ("robot_bands_spline", "float32"),
                                         ("robot_corridor_q15_spline", "q15"),
                                         ("robot_corridor_q31_spline", "q31")])
def test_flash_bytes_match_the_compiled_tables(name, arith, robot_zoh, tmp_path):
    if name.endswith("_spline") and arith != "float32":
        from stospline.pipeline import design_problem, fixed_point_spline
        from stospline.problem import load_problem
        d = design_problem(load_problem(EXAMPLES / "robot_corridor.toml"), table="spline")
        table = fixed_point_spline(d, arith)[0]
        assert table.spline is not None
        # the target for the Q15 robot table: at most 3 KB in compiled symbols
        if arith == "q15":
            assert flash_bytes(table, arith) <= 3072
    elif name.endswith("_spline"):
        from stospline.pipeline import design_problem
        from stospline.problem import load_problem
        problem = load_problem(EXAMPLES / f"{name.removesuffix('_spline')}.toml")
        table = design_problem(problem, table="spline",
                               mode=problem.options.get("mode", "stagewise")).table
        assert table.spline is not None
    elif name == "robot_bands":
        from stospline.pipeline import design_problem
        from stospline.problem import load_problem
        table = design_problem(load_problem(EXAMPLES / "robot_bands.toml"), mode="joint").table
        assert table.band_qp is not None
    else:
        table = robot_zoh.table
    defines = {"q15": ["-DSTSP_ARITH_Q15"], "q31": ["-DSTSP_ARITH_Q31"]}.get(arith, [])
    assert flash_bytes(table, arith) == symbol_bytes(GAINS / f"{name}.c", defines, tmp_path)
