"""A row ``lower <= c'x <= upper`` means the same for any positive multiple of ``c`` and its
bounds: knot constraints, regions (every tick and on a grid) and corridor walls scaled by any
factor in the accepted range give the same design and the same corridor figures, and a row that
cannot be represented to full precision is refused naming its key
(`stospline.problem.rows`; docs/guide/problem-file.md, "Rows: their scale")."""
import copy
import json

import numpy as np
import pytest

from stospline.cli import main
from stospline.pipeline import design_problem
from stospline.problem import parse_problem
from stospline.harness.controller import build_controller
from stospline.oracle.exit_bound import corridor_outputs, exit_bounds
from stospline.harness.montecarlo import simulate

# The guide's minimal cart with velocity noise, in joint mode, its speed within +-1.2 at every
# tick: the band binds (J0 32 against 24.24 without it).
CART = {
    "name": "cart", "x0": [0.0, 0.0], "tick_hz": 10, "design": {"mode": "joint"},
    "dynamics": {"A": [[0, 1], [0, 0]], "B": [[0], [1]],
                 "noise": [{"state": 1, "G": [[0], [0.3]]}]},
    "cost": {"R": [[1]]},
    "knots": [{"t": 1.0, "constraint": {"C": [[1, 0]], "value": [1.0]}},
              {"t": 2.0, "constraint": {"C": [[1, 0], [0, 1]], "value": [0.0, 0.0]}}],
    "regions": [{"t": [0.0, 2.0], "every": "tick", "C": [[0, 1]], "lower": [-1.2],
                 "upper": [1.2]}],
}
# Scales of the rows: 10^k for |k| <= 12 and the ends of the accepted range (any normal
# double: a row's largest coefficient from 2.2e-308 to 1.8e308).
SCALES = [10.0 ** k for k in range(-12, 13, 3)] + [1e-300, 3e-308, 1e300, 1e307]


def scaled_rows(doc: dict, s: float, which: str) -> dict:
    """`doc` with the rows of `which` ("region", "knot", "grid") multiplied by `s`."""
    doc = copy.deepcopy(doc)
    if which == "knot":
        for kn in doc["knots"]:
            con = kn["constraint"]
            con["C"] = [[s * c for c in row] for row in con["C"]]
            con["value"] = [s * v for v in con["value"]]
        return doc
    if which == "grid":
        doc["regions"][0]["every"] = 0.2
    reg = doc["regions"][0]
    reg["C"] = [[s * c for c in row] for row in reg["C"]]
    reg["lower"], reg["upper"] = [s * v for v in reg["lower"]], [s * v for v in reg["upper"]]
    return doc


def designed(doc: dict):
    """The design of `doc` in its file's mode, as `stospline design` runs it."""
    p = parse_problem(doc)
    return design_problem(p, mode=p.options.get("mode", "stagewise"))


def assert_same_design(a, b):
    assert b.design.J0 == pytest.approx(a.design.J0, rel=1e-9, abs=0)
    for key in ("K", "k0", "L", "Lambda"):
        x, y = getattr(a.table, key), getattr(b.table, key)
        assert x.shape == y.shape, key
        np.testing.assert_allclose(y, x, rtol=0, atol=1e-9 * max(1.0, np.abs(x).max()),
                                   err_msg=key)


@pytest.fixture(scope="module")
def reference():
    return {which: designed(scaled_rows(CART, 1.0, which))
            for which in ("region", "knot", "grid")}


def test_the_band_binds(reference):
    """The reference is not a trivial case: the region moves the design."""
    free = copy.deepcopy(CART)
    free.pop("regions")
    assert reference["region"].design.J0 > designed(free).design.J0 + 5


@pytest.mark.parametrize("which", ["region", "knot", "grid"])
@pytest.mark.parametrize("s", SCALES, ids=[f"{s:g}" for s in SCALES])
def test_scaled_rows_give_the_same_design(reference, which, s):
    assert_same_design(reference[which], designed(scaled_rows(CART, s, which)))


def test_rows_are_kept_bit_for_bit_when_their_largest_coefficient_is_in_1_2():
    doc = copy.deepcopy(CART)
    doc["knots"][0]["constraint"] = {"C": [[1.5, -0.25]], "value": [0.7]}
    kn = parse_problem(doc).knots[0]
    assert kn.constraint.C.tolist() == [[1.5, -0.25]] and kn.constraint.value.tolist() == [0.7]


# A corridor on the position, y <= 1 and y >= -0.2, one wall scaled: the same exits for the
# same seed and the same analytic bounds.
def corridor_cart(s: float) -> dict:
    doc = copy.deepcopy(CART)
    doc.pop("regions")
    doc["design"] = {"mode": "stagewise"}
    doc["corridors"] = [{"t": [0.0, 2.0], "C": [[1, 0]],
                         "polygons": [{"A": [[s], [-1]], "b": [s, 0.2]}]}]
    return doc


def corridor_figures(s: float):
    p = parse_problem(corridor_cart(s))
    d = design_problem(p)
    mc = simulate(p, build_controller(d.table), paths=2000, seed=7, substeps=1, workers=1,
                  per_path=True)
    ((ym, yc),) = corridor_outputs(p, d.table)
    return mc, exit_bounds(p.corridors[0], ym, yc, p.t0, p.tick_hz)


@pytest.fixture(scope="module")
def corridor_reference():
    return corridor_figures(1.0)


@pytest.mark.parametrize("s", [1e-12, 1e-6, 1e6, 1e12, 1e-200, 1e-300, 1e300],
                         ids=lambda s: f"{s:g}")
def test_a_scaled_wall_gives_the_same_exits_and_bounds(corridor_reference, s):
    ref_mc, ref_b = corridor_reference
    assert (ref_mc.exit_wall[0] == 0).sum() > 50     # the scaled wall is crossed
    mc, b = corridor_figures(s)
    np.testing.assert_array_equal(mc.exit_tick, ref_mc.exit_tick)
    np.testing.assert_array_equal(mc.exit_wall, ref_mc.exit_wall)
    for kind in ("cantelli", "gaussian"):
        np.testing.assert_allclose(b[kind].per_wall, ref_b[kind].per_wall, rtol=1e-12)
        assert b[kind].per_wall[0] > 1.0 if kind == "cantelli" else True


def _value(v) -> str:
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {_value(x)}" for k, x in v.items()) + "}"
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    return json.dumps(v) if isinstance(v, str) else repr(v)


def _toml(doc: dict) -> str:
    """`doc` as TOML: one ``key = value`` line per top-level key, inline tables below."""
    return "".join(f"{k} = {_value(v)}\n" for k, v in doc.items())


def _set_region(doc, C, lo, hi):
    doc["regions"][0].update(C=C, lower=lo, upper=hi)


REFUSED = [
    # (id, edit of CART, the key named)
    ("region subnormal", lambda d: _set_region(d, [[0, 1e-320]], [-1.2e-320], [1.2e-320]),
     "regions[0].C[0][1]"),
    ("knot subnormal", lambda d: d["knots"][0]["constraint"].update(C=[[5e-324, 0]]),
     "knots[0].constraint.C[0][0]"),
    ("bound subnormal", lambda d: _set_region(d, [[0, 1]], [-1e-310], [1.2]),
     "regions[0].lower[0]"),
    ("wall subnormal", lambda d: d.update(corridors=[{
        "t": [0.0, 2.0], "C": [[1, 0]], "polygons": [{"A": [[1e-320], [-1]],
                                                      "b": [1e-320, 0.2]}]}]),
     "corridors[0].polygons[0].A[0][0]"),
    ("row wider than doubles", lambda d: _set_region(d, [[1e-300, 1e300]], [-1.0], [1.0]),
     "regions[0].C[0][0]"),
    ("bound overflows its row", lambda d: _set_region(d, [[0, 1e-200]], [-1.0], [1e200]),
     "regions[0].upper[0]"),
    ("bound underflows its row", lambda d: d["knots"][0]["constraint"].update(
        C=[[1e200, 0]], value=[1e-200]), "knots[0].constraint.value[0]"),
    ("corridor output too large", lambda d: d.update(corridors=[{
        "t": [0.0, 2.0], "C": [[1e200, 0]], "polygons": [{"A": [[1]], "b": [1.0]}]}]),
     "corridors[0].C[0]"),
]


@pytest.mark.parametrize("change, key", [c[1:] for c in REFUSED], ids=[c[0] for c in REFUSED])
def test_unrepresentable_rows_are_refused_naming_the_key(tmp_path, capsys, change, key):
    doc = copy.deepcopy(CART)
    change(doc)
    path = tmp_path / "bad.toml"
    path.write_text(_toml(doc))
    out = tmp_path / "out"
    assert main(["design", str(path), "--out", str(out)]) == 2
    cap = capsys.readouterr()
    assert cap.out == "" and cap.err.count("\n") == 1
    assert cap.err.startswith(f"stospline: error in {path}: {key}: "), cap.err
    assert not out.exists()
