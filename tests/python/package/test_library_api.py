"""The Python library: `import stospline` (cheap, documented names, __version__), problems from
numpy arrays / plain A, B, Q, R / a control.StateSpace with the file's checks and field names,
problem_to_toml round trips, and the gains as numpy arrays on a time axis."""
import dataclasses
import importlib.metadata
import inspect
import re
import subprocess
import sys
import tomllib

import numpy as np
import pytest

import stospline
from stospline.problem import ProblemError, load_problem, parse_problem
from stospline.problem.toml_writer import ProblemTomlError, problem_to_toml

from conftest import EXAMPLES, REPO
import test_problem_file_doc as doc_snippets


def test_import_is_cheap_and_versioned():
    code = ("import sys, stospline; heavy = [m for m in ('scipy', 'matplotlib', 'cffi', "
            "'osqp', 'stospline.pipeline') if m in sys.modules]; print(heavy, stospline.__version__)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.split(maxsplit=1)
    assert out[0] == "[]", out
    assert out[1].strip() == importlib.metadata.version("stospline")


PUBLIC = sorted(set(stospline.__all__) - {"__version__"})


def documented_public_names() -> list[str]:
    """The names in the table under "Public names" in docs/guide/library.md."""
    text = (REPO / "docs" / "guide" / "library.md").read_text(encoding="utf-8")
    section = text.split("\n## Public names\n", 1)[1].split("\n## ", 1)[0]
    first_cells = [row.split("|")[1] for row in section.splitlines() if row.startswith("| `")]
    return re.findall(r"`(\w+)`", " ".join(first_cells))


def test_all_is_the_documented_public_api():
    documented = documented_public_names()
    assert len(documented) == len(set(documented)), documented
    assert len(stospline.__all__) == len(set(stospline.__all__)), stospline.__all__
    assert sorted(documented) == PUBLIC


@pytest.mark.parametrize("name", PUBLIC)
def test_every_public_name_is_defined_in_the_package(name):
    """Each name is the class or function of that name defined in a stospline module (not an
    alias, a stub or a re-export of something else); the exceptions are ValueErrors."""
    obj = getattr(stospline, name)
    assert obj.__module__.startswith("stospline."), obj.__module__
    assert obj.__name__ == name and obj.__qualname__ == name, obj
    assert getattr(sys.modules[obj.__module__], name) is obj
    if name[0].isupper():
        assert isinstance(obj, type), obj
        if issubclass(obj, BaseException):
            assert issubclass(obj, ValueError), obj.__mro__
    else:
        assert inspect.isfunction(obj), obj


def robot_doc(array):
    """The robot corridor problem as a Python dict, arrays made by `array`."""
    doc = tomllib.loads((EXAMPLES / "robot_corridor.toml").read_text())
    def conv(v):
        if isinstance(v, dict):
            return {k: conv(x) for k, x in v.items()}
        if isinstance(v, list) and v and all(isinstance(x, (int, float, list)) for x in v):
            return array(v)
        if isinstance(v, list):
            return [conv(x) for x in v]
        return v
    return conv(doc)


def same_problem(a, b) -> bool:
    """Equal as problems: every array, every knot, limits, options, and time-varying data at
    the stage ends and at every sample time."""
    if (a.name, float(a.t0), a.tick_hz, a.options, a.plot) != (b.name, float(b.t0), b.tick_hz,
                                                               b.options, b.plot):
        return False
    eq = lambda x, y: (x is None and y is None) or (x is not None and y is not None  # noqa: E731
                                                    and np.array_equal(x, y))
    if not (eq(a.x0, b.x0) and eq(a.u_min, b.u_min) and eq(a.u_max, b.u_max)):
        return False
    if len(a.knots) != len(b.knots) or len(a.stages) != len(b.stages):
        return False
    if a.measurement != b.measurement or a.parameters != b.parameters:
        return False
    if len(a.corridors) != len(b.corridors) or not all(
            ca.t == cb.t and ca.epsilon == cb.epsilon and eq(ca.C, cb.C)
            and len(ca.polygons) == len(cb.polygons)
            and all(eq(A, B) and eq(x, y) for (A, x), (B, y) in zip(ca.polygons, cb.polygons))
            for ca, cb in zip(a.corridors, b.corridors)):
        return False
    if len(a.tick_regions) != len(b.tick_regions) or not all(
            ra.t == rb.t and eq(ra.C, rb.C) and eq(ra.lower, rb.lower) and eq(ra.upper, rb.upper)
            for ra, rb in zip(a.tick_regions, b.tick_regions)):
        return False
    for ka, kb in zip(a.knots, b.knots):
        if ka.t != kb.t or (ka.penalty is None) != (kb.penalty is None) or (
                (ka.constraint is None) != (kb.constraint is None)):
            return False
        if ka.penalty and not (eq(ka.penalty.C, kb.penalty.C)
                               and eq(ka.penalty.target, kb.penalty.target)
                               and ka.penalty.weight == kb.penalty.weight):
            return False
        if ka.constraint and not all(eq(getattr(ka.constraint, f), getattr(kb.constraint, f))
                                     for f in ("C", "value", "lower", "upper")):
            return False
    times = a.times
    for k, (sa, sb) in enumerate(zip(a.stages, b.stages)):
        if (sa.varying is None) != (sb.varying is None):
            return False
        probes = [None]
        if sa.varying is not None:
            origin = sa.origin
            sample_t = [t for s in origin.series() for t in s.t]
            probes = sorted({times[k], times[k + 1], 0.5 * (times[k] + times[k + 1]),
                             *[t for t in sample_t if times[k] <= t <= times[k + 1]]})
        for t in probes:
            xa, xb = (sa, sb) if t is None else (sa.at(t), sb.at(t))
            for f in ("A", "B", "G", "H", "Q", "S", "R", "q", "r", "rho"):
                if not eq(getattr(xa, f), getattr(xb, f)):
                    return False
    return True


def test_numpy_arrays_tuples_and_scalars_parse_like_lists():
    lists = parse_problem(robot_doc(lambda v: v))
    arrays = parse_problem(robot_doc(np.array))
    tuples = parse_problem(robot_doc(lambda v: tuple(tuple(x) if isinstance(x, list) else x
                                                     for x in v)))
    assert same_problem(arrays, lists) and same_problem(tuples, lists)
    doc = robot_doc(np.array)
    doc["tick_hz"] = np.int64(1000)
    doc["knots"][0]["penalty"]["weight"] = np.float32(7.0)
    assert same_problem(parse_problem(doc), lists)


@pytest.mark.parametrize("edit, field", [
    (lambda d: d["dynamics"].__setitem__("A", np.full((4, 4), np.nan)), "dynamics.A[0][0]"),
    (lambda d: d["dynamics"].__setitem__("B", np.zeros((3, 2))), "dynamics.B"),
    (lambda d: d["cost"].__setitem__("R", -np.eye(2)), "cost.R"),
    (lambda d: d.__setitem__("tick_hz", np.bool_(True)), "tick_hz"),
    (lambda d: d["knots"][1]["constraint"].__setitem__("value", np.zeros(3)),
     "knots[1].constraint.value"),
])
def test_numpy_values_get_the_files_errors(edit, field):
    """The same field and message for a numpy value as for the list a file would hold."""
    msgs = []
    for array in (lambda v: v, np.array):
        doc = robot_doc(array)
        edit(doc)
        with pytest.raises(ProblemError) as exc:
            parse_problem(doc)
        msgs.append(str(exc.value))
        assert exc.value.field == field
    assert msgs[0] == msgs[1]


ROBOT = dict(
    A=np.array([[0, 1, 0, 0], [0, 0, 0, 0], [0, 0, 0, 1], [0, 0, 0, 0]], float),
    B=np.array([[0, 0], [1, 0], [0, 0], [0, 1]], float),
    G=np.zeros((4, 4, 2)))
ROBOT["G"][1, 1, 0] = 1.0
ROBOT["G"][3, 3, 1] = 1.0
ROBOT_KNOTS = [
    {"t": 3.0, "penalty": {"C": np.array([[1, 0, 0, 0], [0, 0, 1, 0]]), "target": [-1.0, 1.0],
                           "weight": 7.0},
     "constraint": {"C": [[1, 0, 1, 0]], "value": [0.0]}},
    {"t": 6.0, "penalty": {"C": np.eye(4), "target": [-1.0, 0.0, 5.0, 0.0], "weight": 1.0},
     "constraint": {"C": np.eye(4), "value": np.array([-1.0, 0.0, 5.0, 0.0])}},
]


ROBOT_CORRIDOR = [{"t": [0.0, 6.0], "C": [[1, 0, 0, 0], [0, 0, 1, 0]],
                   "polygons": [{"A": [[0, -1], [0, 1], [1, 0]], "b": [0, 2, 0]},
                                {"A": [[-1, 0], [1, 0], [0, -1]], "b": [2, 0, 0]}]}]


def robot_from_arrays(**kw):
    return stospline.problem_from_arrays(
        ROBOT["A"], ROBOT["B"], None, np.eye(2), x0=np.array([-5.0, 0.0, 1.0, 0.0]),
        knots=ROBOT_KNOTS, tick_hz=1000, noise=ROBOT["G"], name="robot_corridor", **kw)


def test_problem_from_arrays_is_the_robot_file(robot_problem):
    from dataclasses import replace
    p = robot_from_arrays(plot=robot_problem.plot, corridors=ROBOT_CORRIDOR)
    assert same_problem(p, robot_problem)
    # Without the corridor, the same problem but for it.
    assert same_problem(robot_from_arrays(plot=robot_problem.plot),
                        replace(robot_problem, corridors=()))
    # Its hash is that of its TOML form: the tables it designs name the file it writes.
    import hashlib
    assert p.source_sha256 == hashlib.sha256(p.to_toml().encode()).hexdigest()


def test_problem_from_arrays_names_the_field():
    with pytest.raises(ProblemError) as exc:
        stospline.problem_from_arrays(ROBOT["A"], ROBOT["B"], None, np.diag([1.0, -1.0]),
                                      x0=np.zeros(4), knots=ROBOT_KNOTS, tick_hz=1000)
    assert exc.value.field == "cost.R" and "positive definite" in exc.value.reason
    with pytest.raises(ProblemError) as exc:
        stospline.problem_from_arrays(ROBOT["A"], ROBOT["B"], None, np.eye(2), x0=np.zeros(3),
                                      knots=ROBOT_KNOTS, tick_hz=1000)
    assert exc.value.field == "dynamics.A"


def test_state_space_dynamics(robot_problem):
    control = pytest.importorskip("control")
    sys_c = control.ss(ROBOT["A"], ROBOT["B"], np.eye(4), np.zeros((4, 2)))
    p = stospline.problem_from_statespace(
        sys_c, None, np.eye(2), x0=[-5.0, 0.0, 1.0, 0.0], knots=ROBOT_KNOTS, tick_hz=1000,
        noise=ROBOT["G"], name="robot_corridor", plot=robot_problem.plot)
    from dataclasses import replace
    assert same_problem(p, replace(robot_problem, corridors=()))
    sys_d = control.ss(ROBOT["A"], ROBOT["B"], np.eye(4), np.zeros((4, 2)), 0.001)
    with pytest.raises(ProblemError, match="discrete-time") as exc:
        stospline.problem_from_statespace(sys_d, None, np.eye(2), x0=np.zeros(4),
                                          knots=ROBOT_KNOTS, tick_hz=1000)
    assert exc.value.field == "dynamics"


def doc_problems():
    out = {}
    for block in doc_snippets.BLOCKS:
        doc = tomllib.loads(block)
        if doc_snippets.kind(block) != "complete":
            doc = doc_snippets.merged(doc_snippets.minimal(), doc)
        out[doc_snippets.label(block)] = parse_problem(doc)
    for path in sorted(EXAMPLES.glob("*.toml")):
        out[path.name] = load_problem(path)
    return out


DOC_PROBLEMS = doc_problems()


@pytest.mark.parametrize("label", sorted(DOC_PROBLEMS))
def test_toml_round_trip(label):
    """parse(to_toml(p)) == p for every example and every snippet of docs/guide/problem-file.md:
    time-varying samples, tracking, [[stages]], regions, bands, limits, noise, [design]."""
    p = DOC_PROBLEMS[label]
    text = problem_to_toml(p)
    q = parse_problem(tomllib.loads(text))
    assert same_problem(q, p), text
    assert problem_to_toml(q) == text


def test_round_trip_covers_the_hard_cases():
    kinds = {"varying": False, "stages": False, "bands": False, "limits": False,
             "tracking": False, "input_noise": False}
    for p in DOC_PROBLEMS.values():
        kinds["varying"] |= any(s.varying is not None for s in p.stages)
        kinds["stages"] |= len({id(s) for s in p.stages}) > 1
        kinds["bands"] |= any(k.constraint is not None and k.constraint.is_band for k in p.knots)
        kinds["limits"] |= p.u_min is not None or p.u_max is not None
        kinds["tracking"] |= any(s.origin is not None and s.origin.tracking is not None
                                 for s in p.stages)
        kinds["input_noise"] |= any(s.H is not None for s in p.stages)
    assert all(kinds.values()), kinds


def test_a_python_callable_has_no_toml_form():
    p = parse_problem(doc_snippets.minimal())
    varying = lambda t: {"A": np.array([[0.0, 1.0], [-t, 0.0]])}  # noqa: E731
    p = dataclasses.replace(p, stages=tuple(dataclasses.replace(s, varying=varying, origin=None)
                                            for s in p.stages))
    with pytest.raises(ProblemTomlError, match="callable"):
        problem_to_toml(p)


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -float("inf")])
def test_a_number_toml_cannot_hold_is_refused(bad):
    """TOML has nan and inf, a problem file does not: writing one would make a file that the
    reader refuses."""
    p = parse_problem(doc_snippets.minimal())
    x0 = np.array(p.x0, dtype=float)
    x0[-1] = bad
    with pytest.raises(ProblemTomlError, match="not a valid problem-file number"):
        problem_to_toml(dataclasses.replace(p, x0=x0))


def test_gains_as_numpy_arrays(robot_zoh):
    g = robot_zoh.gains()
    t = robot_zoh.table
    n, m, P = t.dims
    assert g.K.shape == (t.n_ticks, m, n) and g.k0.shape == (t.n_ticks, m)
    assert g.L.shape == (t.n_ticks, m, P) and g.t.shape == (t.n_ticks,)
    assert g.Lambda.shape == (t.n_stages, P, n) and g.lambda0.shape == (t.n_stages, P)
    assert g.K.dtype == np.float64
    np.testing.assert_array_equal(g.K, t.K.astype(np.float64))
    assert g.t[0] == robot_zoh.problem.t0 and g.t[1] - g.t[0] == pytest.approx(1e-3)
    exact = robot_zoh.gains(quantized=False)
    assert 0 < np.abs(exact.K - g.K).max() <= 1e-6 * np.abs(exact.K).max()
