"""Generators of hostile inputs for the CLI contract test (`test_hostile_inputs.py`).

A case is a problem document (a dict, written as TOML by `to_toml`) or raw file bytes, plus a
command line. Problem cases start from one of a few small valid problems (`BASES`) and apply
one or more mutations, each from a named class (`MUTATIONS`), so a failure says which class of
input broke the contract. Nothing here runs the tool; the test does.
"""
from __future__ import annotations

import copy
import math
from typing import Any, Callable

from hypothesis import strategies as st

# ---------------------------------------------------------------------------------------
# Valid starting points: small (few ticks) so that a mutation that is accepted designs fast.

CART = {  # the docs' minimal file (noise-free)
    "name": "cart", "x0": [0.0, 0.0], "tick_hz": 10,
    "dynamics": {"A": [[0, 1], [0, 0]], "B": [[0], [1]]},
    "cost": {"R": [[1]]},
    "knots": [{"t": 1.0, "constraint": {"C": [[1, 0]], "value": [1.0]}},
              {"t": 2.0, "constraint": {"C": [[1, 0], [0, 1]], "value": [0.0, 0.0]}}],
}

NOISY = {  # state- and input-multiplicative noise, penalty and constraint, limits, stages
    "name": "di", "t0": 0.0, "x0": [0.5, 0.0], "tick_hz": 20, "u_min": -50.0, "u_max": [50.0],
    "dynamics": {"A": [[0, 1], [0, 0]], "B": [[0], [1]],
                 "noise": [{"state": 1, "G": [[0], [0.3]]}, {"input": 0, "G": [[0], [0.1]]}]},
    "cost": {"Q": [[0.1, 0], [0, 0]], "R": [[1]], "q": [0.0, 0.0], "rho": 0.0},
    "knots": [{"t": 1.0, "penalty": {"C": [[1, 0]], "target": [1.0], "weight": 2.0},
               "constraint": {"C": [[1, 0]], "value": [1.0]}},
              {"t": 2.0, "constraint": {"C": [[1, 0], [0, 1]], "value": [0.0, 0.0]}}],
    "stages": [{"cost": {"R": [[2]]}}, {"dynamics": {"A": [[0, 1], [0, -1]]}}],
}

BANDS = {  # joint mode, band constraints, a region, fixed-point arithmetic
    "name": "band", "x0": [0.0, 0.0], "tick_hz": 10,
    "design": {"mode": "joint", "arith": "q15"},
    "dynamics": {"A": [[0, 1], [0, 0]], "B": [[0], [1]],
                 "noise": [{"state": 0, "G": [[0.1], [0]]}]},
    "cost": {"R": [[1]]},
    "knots": [{"t": 1.0, "constraint": {"C": [[1, 0]], "lower": [0.5], "upper": [1.5]}},
              {"t": 2.0, "constraint": {"C": [[1, 0], [0, 1]], "value": [0.0, 0.0]}}],
    "regions": [{"t": [0.2, 0.8], "every": 0.2, "C": [[0, 1]], "lower": [-3.0], "upper": [3.0]}],
}

VARYING = {  # time-varying samples, tracking
    "name": "tv", "x0": [0.0], "tick_hz": 10,
    "dynamics": {"A": {"t": [0.0, 2.0], "values": [[[0.1]], [[0.3]]]}, "B": [[1]],
                 "noise": [{"state": 0, "G": [[0.2]]}]},
    "cost": {"R": [[1]], "tracking": {"C": [[1]], "weight": [[1]],
                                      "t": [0.0, 2.0], "y0": [[0.0], [1.0]]}},
    "knots": [{"t": 1.0, "constraint": {"C": [[1]], "value": [1.0]}},
              {"t": 2.0, "penalty": {"C": [[1]], "target": [2.0], "weight": 1.0}}],
}

TICK = {  # a region at every tick (constraint generation), active: the speed limit binds
    "name": "tick", "x0": [0.0, 0.0], "tick_hz": 10, "design": {"mode": "joint"},
    "dynamics": {"A": [[0, 1], [0, 0]], "B": [[0], [1]],
                 "noise": [{"state": 1, "G": [[0], [0.2]]}]},
    "cost": {"R": [[1]]},
    "knots": [{"t": 2.0, "constraint": {"C": [[1, 0], [0, 1]], "value": [1.0, 0.0]}}],
    "regions": [{"t": [0.0, 2.0], "every": "tick", "C": [[0, 1]], "lower": [0.0],
                 "upper": [0.7]}],
}

BASES = {"cart": CART, "noisy": NOISY, "bands": BANDS, "varying": VARYING, "tick": TICK}


# ---------------------------------------------------------------------------------------
# TOML writer: inline tables and arrays only, so any dict/list tree is one valid document.

def _key(k: str) -> str:
    bare = k and all(c.isalnum() and c.isascii() or c in "_-" for c in k)
    return k if bare else _string(k)


def _string(s: str) -> str:
    out = []
    for c in s:
        if c in '"\\':
            out.append("\\" + c)
        elif ord(c) < 0x20 or ord(c) == 0x7F:
            out.append(f"\\u{ord(c):04x}")
        else:
            out.append(c)
    return '"' + "".join(out) + '"'


def _value(v: Any) -> str:
    # Iterative for lists nested thousands deep (a recursive writer would overflow first).
    if isinstance(v, list) and v and isinstance(v[0], list) and _depth(v) > 50:
        d = _depth(v)
        inner = v
        for _ in range(d - 1):
            inner = inner[0]
        return "[" * (d - 1) + _value(inner) + "]" * (d - 1)
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return _string(v)
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(type(v))


def _depth(v: Any) -> int:
    d = 0
    while isinstance(v, list) and len(v) == 1:
        d, v = d + 1, v[0]
    return d


def to_toml(doc: dict) -> str:
    """A TOML document for `doc`: one ``key = value`` line per top-level key."""
    return "".join(f"{_key(k)} = {_value(v)}\n" for k, v in doc.items())


# ---------------------------------------------------------------------------------------
# Mutations. Each takes (doc, draw) and edits doc in place; `draw` draws from hypothesis.

def _paths(node: Any, prefix=()) -> list[tuple]:
    """Every path to a value in the document (dict keys and list indices)."""
    out, stack = [], [(node, prefix)]
    while stack:
        cur, p = stack.pop()
        if p:
            out.append(p)
        if isinstance(cur, dict):
            stack.extend((v, p + (k,)) for k, v in cur.items())
        elif isinstance(cur, list) and len(p) < 12:
            stack.extend((v, p + (i,)) for i, v in enumerate(cur))
    return sorted(out, key=repr)


def _get(doc, path):
    for k in path:
        doc = doc[k]
    return doc


def _set(doc, path, value):
    _get(doc, path[:-1])[path[-1]] = value


def _pick_path(doc, draw, want: Callable[[Any], bool] = lambda v: True):
    paths = [p for p in _paths(doc) if want(_get(doc, p))]
    return draw(st.sampled_from(paths)) if paths else None


EXTREME_NUMBERS = [0, -0.0, 1, -1, 1e308, -1e308, 1.7976931348623157e308, 1e300, 1e-300,
                   5e-324, 3.5e38, -3.5e38, 1e39, 2**31, 2**32, 2**63 - 1, -2**63, 10**30,
                   float("nan"), float("inf"), float("-inf"), 0.1, 1e-9]
ODD_VALUES = ["", "1.0", "nan", True, False, {}, [], [[]], [[[1.0]]], {"a": 1}, [1, "x"],
              [None] if False else [1.0, [2.0]]]


def m_extreme_number(doc, draw):
    p = _pick_path(doc, draw, lambda v: isinstance(v, (int, float)) and not isinstance(v, bool))
    if p:
        _set(doc, p, draw(st.sampled_from(EXTREME_NUMBERS)))


def m_wrong_type(doc, draw):
    p = _pick_path(doc, draw)
    if p:
        _set(doc, p, copy.deepcopy(draw(st.sampled_from(ODD_VALUES))))


def m_delete_key(doc, draw):
    p = _pick_path(doc, draw)
    if p:
        parent = _get(doc, p[:-1])
        if isinstance(parent, dict):
            del parent[p[-1]]
        elif len(parent) > 0:
            parent.pop(p[-1])


def m_unknown_key(doc, draw):
    p = _pick_path(doc, draw, lambda v: isinstance(v, dict))
    target = _get(doc, p) if p else doc
    target[draw(st.sampled_from(["Aa", "tick", "weight ", "x0", "é", "constraint", "G"]))] = 1.0


def _copy(v):
    """A deep copy, or `v` itself where it nests deeper than Python's recursion limit (a
    `deep_nesting` value: the duplicate then shares it, which no later mutation minds)."""
    try:
        return copy.deepcopy(v)
    except RecursionError:
        return v


def m_shape(doc, draw):
    """Drop, duplicate or append an element, or wrap/unwrap a value in a list."""
    p = _pick_path(doc, draw, lambda v: isinstance(v, list))
    if not p:
        return
    v = _get(doc, p)
    how = draw(st.sampled_from(["drop", "dup", "append", "wrap", "unwrap", "empty"]))
    if how == "drop" and v:
        v.pop(draw(st.integers(0, len(v) - 1)))
    elif how == "dup" and v:
        v.append(_copy(v[-1]))
    elif how == "append":
        v.append(0.0)
    elif how == "wrap":
        _set(doc, p, [v])
    elif how == "unwrap" and v:
        _set(doc, p, v[0])
    elif how == "empty":
        _set(doc, p, [])


def m_deep_nesting(doc, draw):
    p = _pick_path(doc, draw)
    if p:
        v = _get(doc, p)
        for _ in range(draw(st.sampled_from([40, 300, 1000, 5000]))):
            v = [v]
        _set(doc, p, v)


def m_name(doc, draw):
    doc["name"] = draw(st.sampled_from([
        "", "1abc", "a-b", "double", "int", "main", "harness", "harness_table", "stsp_max",
        "stsp_fixed", "STSP_MAX_NX", "stsp", "stsp_ctrl_t", "_Foo", "__x", "a" * 250, "a" * 64,
        "é", "con", "nul", "x/y", "../evil", ".hidden", "memcpy", "NULL", "errno", "float",
        "uint32_t", "ok_name",
    ]))


def m_dimensions(doc, draw):
    """Sizes at and beyond the firmware's limits: n (x0), m (B columns), stages (knots)."""
    which = draw(st.sampled_from(["n", "m", "stages", "latch"]))
    size = draw(st.sampled_from([16, 17, 32, 33, 64, 200, 300]))
    if which == "n":
        n = size
        doc.clear()
        doc.update({"name": "big", "x0": [0.0] * n, "tick_hz": 10,
                    "dynamics": {"A": [[0.0] * n for _ in range(n)],
                                 "B": [[1.0] if i == 0 else [0.0] for i in range(n)]},
                    "cost": {"R": [[1]]},
                    "knots": [{"t": 1.0, "penalty": {"C": [[1.0] + [0.0] * (n - 1)],
                                                     "target": [1.0], "weight": 1.0}}]})
    elif which == "m":
        doc.clear()
        doc.update({"name": "wide", "x0": [0.0], "tick_hz": 10,
                    "dynamics": {"A": [[0.0]], "B": [[1.0] * size]},
                    "cost": {"R": [[1.0 if i == j else 0.0 for j in range(size)]
                                   for i in range(size)]},
                    "knots": [{"t": 1.0, "constraint": {"C": [[1.0]], "value": [1.0]}}]})
    elif which == "stages":
        doc.pop("stages", None)
        doc.pop("regions", None)
        doc["tick_hz"] = 10
        doc["knots"] = [{"t": 0.1 * (k + 1), "penalty": {"C": [[1] + [0] * (len(doc["x0"]) - 1)],
                                                        "target": [0.0], "weight": 1.0}}
                        for k in range(size)]
    else:  # many constraint rows at one knot: the multiplier width
        n = len(doc["x0"])
        doc["knots"][-1]["constraint"] = {"C": [[1.0] + [0.0] * (n - 1)] * size,
                                          "value": [0.0] * size}


def m_work(doc, draw):
    """Inputs that ask for much work: a high tick rate, long horizons, dense region grids."""
    how = draw(st.sampled_from(["tick_hz", "horizon", "region_grid", "knot_time"]))
    if how == "tick_hz":
        doc["tick_hz"] = draw(st.sampled_from([10**6, 10**8, 10**9, 2**32 - 1, 2**32]))
    elif how == "horizon":
        doc["knots"][-1]["t"] = draw(st.sampled_from([1e5, 1e7, 1e12]))
    elif how == "region_grid":
        doc.setdefault("design", {})["mode"] = "joint"
        doc["tick_hz"] = 100000
        doc["regions"] = [{"t": [0.0, 1.0], "every": 1e-5, "C": [[1] + [0] * (len(doc["x0"]) - 1)],
                           "lower": [-10.0], "upper": [10.0]}]
    else:
        doc["knots"][-1]["t"] = draw(st.sampled_from([1e308, 1e300, 1.7e308, 2.0 ** 70]))


def m_scale(doc, draw):
    """Well-formed numbers that overflow the design or float32: huge weights, states, A."""
    how = draw(st.sampled_from(["Q", "x0", "value", "A", "weight", "R_tiny", "limits"]))
    n = len(doc["x0"])
    big = draw(st.sampled_from([1e30, 1e39, 1e100, 1e300, 1e308]))
    if how == "Q":
        doc["cost"]["Q"] = [[big if i == j else 0.0 for j in range(n)] for i in range(n)]
    elif how == "x0":
        doc["x0"] = [big] + doc["x0"][1:]
    elif how == "value":
        for kn in doc["knots"]:
            if "constraint" in kn and "value" in kn["constraint"]:
                kn["constraint"]["value"] = [big] * len(kn["constraint"]["value"])
    elif how == "A":
        doc["dynamics"]["A"] = [[draw(st.sampled_from([50.0, 800.0, 1e5])) if i == j else 0.0
                                 for j in range(n)] for i in range(n)]
    elif how == "weight":
        for kn in doc["knots"]:
            if "penalty" in kn:
                kn["penalty"]["weight"] = big
    elif how == "R_tiny":
        m = len(doc["dynamics"]["B"][0]) if isinstance(doc["dynamics"]["B"], list) else 1
        doc["cost"]["R"] = [[1e-300 if i == j else 0.0 for j in range(m)] for i in range(m)]
    else:
        doc["u_min"], doc["u_max"] = -big, big


MUTATIONS: dict[str, Callable] = {
    "extreme_number": m_extreme_number,
    "wrong_type": m_wrong_type,
    "delete_key": m_delete_key,
    "unknown_key": m_unknown_key,
    "shape": m_shape,
    "deep_nesting": m_deep_nesting,
    "name": m_name,
    "dimensions": m_dimensions,
    "work": m_work,
    "scale": m_scale,
}


# ---------------------------------------------------------------------------------------
# Row scale: a constraint row ``lower <= c'x <= upper`` (knot constraints, regions, corridor
# walls) means the same for any positive multiple of c and its bounds. Scaled rows must give
# the same design, or, where the scaled numbers cannot be held to full precision (subnormal,
# a bound beyond the range of doubles beside its row), a clean refusal naming the key.

ROW_SCALES = [10.0 ** k for k in (-320, -307, -300, -150, -12, -9, -6, 6, 9, 12, 150, 300, 307)]


def _scale_row(row: list, bounds: list, i: int, f: float) -> None:
    row[:] = [f * c for c in row]
    for b in bounds:
        b[i] *= f


def scale_rows(doc: dict, factor: Callable[[], float]) -> None:
    """Every constraint, region and corridor-wall row of `doc` with its bounds multiplied by
    ``factor()`` (called once per row), in place."""
    for kn in doc.get("knots", []):
        con = kn.get("constraint") if isinstance(kn, dict) else None
        if isinstance(con, dict):
            bounds = [con[k] for k in ("value", "lower", "upper") if k in con]
            for i, row in enumerate(con.get("C", [])):
                _scale_row(row, bounds, i, factor())
    for reg in doc.get("regions", []):
        for i, row in enumerate(reg["C"]):
            _scale_row(row, [reg["lower"], reg["upper"]], i, factor())
    for cor in doc.get("corridors", []):
        for poly in cor["polygons"]:
            for i, row in enumerate(poly["A"]):
                _scale_row(row, [poly["b"]], i, factor())


def m_row_scale(doc, draw):
    """Constraint, region and wall rows scaled by 10^k, |k| up to 320 (one factor per row)."""
    scale_rows(doc, lambda: draw(st.sampled_from(ROW_SCALES)))


MUTATIONS["row_scale"] = m_row_scale



# -- budget_everything: costs outside the tick grid's tables -----------------------------
def m_budget_everything(doc, draw):
    """Inputs whose work is in corridors or in the tick-grid QP: hundreds or thousands of
    corridors, regions at every tick and between ticks at a high tick rate (the QP's sparse
    LU), which the budget must refuse up front or finish."""
    n = len(doc["x0"])
    end = float(doc["knots"][-1]["t"])
    first = [[1.0] + [0.0] * (n - 1)]
    if draw(st.sampled_from(["corridors", "between_ticks"])) == "corridors":
        corridor = {"t": [0.0, end], "C": first,
                    "polygons": [{"A": [[1.0], [-1.0]], "b": [1e6, 1e6]}]}
        doc["corridors"] = [copy.deepcopy(corridor)
                            for _ in range(draw(st.sampled_from([300, 3000])))]
    else:
        doc.setdefault("design", {})["mode"] = "joint"
        doc["tick_hz"] = draw(st.sampled_from([1000, 60000]))
        doc["regions"] = [{"t": [0.0, end], "every": "tick", "C": first, "lower": [-1e3],
                           "upper": [1e3], "between_ticks": True}]


MUTATIONS["budget_everything"] = m_budget_everything

# Outputs and blame: well-formed extremes whose overflow must name them (not knots[0].t),
# and output paths that must be refused before any work (tests: test_hostile_inputs.py,
# "Outputs and blame").

def _blame_edit(doc, how: str) -> None:
    n = len(doc["x0"])
    t_end = float(doc["knots"][-1]["t"])
    if how == "corridor_A":       # a wall row of 1e308 (scaled as read: a valid wall)
        doc["corridors"] = [{"t": [0.0, t_end], "C": [[1.0] + [0.0] * (n - 1)],
                             "polygons": [{"A": [[1e308], [-1.0]], "b": [10.0, 10.0]}]}]
    elif how == "drift":
        doc["dynamics"]["f"] = [1e308] + [0.0] * (n - 1)
    elif how == "varying_sample":  # one sample of B far out, between the stage ends
        B = doc["dynamics"]["B"]
        doc["dynamics"]["B"] = {"t": [0.0, t_end / 3, t_end],
                                "values": [B, [[1e308 * v for v in row] for row in B], B]}
    elif how in ("plant_A_scale", "plant_B_scale", "plant_noise_scale"):
        doc["faults"] = {how: 1000.0}
    elif how == "miss_probability":
        doc["faults"] = {"miss_probability": 0.999999999}


BLAME_KINDS = ["corridor_A", "drift", "varying_sample", "plant_A_scale", "plant_B_scale",
               "plant_noise_scale", "miss_probability"]


def m_blame(doc, draw):
    _blame_edit(doc, draw(st.sampled_from(BLAME_KINDS)))


MUTATIONS["blame"] = m_blame

UNSTABLE = {  # an unstable mode over 20 s: a plant A 1000x the design's overflows the run
    "name": "unstable", "x0": [1.0], "tick_hz": 10,
    "dynamics": {"A": [[0.5]], "B": [[1.0]], "noise": [{"state": 0, "G": [[0.1]]}]},
    "cost": {"R": [[1]]},
    "knots": [{"t": 20.0, "penalty": {"C": [[1]], "target": [0.0], "weight": 1.0}}],
}

# name -> (base, edit, simulate arguments, the field the one-line refusal names; None: the
# run succeeds). "robot" is examples/robot_corridor.toml, its edit `ROBOT_EDITS`.
BLAME_CASES = {
    # A wall row is scaled as read (stospline.problem.rows): 1e308 in it is exact, no overflow.
    "corridor_A_1e308": ("robot", "corridor_A", [], None),
    "drift_1e308": ("noisy", "drift", [], "dynamics.f"),
    "varying_sample_1e308": ("noisy", "varying_sample", [], "dynamics.B.values[1]"),
    "plant_A_scale_1000": ("unstable", "plant_A_scale", ["--substeps", "1"],
                           "faults.plant_A_scale"),
    "plant_noise_scale_1000": ("robot", None, ["--fault", "plant_noise_scale=1000"],
                               "--fault plant_noise_scale"),
    "miss_probability_near_1": ("noisy", "miss_probability", [], None),
}

ROBOT_EDITS = {"corridor_A": ("{ A = [[0, -1], [0, 1], [1, 0]]",
                              "{ A = [[0, -1e308], [0, 1], [1, 0]]")}

# name -> (command, --out value, words of the refusal). Placeholders: {input} the problem
# file itself, {here} its directory, {unwritable} a directory no one can create files in.
OUTPUT_CASES = {
    "design_name_300": ("design", "a" * 300, "longer than"),
    "design_path_4k": ("design", "/".join(["d" * 200] * 21), "longer than"),
    "design_unwritable": ("design", "{unwritable}/out", "not writable"),
    "design_parent_is_input": ("design", "{input}/out", "not a directory"),
    "design_out_holds_input": ("design", "{here}", "input file"),
    "plot_name_300": ("plot", "p" * 300 + ".png", "longer than"),
    "plot_unwritable": ("plot", "{unwritable}/p.png", "not writable"),
    "plot_missing_parent": ("plot", "missing/p.png", "cannot be used"),
    "plot_is_input": ("plot", "{input}", "input file"),
    "report_name_300": ("report", "r" * 300 + ".html", "longer than"),
    "report_path_4k": ("report", "/".join(["d" * 200] * 21) + ".html", "longer than"),
    "report_unwritable": ("report", "{unwritable}/r.html", "not writable"),
    "report_is_input": ("report", "{input}", "input file"),
}


# ---------------------------------------------------------------------------------------
# Measurement: a [measurement] table (the sensor an estimator reads), valid, or with one key
# broken: shapes, non-finite and beyond-float32 entries, covariances that are not symmetric
# or not positive semidefinite, sample periods out of range, noise entries out of range,
# repeated or of mixed widths, unknown keys.

def _sensor(n: int) -> dict:
    return {"C": [[1.0] + [0.0] * (n - 1)], "V": [[1e-4]], "every": 2,
            "noise": [{"state": 0, "D": [[0.01]]}],
            "x0_cov": [[1e-3 if i == j else 0.0 for j in range(n)] for i in range(n)]}


MEASUREMENT_EDITS = {
    "valid": lambda s, n: None,
    "not_a_table": lambda s, n: s.clear() or s.update({"__replace__": [1.0]}),
    "C_columns": lambda s, n: s.update(C=[[1.0] * (n + 1)]),
    "C_zero_row": lambda s, n: s.update(C=[[0.0] * n]),
    "C_nan": lambda s, n: s.update(C=[[float("nan")] + [0.0] * (n - 1)]),
    "C_beyond_float32": lambda s, n: s.update(C=[[1e39] + [0.0] * (n - 1)]),
    "C_too_many_rows": lambda s, n: s.update(C=[[1.0] + [0.0] * (n - 1)] * 40,
                                             V=[[0.0] * 40] * 40),
    "V_missing": lambda s, n: s.pop("V"),
    "V_negative": lambda s, n: s.update(V=[[-1.0]]),
    "V_size": lambda s, n: s.update(V=[[1.0, 0.0], [0.0, 1.0]]),
    "V_inf": lambda s, n: s.update(V=[[float("inf")]]),
    "V_not_psd": lambda s, n: s.update(C=[[1.0] + [0.0] * (n - 1)] * 2,
                                       V=[[1.0, 2.0], [2.0, 1.0]]),
    "V_asymmetric": lambda s, n: s.update(C=[[1.0] + [0.0] * (n - 1)] * 2,
                                          V=[[1.0, 0.5], [0.0, 1.0]]),
    "every_zero": lambda s, n: s.update(every=0),
    "every_float": lambda s, n: s.update(every=2.5),
    "every_huge": lambda s, n: s.update(every=2**32),
    "every_bool": lambda s, n: s.update(every=True),
    "noise_state": lambda s, n: s.update(noise=[{"state": n, "D": [[0.1]]}]),
    "noise_repeated": lambda s, n: s.update(noise=[{"state": 0, "D": [[0.1]]}] * 2),
    "noise_D_rows": lambda s, n: s.update(noise=[{"state": 0, "D": [[0.1], [0.1]]}]),
    "noise_mixed_widths": lambda s, n: s.update(noise=[{"state": 0, "D": [[0.1]]},
                                                       {"state": n - 1, "D": [[0.1, 0.2]]}]),
    "noise_not_list": lambda s, n: s.update(noise={"state": 0, "D": [[0.1]]}),
    "noise_unknown_key": lambda s, n: s.update(noise=[{"state": 0, "G": [[0.1]]}]),
    "x0_cov_not_psd": lambda s, n: s.update(x0_cov=[[-1.0 if i == j else 0.0 for j in range(n)]
                                                    for i in range(n)]),
    "x0_cov_shape": lambda s, n: s.update(x0_cov=[[1.0]] if n > 1 else [[1.0, 0.0]]),
    "x0_cov_huge": lambda s, n: s.update(x0_cov=[[1e39 if i == j else 0.0 for j in range(n)]
                                                 for i in range(n)]),
    "unknown_key": lambda s, n: s.update(R=[[1.0]]),
}


def m_measurement(doc, draw):
    n = len(doc["x0"])
    sensor = _sensor(n)
    MEASUREMENT_EDITS[draw(st.sampled_from(sorted(MEASUREMENT_EDITS)))](sensor, n)
    doc["measurement"] = sensor.get("__replace__", sensor)


MUTATIONS["measurement"] = m_measurement


# ---------------------------------------------------------------------------------------
# Parameters: a [[parameters]] array (runtime parameters set on the device), valid, or with
# one entry broken: not an array, names, paths that are junk, missing, out of range, band
# limits or tracking paths, a value set twice, ranges that are empty, non-finite, beyond
# float32 or miss the nominal, unknown keys, too many entries. Bases with bands refuse any.

def _parameter(doc: dict) -> dict:
    x = float(doc["x0"][0])
    return {"name": "p0", "sets": ["x0[0]"], "range": [x - 1.0, x + 1.0]}


PARAMETER_EDITS = {
    "valid": lambda ps, d: None,
    "not_array": lambda ps, d: ps.clear() or ps.append("__replace__"),
    "empty": lambda ps, d: ps.clear(),
    "entry_not_table": lambda ps, d: ps.__setitem__(0, 1.5),
    "name_not_identifier": lambda ps, d: ps[0].update(name="p 0"),
    "name_repeated": lambda ps, d: ps.append({**ps[0], "name": "P0", "sets": ["x0[0]"]}),
    "sets_not_array": lambda ps, d: ps[0].update(sets="x0[0]"),
    "sets_junk": lambda ps, d: ps[0].update(sets=["x0[0]]]"]),
    "sets_not_string": lambda ps, d: ps[0].update(sets=[[0]]),
    "sets_index_beyond": lambda ps, d: ps[0].update(sets=[f"x0[{len(d['x0'])}]"]),
    "sets_knot_beyond": lambda ps, d: ps[0].update(sets=["knots[9].penalty.target[0]"]),
    "sets_band_limit": lambda ps, d: ps[0].update(sets=["knots[0].constraint.upper[0]"]),
    "sets_tracking": lambda ps, d: ps[0].update(sets=["cost.tracking.y0[0][0]"]),
    "sets_weight": lambda ps, d: ps[0].update(sets=["knots[0].penalty.weight"]),
    "sets_absent_drift": lambda ps, d: ps[0].update(sets=["dynamics.f[0]"]),
    "set_twice": lambda ps, d: ps[0].update(sets=["x0[0]", "x0[0]"]),
    "range_nan": lambda ps, d: ps[0].update(range=[float("nan"), 1.0]),
    "range_inf": lambda ps, d: ps[0].update(range=[0.0, float("inf")]),
    "range_reversed": lambda ps, d: ps[0].update(range=ps[0]["range"][::-1]),
    "range_misses_nominal": lambda ps, d: ps[0].update(range=[1e3, 2e3]),
    "range_beyond_float32": lambda ps, d: ps[0].update(range=[-1e39, 1e39]),
    "range_string": lambda ps, d: ps[0].update(range=["0", "1"]),
    "range_three": lambda ps, d: ps[0].update(range=[0.0, 1.0, 2.0]),
    "unknown_key": lambda ps, d: ps[0].update(nominal=0.0),
    "missing_sets": lambda ps, d: ps[0].pop("sets"),
    "too_many": lambda ps, d: ps.extend({**ps[0], "name": f"q{i}"} for i in range(40)),
}


def parameters_doc(doc: dict, edit: str) -> dict:
    """`doc` with a [[parameters]] array broken by `edit` (a key of PARAMETER_EDITS)."""
    params = [_parameter(doc)]
    PARAMETER_EDITS[edit](params, doc)
    doc["parameters"] = 7 if params == ["__replace__"] else params
    return doc


def m_parameters(doc, draw):
    parameters_doc(doc, draw(st.sampled_from(sorted(PARAMETER_EDITS))))


MUTATIONS["parameters"] = m_parameters

# ---------------------------------------------------------------------------------------
# Sensor loop: `simulate` of a problem with [measurement] runs the law on the filter's
# estimate through the compiled C; what that loop does not run is refused with exit status 2,
# one line naming the option or the file's key, nothing on stdout or disk. Each case is
# (base, edit of the document with a sensor, extra arguments, the field named); a field of
# None: the control case, accepted.

SENSOR_SIMULATE_CASES = {
    "valid": ("noisy", {}, [], None),
    "faults_in_file": ("noisy", {"faults": {"delay_ticks": 1}}, [], "faults.delay_ticks"),
    "quantum_in_file": ("noisy", {"faults": {"sensor_quantum": 0.01}}, [],
                        "faults.sensor_quantum"),
    "fault_option": ("noisy", {}, ["--fault", "delay_ticks=1"], "--fault"),
    "faults": ("noisy", {"faults": {"actuator_noise": 0.1, "sensor_noise": 0.01,
                                    "plant_B_scale": 0.9, "miss_probability": 0.1}}, [], None),
    "x0_option": ("noisy", {}, ["--x0=0.1,0"], "--x0"),
    "scheduler_option": ("noisy", {}, ["--scheduler", "local"], "--scheduler"),
    "paths_beyond_memory": ("noisy", {}, ["--paths", str(10**7 + 1)], "--paths"),
    "delay_option": ("noisy", {}, ["--delay-ticks", "1"], "--delay-ticks"),
    "delay_in_file": ("noisy", {"design": {"delay_ticks": 1}}, [], "design.delay_ticks"),
    # A spline table runs: the law's spline and the filter's gain spline (stsp_est_init_spline).
    "spline_in_file": ("noisy", {"design": {"table": "spline"}}, [], None),
    "q15_in_file": ("noisy", {"design": {"arith": "q31"}}, [], "design.arith"),
    "time_varying": ("varying", {}, ["--substeps", "1"], None),
    "varying_V": ("noisy", {"measurement": {"C": [[1.0, 0.0]], "every": 2, "V": {
        "t": [0.0, 1.0], "values": [[[1e-2]], [[1e-4]]]}}}, [], None),
    "varying_C": ("noisy", {"measurement": {"V": [[1e-4]], "every": 2, "C": {
        "t": [0.0, 1.0], "values": [[[1.0, 0.0]], [[1.0, 0.1]]]}}}, [], "measurement.C"),
    "band_latch": ("bands", {"design": {"mode": "joint"}}, [], "knots"),
}


def sensor_simulate_doc(name: str) -> tuple[dict, list[str], str | None]:
    """The problem document, extra arguments and expected field of a sensor-loop case."""
    base, edit, extra, field = SENSOR_SIMULATE_CASES[name]
    doc = copy.deepcopy(BASES[base])
    n = len(doc["x0"])
    doc["measurement"] = {"C": [[1.0] + [0.0] * (n - 1)], "V": [[1e-4]], "every": 2}
    doc.update(copy.deepcopy(edit))
    return doc, list(extra), field


# Plant: a [plant] table (a nonlinear model in C, `stospline.nonlinear`) on the noisy double
# integrator written in C, valid or broken: the table's keys (missing, wrong types, out of
# range, unknown, [dynamics] beside it), the model file (absent, a directory, not text) and
# the C (each of `support.plant_sources.BROKEN`). Each case is refused naming its field, by
# `tests/python/nonlinear/test_plant_sources.py`; "valid" designs.

def _plant_table(p: dict, **edits) -> None:
    p.update(edits)


PLANT_EDITS = {
    "valid": (lambda d, f: None, None),
    "not_table": (lambda d, f: d.__setitem__("plant", 3), "plant"),
    "source_missing": (lambda d, f: d["plant"].pop("source"), "plant.source"),
    "source_not_string": (lambda d, f: _plant_table(d["plant"], source=5), "plant.source"),
    "source_absent": (lambda d, f: _plant_table(d["plant"], source="nowhere.c"),
                      "plant.source"),
    "source_directory": (lambda d, f: _plant_table(d["plant"], source="."), "plant.source"),
    "source_not_text": (lambda d, f: f.__setitem__("model.c", "int x = 0; /* \u00e9 */\n"),
                        "plant.source"),
    "params_string": (lambda d, f: _plant_table(d["plant"], params="0.3"), "plant.params"),
    "params_count": (lambda d, f: _plant_table(d["plant"], params=[0.3, 1.0]),
                     "plant.params"),
    "params_huge": (lambda d, f: _plant_table(d["plant"], params=[1e308]), "plant"),
    "tolerance_zero": (lambda d, f: _plant_table(d["plant"], tolerance=0.0),
                       "plant.tolerance"),
    "tolerance_string": (lambda d, f: _plant_table(d["plant"], tolerance="1e-6"),
                         "plant.tolerance"),
    "max_iterations_zero": (lambda d, f: _plant_table(d["plant"], max_iterations=0),
                            "plant.max_iterations"),
    "guess_t_decreasing": (lambda d, f: _plant_table(
        d["plant"], guess={"t": [2.0, 0.0], "x": [[0.5, 0.0], [0.0, 0.0]]}), "plant.guess.t"),
    "guess_x_shape": (lambda d, f: _plant_table(
        d["plant"], guess={"t": [0.0, 2.0], "x": [[0.5], [0.0]]}), "plant.guess.x"),
    "guess_u_columns": (lambda d, f: _plant_table(
        d["plant"], guess={"t": [0.0, 2.0], "x": [[0.5, 0.0], [0.0, 0.0]],
                           "u": [[0.0, 0.0], [0.0, 0.0]]}), "plant.guess.u"),
    "unknown_key": (lambda d, f: _plant_table(d["plant"], n_noise=1), "plant.n_noise"),
    "x0_missing": (lambda d, f: d.pop("x0"), "x0"),
    "x0_not_array": (lambda d, f: d.__setitem__("x0", 0.5), "x0"),
    "x0_length": (lambda d, f: d.__setitem__("x0", [0.5, 0.0, 0.0]), "plant.source"),
    "with_dynamics": (lambda d, f: d.__setitem__("dynamics", {"A": [[0, 1], [0, 0]],
                                                              "B": [[0], [1]]}), "dynamics"),
    "stage_dynamics": (lambda d, f: d.__setitem__("stages", [
        {"dynamics": {"A": [[0, 1], [0, 0]]}}, {}]), "stages[0].dynamics"),
}


def plant_case(edit: str) -> tuple[dict, dict, str | None]:
    """``(files, doc, field)``: the files beside the problem (name -> text), the problem
    document and the field its refusal names (None: valid) of a key of PLANT_EDITS or of
    `support.plant_sources.BROKEN` (``"c:" + key``)."""
    from support.plant_sources import BROKEN, LINEAR, linear_doc
    files, doc = {"model.c": LINEAR}, linear_doc()
    if edit.startswith("c:"):
        files["model.c"] = BROKEN[edit[2:]][0]
        return files, doc, "plant.source" if edit != "c:dims_params" else "plant.params"
    how, field = PLANT_EDITS[edit]
    how(doc, files)
    return files, doc, field

# Board and HIL: options, files and serial peers of `stospline board` and `stospline hil`.
# Each case is refused with exit status 2, one line naming the option (or key) and nothing on
# disk; `None` instead of the words: the control case, accepted. The test's placeholders:
#   {problem} NOISY as a file   {delayed} NOISY with [design] delay_ticks = 1
#   {faulty}  NOISY with [faults]   {file} a regular file   {dir} a directory
#   {fifo}    a named pipe      {text} a text file named .elf   {elf64} an x86-64 ELF header
#   {arm_stub} an ARM ELF header with nothing to load (QEMU starts and gives up; needs QEMU)
#   {closed}  tcp: to a port nobody listens on
#   {peer:NAME} tcp: to a fake board that sends BOARD_PEERS[NAME] (None: hangs up at once)
# The hil cases that get past the options to the serial line say --paths 2 (a short reference
# run of the host-compiled controller first); the test runs those in a child process.

def _hello(crc32: int, payload_len: int = 29) -> bytes:
    """A HELLO frame from a float32 board with NOISY's shape (nx 2, nu 1, 40 ticks at 20 Hz),
    stepping one path a frame."""
    import struct
    from stospline.board import frames
    payload = struct.pack("<BBBBIIIbbBBIIB", frames.PROTOCOL, 0, 2, 1, 40, 20, crc32, 0, 0, 1,
                          1, 168_000_000, 8_400_000, 1)
    return frames.encode(frames.HELLO, 0, payload[:payload_len])


def _short_command(crc32: int) -> bytes:
    """The right table's HELLO (to QUERY, then to RESET), then a COMMAND of 2 bytes."""
    from stospline.board import frames
    return _hello(crc32) + _hello(crc32) + frames.encode(frames.COMMAND, 1, b"\x00\x00")


# name -> what the fake board sends: bytes, None (hangs up), or a function of the CRC-32 of
# NOISY's float32 table (a board that runs the right table).
BOARD_PEERS = {
    "hangup": None,
    "garbage": bytes(range(256)) * 4,                   # no frame: the 5 s timeout
    "short_hello": _hello(0, 28),                       # a HELLO of the wrong length
    "other_table": _hello(0xDEADBEEF),                  # another table's CRC
    "short_command": _short_command,
}


def arm_stub_elf() -> bytes:
    """An ELF header for 32-bit little-endian ARM (e_machine 40) with no program headers."""
    import struct
    return (b"\x7fELF" + bytes((1, 1, 1, 0)) + bytes(8)
            + struct.pack("<HHIIIIIHHHHHH", 2, 40, 1, 0x08000001, 0, 0, 0x05000400, 52, 0, 0,
                          0, 0, 0))


_B = ["--board", "netduinoplus2"]
BOARD_CASES = {
    "board_valid": (["board", "{problem}", *_B, "--out", "o"], None),
    "board_unknown": (["board", "{problem}", "--board", "nope", "--out", "o"], "--board"),
    "board_none": (["board", "{problem}", "--out", "o"], "--board"),
    "board_out_file": (["board", "{problem}", *_B, "--out", "{file}"], "--out"),
    "board_out_under_file": (["board", "{problem}", *_B, "--out", "{file}/sub"], "--out"),
    "board_out_is_problem": (["board", "{problem}", *_B, "--out", "{problem}"], "--out"),
    "board_out_empty": (["board", "{problem}", *_B, "--out", ""], "--out"),
    "board_out_proc": (["board", "{problem}", *_B, "--out", "/proc/forbidden/x"], "--out"),
    "board_arith": (["board", "{problem}", *_B, "--out", "o", "--arith", "q7"], "--arith"),
    "board_timeout_zero": (["board", "{problem}", *_B, "--out", "o", "--timeout-ticks", "0"],
                           "--timeout-ticks"),
    "board_verify_float": (["board", "{problem}", *_B, "--out", "o", "--verify-ticks", "1e3"],
                           "--verify-ticks"),
    "board_delay_option": (["board", "{problem}", *_B, "--out", "o", "--delay-ticks", "1"],
                           "--delay-ticks"),
    "board_delay_in_file": (["board", "{delayed}", *_B, "--out", "o"], "design.delay_ticks"),
    "board_problem_dir": (["board", "{dir}", *_B, "--out", "o"], "not a problem file"),
    "board_problem_missing": (["board", "missing.toml", *_B, "--out", "o"], "missing.toml"),
    "hil_unknown": (["hil", "{problem}", "--board", "nope", "--port", "{closed}"], "--board"),
    "hil_no_line": (["hil", "{problem}", *_B], "--elf --port"),
    "hil_both_lines": (["hil", "{problem}", *_B, "--port", "{closed}", "--elf", "{arm_stub}"],
                       "--elf: not allowed with argument --port"),
    "hil_paths_one": (["hil", "{problem}", *_B, "--port", "{closed}", "--paths", "1"],
                      "--paths"),
    "hil_paths_513": (["hil", "{problem}", *_B, "--port", "{closed}", "--paths", "513"],
                      "--paths"),
    "hil_seed": (["hil", "{problem}", *_B, "--port", "{closed}", "--seed", "-1"], "--seed"),
    "hil_substeps": (["hil", "{problem}", *_B, "--port", "{closed}", "--substeps", "0"],
                     "--substeps"),
    "hil_arith": (["hil", "{problem}", *_B, "--port", "{closed}", "--arith", "q7"], "--arith"),
    "hil_faults": (["hil", "{faulty}", *_B, "--port", "{closed}"], "faults"),
    "hil_elf_missing": (["hil", "{problem}", *_B, "--elf", "missing.elf"], "--elf"),
    "hil_elf_dir": (["hil", "{problem}", *_B, "--elf", "{dir}"], "--elf"),
    "hil_elf_dev_zero": (["hil", "{problem}", *_B, "--elf", "/dev/zero"], "--elf"),
    "hil_elf_text": (["hil", "{problem}", *_B, "--elf", "{text}"], "--elf"),
    "hil_elf_x86_64": (["hil", "{problem}", *_B, "--elf", "{elf64}"], "--elf"),
    "hil_elf_nothing_to_load": (["hil", "{problem}", *_B, "--elf", "{arm_stub}", "--paths", "2"],
                                "--elf"),
    "hil_port_missing": (["hil", "{problem}", *_B, "--port", "/dev/nonexistent-tty"], "--port"),
    "hil_port_empty": (["hil", "{problem}", *_B, "--port", ""], "--port"),
    "hil_port_file": (["hil", "{problem}", *_B, "--port", "{file}"], "--port"),
    "hil_port_fifo": (["hil", "{problem}", *_B, "--port", "{fifo}"], "--port"),
    "hil_port_not_a_tty": (["hil", "{problem}", *_B, "--port", "/dev/null", "--paths", "2"],
                           "--port"),
    "hil_port_tcp_letters": (["hil", "{problem}", *_B, "--port", "tcp:127.0.0.1:x"], "--port"),
    "hil_port_tcp_range": (["hil", "{problem}", *_B, "--port", "tcp::99999"], "--port"),
    "hil_port_tcp_zero": (["hil", "{problem}", *_B, "--port", "tcp::0"], "--port"),
    "hil_port_tcp_bare": (["hil", "{problem}", *_B, "--port", "tcp:"], "--port"),
    "hil_port_tcp_space": (["hil", "{problem}", *_B, "--port", "tcp:a b:80"], "--port"),
    "hil_port_refused": (["hil", "{problem}", *_B, "--port", "{closed}", "--paths", "2"],
                         "--port"),
    "hil_peer_hangup": (["hil", "{problem}", *_B, "--port", "{peer:hangup}", "--paths", "2"],
                        "--port"),
    "hil_peer_garbage": (["hil", "{problem}", *_B, "--port", "{peer:garbage}", "--paths", "2"],
                         "--port"),
    "hil_peer_short_hello": (["hil", "{problem}", *_B, "--port", "{peer:short_hello}",
                              "--paths", "2"], "--port"),
    "hil_peer_other_table": (["hil", "{problem}", *_B, "--port", "{peer:other_table}",
                              "--paths", "2"], "--board"),
    "hil_peer_short_command": (["hil", "{problem}", *_B, "--port", "{peer:short_command}",
                                "--paths", "2"], "--port: a frame from the board too short"),
}


@st.composite
def problem_cases(draw):
    """(classes, base name, TOML text): a base problem with 1-2 mutations applied."""
    base = draw(st.sampled_from(sorted(BASES)))
    doc = copy.deepcopy(BASES[base])
    classes = draw(st.lists(st.sampled_from(sorted(MUTATIONS)), min_size=1, max_size=2))
    for cls in classes:
        try:
            MUTATIONS[cls](doc, draw)
        except (TypeError, KeyError, IndexError, AttributeError, ValueError):
            pass   # an earlier mutation removed what this one edits: the document stays hostile
    return tuple(classes), base, to_toml(doc)
