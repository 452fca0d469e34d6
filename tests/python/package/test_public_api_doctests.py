"""The calls a user scripts with carry numpydoc docstrings whose Examples run: the doctests
of every function in `WORKFLOW` pass, from the repository root (they read `examples/`)."""
import doctest
import inspect
from pathlib import Path

import pytest

import stospline

ROOT = Path(__file__).resolve().parents[3]
# load/parse a problem, design, build the table, quantize, generate C, build the controller,
# simulate, evaluate with the oracle
WORKFLOW = ["load_problem", "problem_from_arrays", "design_problem", "table_of", "fixed_point_table",
            "generate_c", "build_controller", "simulate_problem", "evaluate_table"]


@pytest.mark.parametrize("name", WORKFLOW)
def test_the_examples_run(name, monkeypatch):
    monkeypatch.chdir(ROOT)
    obj = getattr(stospline, name)
    tests = doctest.DocTestFinder(recurse=False).find(obj, name, globs={})
    assert tests and tests[0].examples, f"{name} has no Examples"
    runner = doctest.DocTestRunner(optionflags=doctest.NORMALIZE_WHITESPACE)
    for t in tests:
        runner.run(t)
    assert runner.failures == 0, f"{runner.failures} example(s) of {name} failed (see above)"


@pytest.mark.parametrize("name", WORKFLOW)
def test_numpydoc_sections(name):
    # cleandoc: CPython 3.13 strips the docstring's indentation when it compiles, 3.11-3.12 not
    doc = inspect.cleandoc(getattr(stospline, name).__doc__)
    for section in ("Parameters", "Returns", "Examples"):
        assert f"\n{section}\n{'-' * len(section)}\n" in doc, (name, section)


def test_help_lists_the_public_api():
    import pydoc
    text = pydoc.render_doc(stospline, renderer=pydoc.plaintext)
    for name in WORKFLOW + ["__version__"]:
        assert name in text, name
