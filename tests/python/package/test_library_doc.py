"""docs/guide/library.md cannot drift from the library: its ```python blocks run, in order, in one
namespace, from a temporary directory holding a copy of examples/."""
import re
import shutil

import pytest

from conftest import EXAMPLES, REPO

DOC = REPO / "docs" / "guide" / "library.md"
BLOCKS = re.findall(r"^```python\n(.*?)^```", DOC.read_text(encoding="utf-8"),
                    flags=re.DOTALL | re.MULTILINE)


def test_the_page_has_the_design_table_simulate_path():
    text = "\n".join(BLOCKS)
    for call in ("load_problem", "design_problem", ".gains()", "generated_files",
                 "simulate_problem", "problem_from_arrays", "problem_from_statespace",
                 "to_toml"):
        assert call in text, call


def test_the_blocks_run(tmp_path, monkeypatch, capsys):
    pytest.importorskip("control")
    shutil.copytree(EXAMPLES, tmp_path / "examples")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    namespace: dict = {}
    for i, block in enumerate(BLOCKS):
        exec(compile(block, f"{DOC.name}[python block {i}]", "exec"), namespace)
    out = capsys.readouterr().out
    assert "cost.R - " in out and "positive definite" in out
    assert (tmp_path / "robot.png").stat().st_size > 1000
    assert sorted(p.name for p in (tmp_path / "gains_out").iterdir()) == [
        "robot_corridor.c", "robot_corridor.h", "robot_corridor.json"]
