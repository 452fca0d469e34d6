"""docs/guide/problem-file.md cannot drift from the parser: every ```toml block in it parses, and
every key the parser accepts is documented.

Each block's first line says what it is: ``# complete file`` (a whole problem file; when it
names ``examples/X.toml`` it must parse to the same problem as that file) or ``# fragment of
the minimal file`` (merged into the block marked ``the minimal file``: tables key by key, every
other value, arrays of tables included, replaced)."""
import re
import tomllib

import numpy as np
import pytest

from stospline.problem import reader as problem_module
from stospline.problem.faults import FAULT_KEYS
from stospline.cli import build_parser
from stospline.problem import load_problem, parse_problem

from conftest import REPO

DOC = REPO / "docs" / "guide" / "problem-file.md"
TEXT = DOC.read_text(encoding="utf-8")
BLOCKS = re.findall(r"^```toml\n(.*?)^```", TEXT, flags=re.DOTALL | re.MULTILINE)
COMPLETE = re.compile(r"# complete file(?::.*?(?P<example>examples/\S+\.toml))?")
FRAGMENT = "# fragment of the minimal file"


def kind(block: str) -> str:
    first = block.splitlines()[0]
    if COMPLETE.match(first):
        return "complete"
    if first.startswith(FRAGMENT):
        return "fragment"
    return "unmarked"


def merged(base: dict, fragment: dict) -> dict:
    out = dict(base)
    for key, value in fragment.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = merged(out[key], value)
        else:
            out[key] = value
    return out


def minimal() -> dict:
    (base,) = [b for b in BLOCKS if "the minimal file (the fragments" in b.splitlines()[0]]
    return tomllib.loads(base)


def same_knot(a, b) -> bool:
    def parts(kn):
        out = [kn.t]
        for obj, fields in ((kn.penalty, ("C", "target", "weight")),
                            (kn.constraint, ("C", "value", "lower", "upper"))):
            out += [None] if obj is None else [getattr(obj, f) for f in fields]
        return out
    return all((x is None and y is None) or (x is not None and y is not None
                                              and np.array_equal(x, y))
               for x, y in zip(parts(a), parts(b)))


def label(block: str) -> str:
    return f"{kind(block)}@line{TEXT[:TEXT.index(block)].count(chr(10)) + 1}"


def test_the_doc_has_marked_snippets():
    assert sum(kind(b) == "complete" for b in BLOCKS) >= 2
    assert sum(kind(b) == "fragment" for b in BLOCKS) >= 8
    unmarked = [label(b) for b in BLOCKS if kind(b) == "unmarked"]
    assert not unmarked, f"blocks without a '# complete file' / '{FRAGMENT}' first line"


@pytest.mark.parametrize("block", BLOCKS, ids=label)
def test_snippet_parses(block, tmp_path):
    if kind(block) == "complete":
        path = tmp_path / "snippet.toml"
        path.write_text(block, encoding="utf-8")
        problem = load_problem(path)
        example = COMPLETE.match(block.splitlines()[0]).group("example")
        if example:   # the doc's copy says the same as the file (comments may differ)
            same = load_problem(REPO / example)
            assert problem.name == same.name and problem.tick_hz == same.tick_hz
            np.testing.assert_array_equal(problem.times, same.times)
            np.testing.assert_array_equal(problem.x0, same.x0)
            for a, b in zip(problem.stages, same.stages):
                for f in ("A", "B", "G", "Q", "S", "R", "q", "r"):
                    np.testing.assert_array_equal(getattr(a, f), getattr(b, f))
            assert len(problem.knots) == len(same.knots)
            for a, b in zip(problem.knots, same.knots):
                assert same_knot(a, b)
            assert problem.plot == same.plot and problem.options == same.options
            assert len(problem.corridors) == len(same.corridors)
            for a, b in zip(problem.corridors, same.corridors):
                assert a.t == b.t and a.epsilon == b.epsilon
                np.testing.assert_array_equal(a.C, b.C)
                np.testing.assert_array_equal(a.A, b.A)
                np.testing.assert_array_equal(a.b, b.b)
                np.testing.assert_array_equal(a.row_start, b.row_start)
    else:
        assert kind(block) == "fragment"
        parse_problem(merged(minimal(), tomllib.loads(block)))


def test_fragments_change_the_minimal_file():
    """A fragment whose keys the merge silently dropped would parse trivially."""
    base = parse_problem(minimal())
    for block in BLOCKS:
        if kind(block) == "fragment":
            frag = tomllib.loads(block)
            assert frag, label(block)
            problem = parse_problem(merged(minimal(), frag))
            changed = (len(problem.knots) != len(base.knots)
                       or not all(map(same_knot, problem.knots, base.knots)) or problem.options or problem.plot
                       or problem.u_min is not None or problem.mz != base.mz
                       or problem.faults.any
                       or problem.u_hold is not None
                       or problem.corridors
                       or problem.measurement is not None
                       or problem.parameters
                       or any(s.varying is not None or not np.array_equal(s.R, b.R)
                              or s.f is not None
                              or not np.array_equal(s.A, b.A) or s.G.any()
                              for s, b in zip(problem.stages, base.stages)))
            assert changed, label(block)


def documented(key: str) -> bool:
    return any(f"`{form}`" in TEXT for form in (key, f"[{key}]", f"[[{key}]]")) or re.search(rf"`[^`]*\b{re.escape(key)} =", TEXT) is not None


# Keys accepted below the top-level tables (the parser spells these inline).
NESTED = ["state", "input", "G", "C", "target", "weight", "value", "lower", "upper", "t",
          "values", "interpolation", "y0", "every", "axes", "walls", "polygons", "epsilon",
          "A", "b", "V", "D", "x0_cov", *FAULT_KEYS]


@pytest.mark.parametrize("key", sorted(problem_module._TOP_KEYS | problem_module._DYN_KEYS
                                       | problem_module._COST_KEYS
                                       | set(problem_module._DESIGN_OPTIONS)) + NESTED)
def test_every_accepted_key_is_documented(key):
    assert documented(key), f"docs/guide/problem-file.md does not mention `{key}`"


@pytest.mark.parametrize("key, values", list(problem_module._DESIGN_OPTIONS.items()))
def test_design_option_values_are_documented(key, values):
    for v in values or ():       # None: a number (spline_tolerance), its range documented
        shown = f'`"{v}"`' if isinstance(v, str) else f"`{v}`"
        assert shown in TEXT, f"design.{key} = {v!r} is not documented"


def test_overriding_cli_options_are_documented():
    sub = build_parser()._subparsers._group_actions[0].choices
    opts = {s for p in sub.values() for a in p._actions for s in a.option_strings}
    for opt in ("--mode", "--discretization", "--ignore-noise", "--x0"):
        assert opt in opts, opt          # the option still exists ...
        assert f"`{opt}" in TEXT, opt    # ... and is documented
    choices = {c for p in sub.values() for a in p._actions if a.choices for c in a.choices}
    for c in choices:
        assert c in TEXT, c


@pytest.mark.parametrize("block", [b for b in BLOCKS if kind(b) == "fragment"
                                   or "the minimal file" in b.splitlines()[0]], ids=label)
def test_minimal_snippets_design(block):
    """The small snippets are working problems, not only well-formed ones: each designs (in
    the file's [design] mode, exact-zoh) and the oracle confirms the float32 table's cost."""
    from stospline.pipeline import design_problem
    doc = tomllib.loads(block)
    problem = parse_problem(doc if kind(block) == "complete" else merged(minimal(), doc))
    d = design_problem(problem, mode=problem.options.get("mode", "stagewise"))
    assert d.implemented.J == pytest.approx(d.design.J0, rel=1e-6)
