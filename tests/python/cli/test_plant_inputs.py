"""Every case of the hostile generator's plant family (`hostile.PLANT_EDITS`, and each broken
model of `support.plant_sources.BROKEN`) through `stospline design`: refused with status 2, one
line naming the field, stdout empty and nothing on disk; the valid case designs."""
import pytest
from hostile import PLANT_EDITS, plant_case, to_toml

from stospline.cli import main
from support.plant_sources import BROKEN


@pytest.mark.parametrize("edit", sorted(PLANT_EDITS) + [f"c:{k}" for k in sorted(BROKEN)])
def test_each_plant_edit_is_refused_in_one_line_by_the_cli(edit, tmp_path, capsys):
    files, doc, field = plant_case(edit)
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    (tmp_path / "p.toml").write_text(to_toml(doc))
    out = tmp_path / "out"
    before = sorted(p.name for p in tmp_path.iterdir())
    rc = main(["design", str(tmp_path / "p.toml"), "--out", str(out)])
    captured = capsys.readouterr()
    if field is None:
        assert rc == 0, captured.err
        return
    err = captured.err.strip()
    assert rc == 2, err
    assert len(err.splitlines()) == 1 and f": {field}" in err, err
    assert captured.out == ""
    assert sorted(p.name for p in tmp_path.iterdir()) == before




def test_a_plant_file_leaves_nothing_for_the_next_run(tmp_path, capsys):
    """`main` called again in the same process on a linear file runs the linear harness."""
    import json
    from hostile import NOISY
    files, doc, _ = plant_case("valid")
    (tmp_path / "model.c").write_text(files["model.c"])
    (tmp_path / "p.toml").write_text(to_toml(doc))
    (tmp_path / "lin.toml").write_text(to_toml(NOISY))
    assert main(["simulate", str(tmp_path / "p.toml"), "--paths", "20", "--json"]) == 0
    assert "plant" in json.loads(capsys.readouterr().out)
    assert main(["simulate", str(tmp_path / "lin.toml"), "--paths", "20", "--json"]) == 0
    assert "plant" not in json.loads(capsys.readouterr().out)


def test_corridor_design_of_a_plant_without_a_corridor_is_refused_in_one_line(tmp_path, capsys):
    files, doc, _ = plant_case("valid")
    (tmp_path / "model.c").write_text(files["model.c"])
    (tmp_path / "p.toml").write_text(to_toml(doc))
    rc = main(["corridor-design", str(tmp_path / "p.toml"), "--out", str(tmp_path / "out")])
    captured = capsys.readouterr()
    assert rc == 2 and captured.out == ""
    assert len(captured.err.strip().splitlines()) == 1 and ": corridors:" in captured.err
    assert not (tmp_path / "out").exists()
