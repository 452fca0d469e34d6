"""``[[parameters]]``: runtime parameters declared in the problem file, each bad entry refused
with one error naming its field, and the problem at a parameter vector equal to the file with
the values substituted."""
import copy
from dataclasses import replace

import numpy as np
import pytest

from support.problems import tracked_cart_doc

from stospline.problem import ProblemError, parse_problem
from stospline.problem.parameters import MAX_PARAMETERS, apply_to_doc, check_theta, problem_at


def base_doc():
    """A cart with a drift, one stage override with its own drift, a constraint row the
    reader scales by 2 (largest coefficient 0.5) and penalty targets."""
    return {
        "name": "cart", "x0": [0.0, 0.5], "tick_hz": 10,
        "dynamics": {"A": [[0, 1], [0, 0]], "B": [[0], [1]], "f": [0.0, -1.0]},
        "cost": {"R": [[1]]},
        "knots": [
            {"t": 1.0, "constraint": {"C": [[0.5, 0]], "value": [0.5]},
             "penalty": {"C": [[1, 0]], "target": [1.0], "weight": 2.0}},
            {"t": 2.0, "constraint": {"C": [[1, 0], [0, 1]], "value": [0.0, 0.0]},
             "penalty": {"C": [[1, 0]], "target": [0.0], "weight": 1.0}}],
        "stages": [{}, {"dynamics": {"f": [0.0, 0.25]}}],
        "parameters": [
            {"name": "mid", "sets": ["knots[0].constraint.value[0]"], "range": [0.0, 1.0]},
            {"name": "aim", "sets": ["knots[0].penalty.target[0]"], "range": [0.5, 1.5]},
            {"name": "rest", "sets": ["knots[1].constraint.value[0]",
                                      "knots[1].penalty.target[0]"], "range": [-0.5, 0.5]},
            {"name": "grav", "sets": ["dynamics.f[1]"], "range": [-2.0, 0.0]},
            {"name": "wind", "sets": ["stages[1].dynamics.f[1]"], "range": [0.0, 1.0]},
            {"name": "v0", "sets": ["x0[1]"], "range": [0.0, 1.0]}]}


def test_parameters_are_read():
    p = parse_problem(base_doc())
    assert [q.name for q in p.parameters] == ["mid", "aim", "rest", "grav", "wind", "v0"]
    assert [q.nominal for q in p.parameters] == [0.5, 1.0, 0.0, -1.0, 0.25, 0.5]
    mid = p.parameters[0].targets[0]
    assert (mid.kind, mid.at, mid.index, mid.scale) == ("value", 0, 0, 2.0)
    # dynamics.f sets the stages that take the top-level drift: stage 0 only here
    assert [(t.kind, t.at) for t in p.parameters[3].targets] == [("f", 0)]
    assert len(p.parameters[2].targets) == 2


def test_without_parameters_the_problem_is_unchanged():
    doc = base_doc()
    del doc["parameters"]
    q = parse_problem(doc)
    assert q.parameters == ()
    assert replace(parse_problem(base_doc()), parameters=()).to_toml() == q.to_toml()


def with_a_region(make):
    """`make`'s document with a region over [1.2, 1.6] every 0.2 s: its one grid point,
    t = 1.4, is a band knot that splits the file's stage 1 in two."""
    def doc():
        out = make()
        out["regions"] = [{"t": [1.2, 1.6], "every": 0.2, "C": [[0, 1]], "lower": [-5.0],
                           "upper": [5.0]}]
        return out
    doc.__name__ = f"{make.__name__}_with_a_region"
    return doc


def test_regions_shift_the_problem_indices_of_what_parameters_set():
    """The file's knot 1 is the problem's knot 2, and the file's stage 1 is the problem's
    stages 1 and 2."""
    p = parse_problem(with_a_region(base_doc)())
    assert [kn.t for kn in p.knots] == [1.0, 1.4, 2.0]
    at = {q.name: [(t.kind, t.at) for t in q.targets] for q in p.parameters}
    assert at["rest"] == [("value", 2), ("target", 2)]
    assert at["grav"] == [("f", 0)] and at["wind"] == [("f", 1), ("f", 2)]
    p = parse_problem(with_a_region(tracked_cart_doc)())
    at = {q.name: [(t.kind, t.at) for t in q.targets] for q in p.parameters}
    assert at["late"] == [("offset", 1), ("offset", 2)] and at["rest"] == [("value", 3)]


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("make", [base_doc, tracked_cart_doc, with_a_region(base_doc),
                                  with_a_region(tracked_cart_doc)],
                         ids=lambda f: f.__name__)
def test_problem_at_equals_the_substituted_file(make, seed):
    """Knot values and targets, x0, and every stage's q, rho, Q and f at 31 times (the
    tracking offsets move q and rho)."""
    doc = make()
    p = parse_problem(doc)
    rng = np.random.default_rng(seed)
    theta = rng.uniform([q.lower for q in p.parameters], [q.upper for q in p.parameters])
    a, b = problem_at(p, theta), parse_problem(apply_to_doc(doc, p.parameters, theta))
    assert np.array_equal(a.x0, b.x0)
    for ka, kb in zip(a.knots, b.knots):
        for x, y in ((ka.constraint, kb.constraint), (ka.penalty, kb.penalty)):
            if x is not None:
                assert np.array_equal(getattr(x, "value", None), getattr(y, "value", None))
                assert np.array_equal(getattr(x, "target", None), getattr(y, "target", None))
    times = np.linspace(0.0, 3.0, 31)
    for sa, sb in zip(a.stages, b.stages):
        da, db = sa.samples(times), sb.samples(times)
        for key in ("q", "rho", "Q", "f"):
            np.testing.assert_allclose(da[key], db[key], rtol=1e-14, atol=1e-14)
    assert doc == make()              # the input document is not touched


def test_theta_is_checked():
    p = parse_problem(base_doc())
    nominal = [q.nominal for q in p.parameters]
    assert np.array_equal(check_theta(p.parameters, nominal), nominal)
    with pytest.raises(ValueError, match="grav: .* outside its range"):
        check_theta(p.parameters, nominal[:3] + [0.5] + nominal[4:])
    with pytest.raises(ValueError, match="mid: nan"):
        check_theta(p.parameters, [float("nan")] + nominal[1:])
    with pytest.raises(ValueError, match="needs 6 values"):
        check_theta(p.parameters, nominal[:2])


def _set(path, value):
    def edit(doc):
        *head, last = path
        node = doc
        for k in head:
            node = node[k]
        if value is _DEL:
            del node[last]
        else:
            node[last] = value
    return edit


_DEL = object()
P0 = ("parameters", 0)

BAD = [
    ("not_array", _set(("parameters",), {"name": "a"}), "parameters", "non-empty array"),
    ("empty", _set(("parameters",), []), "parameters", "non-empty array"),
    ("too_many", _set(("parameters",), [{"name": f"p{i}", "sets": ["x0[0]"], "range": [0, 1]}
                                        for i in range(MAX_PARAMETERS + 1)]),
     "parameters", f"at most {MAX_PARAMETERS}"),
    ("unknown_key", _set(P0 + ("rnage",), [0, 1]), "parameters[0].rnage", "did you mean"),
    ("missing_range", _set(P0 + ("range",), _DEL), "parameters[0].range", "is required"),
    ("name_not_identifier", _set(P0 + ("name",), "mid-x"), "parameters[0].name",
     "C identifier"),
    ("name_twice", _set(("parameters", 1, "name"), "MID"), "parameters[1].name",
     "earlier parameter"),
    ("sets_empty", _set(P0 + ("sets",), []), "parameters[0].sets", "non-empty array"),
    ("sets_not_path", _set(P0 + ("sets",), [3]), "parameters[0].sets[0]", "path of a value"),
    ("sets_bad_syntax", _set(P0 + ("sets",), ["knots[0]..value"]), "parameters[0].sets[0]",
     "path of a value"),
    ("band_limit", _set(P0 + ("sets",), ["knots[0].constraint.lower[0]"]),
     "parameters[0].sets[0]", "band limits"),
    ("tracking", _set(P0 + ("sets",), ["cost.tracking.y0[0][0]"]), "parameters[0].sets[0]",
     "tracking path"),
    ("no_tracking", _set(P0 + ("sets",), ["cost.tracking.offset[0]"]), "parameters[0].sets[0]",
     "cost.tracking does not exist"),
    ("weight", _set(P0 + ("sets",), ["knots[0].penalty.weight"]), "parameters[0].sets[0]",
     "cannot be a runtime parameter"),
    ("x0_index", _set(P0 + ("sets",), ["x0[2]"]), "parameters[0].sets[0]", "no entry 2"),
    ("knot_missing", _set(P0 + ("sets",), ["knots[5].penalty.target[0]"]),
     "parameters[0].sets[0]", "does not exist"),
    ("row_missing", _set(P0 + ("sets",), ["knots[0].constraint.value[1]"]),
     "parameters[0].sets[0]", "does not exist"),
    ("f_samples", _set(("dynamics", "f"), {"t": [0, 2], "values": [[0, -1], [0, -1]]}),
     "parameters[3].sets[0]", "given as samples"),
    ("f_absent", _set(("dynamics", "f"), _DEL), "parameters[3].sets[0]", "write dynamics.f"),
    ("set_twice", _set(("parameters", 1, "sets"), ["knots[0].constraint.value[0]"]),
     "parameters[1].sets[0]", "already set by parameters[0].sets[0]"),
    ("unequal_nominals", _set(("parameters", 5, "sets"), ["x0[1]", "x0[0]"]),
     "parameters[5].sets", "must be equal"),
    ("range_length", _set(P0 + ("range",), [0.0]), "parameters[0].range", "[lower, upper]"),
    ("range_not_number", _set(P0 + ("range",), [0.0, True]), "parameters[0].range[1]",
     "must be a number"),
    ("range_inf", _set(P0 + ("range",), [0.0, float("inf")]), "parameters[0].range[1]",
     "finite"),
    ("range_empty", _set(P0 + ("range",), [1.0, 1.0]), "parameters[0].range", "below upper"),
    ("range_misses_nominal", _set(P0 + ("range",), [0.6, 1.0]), "parameters[0].range",
     "nominal value 0.5"),
    ("range_beyond_float32", _set(P0 + ("range",), [0.0, 1e39]), "parameters[0].range",
     "float32"),
]


@pytest.mark.parametrize("case", BAD, ids=[c[0] for c in BAD])
def test_bad_parameters_name_their_field(case):
    _, edit, field, reason = case
    doc = copy.deepcopy(base_doc())
    edit(doc)
    with pytest.raises(ProblemError) as err:
        parse_problem(doc)
    assert err.value.field == field, err.value
    assert reason in err.value.reason, err.value
    assert "\n" not in str(err.value)


def test_written_back_reads_the_same_parameters():
    """The TOML writer keeps the parameters, their paths and the units of a scaled row; a
    drift set on one stage only makes it write the stages one by one."""
    import tomllib
    p = parse_problem(base_doc())
    q = parse_problem(tomllib.loads(p.to_toml()))
    assert q.parameters == p.parameters
    assert np.array_equal(q.knots[0].constraint.C, p.knots[0].constraint.C)
    doc = base_doc()
    del doc["stages"]
    doc["parameters"][4] = {"name": "v1", "sets": ["x0[0]"], "range": [-1.0, 1.0]}
    p = parse_problem(doc)
    text = p.to_toml()
    assert "[[stages]]" not in text and '"dynamics.f[1]"' in text
    assert parse_problem(tomllib.loads(text)).parameters == p.parameters


def test_tracking_offsets_are_read():
    p = parse_problem(tracked_cart_doc())
    where = {q.name: [(t.kind, t.at, t.index) for t in q.targets] for q in p.parameters}
    assert where["shift_x"] == [("offset", 0, 0), ("offset", 2, 0)]   # the top-level path
    assert where["shift_v"] == [("offset", 0, 1), ("offset", 2, 1)]
    assert where["late"] == [("offset", 1, 0)]                        # stage 1's own path
    assert [q.nominal for q in p.parameters[:3]] == [0.1, 0.0, 0.0]   # offset not written: 0


BAD_OFFSETS = [
    ("output", ["cost.tracking.offset[2]"], "has 2 tracked outputs"),
    ("stage_has_none", ["stages[0].cost.tracking.offset[0]"], "does not exist"),
    ("samples", ["cost.tracking.y0[1][0]"], "only its constant offset"),
    ("weight", ["stages[1].cost.tracking.weight"], "only its constant offset"),
]


@pytest.mark.parametrize("case", BAD_OFFSETS, ids=[c[0] for c in BAD_OFFSETS])
def test_bad_offsets_name_their_field(case):
    _, sets, reason = case
    doc = tracked_cart_doc()
    doc["parameters"][0]["sets"] = sets
    with pytest.raises(ProblemError) as err:
        parse_problem(doc)
    assert err.value.field == "parameters[0].sets[0]" and reason in err.value.reason, err.value


def test_offset_of_a_path_no_stage_takes_and_of_the_wrong_length():
    doc = tracked_cart_doc()
    own = doc["stages"][1]["cost"]
    doc["stages"] = [{"cost": {"tracking": {**own["tracking"], "t": t}}}
                     for t in ([0, 1], [1, 2], [2, 3])]
    doc["parameters"] = doc["parameters"][:1]
    with pytest.raises(ProblemError, match="no stage takes cost.tracking") as err:
        parse_problem(doc)
    assert err.value.field == "parameters[0].sets[0]"
    doc = tracked_cart_doc()
    doc["cost"]["tracking"]["offset"] = [0.1]
    with pytest.raises(ProblemError) as err:
        parse_problem(doc)
    assert err.value.field == "cost.tracking.offset", err.value


def test_offsets_written_back_read_the_same_parameters():
    import tomllib
    p = parse_problem(tracked_cart_doc())
    text = p.to_toml()
    assert "stages[1].cost.tracking.offset[0]" in text
    q = parse_problem(tomllib.loads(text))
    assert q.parameters == p.parameters
    times = np.linspace(0.0, 3.0, 7)
    for sa, sb in zip(p.stages, q.stages):
        np.testing.assert_array_equal(sa.samples(times)["q"], sb.samples(times)["q"])
