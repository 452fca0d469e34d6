"""Bad ``[plant]`` models are refused with one `ProblemError` line naming the field (the
command line's side: tests/python/cli/test_plant_inputs.py)."""
import copy

import pytest

from stospline.errors import ProblemError
from stospline.nonlinear.iterate import fit_plant
from support.plant_sources import BROKEN, LINEAR, linear_doc


@pytest.mark.parametrize("case", sorted(BROKEN))
def test_a_broken_model_is_refused_naming_plant_source(case, tmp_path):
    source, words = BROKEN[case]
    (tmp_path / "model.c").write_text(source)
    with pytest.raises(ProblemError) as err:
        fit_plant(linear_doc(), tmp_path)
    assert err.value.field in ("plant.source", "plant.params"), str(err.value)
    assert words in err.value.reason, str(err.value)
    assert "\n" not in str(err.value)


def test_the_linear_model_compiles_clean_with_strict_warnings(tmp_path):
    import subprocess
    from stospline.problem.plant_c import HEADER
    from conftest import EXAMPLES
    (tmp_path / "model.c").write_text(LINEAR)
    for src in (tmp_path / "model.c", EXAMPLES / "nonlinear" / "unicycle.c"):
        r = subprocess.run(["gcc", "-std=c99", "-Wall", "-Wextra", "-Wpedantic", "-Wconversion",
                            "-Werror", f"-I{HEADER.parent}", "-c", str(src), "-o",
                            str(tmp_path / "m.o")], capture_output=True, text=True)
        assert r.returncode == 0, r.stderr
