"""Write a `Problem` back as a TOML problem file: ``parse(problem_to_toml(p))`` equals ``p``.

What is written (``docs/guide/library.md``, "Writing a problem back"):

* every stage's data as constant arrays; time-varying data read from a file (samples with
  their interpolation, a tracking cost) as the same samples. Time-varying data given as a
  Python callable (``Stage.varying`` set by hand) has no TOML form: `ProblemTomlError`.
* a tracking cost on a constant stage is written folded into ``Q``, ``q`` and ``rho`` (what it
  adds to them), which is the same problem;
* ``[[regions]]`` are written as the band knots they expand to, which is the same problem;
  a region with ``every = "tick"`` (`TickRegion`) as itself;
* equal stages once as ``[dynamics]``/``[cost]``, different ones as ``[[stages]]``;
* ``x0``, ``t0``, ``tick_hz``, actuator limits, ``[design]``, ``[plot]``, ``[faults]``,
  ``[measurement]`` and ``[[corridors]]`` as they are;
* ``[[parameters]]`` with their paths in the file as written; a constraint row a parameter
  sets is written in the units the parameter has (the reader scales it again).

Floats are written as Python's shortest repr, which reads back to the same double; NaN and
infinities are refused (a problem file cannot hold them).

Why our own serializer and not tomli-w: tomli-w writes every array element on a line of its
own, so a matrix loses its rows. On the examples' documents (``tools/bench/toml_writer.py``,
tomli-w 1.2.0) its text is 1.4-2.5x the bytes and 4-29x the lines of ours (coupled_axes: 102
lines of one key each, a matrix on one line, against 2 959 lines of one number each); both
parse back to the same document. People read and diff these files (``stospline
corridor-design`` writes ``<name>.toml`` beside its tables), and a problem built in Python
carries the SHA-256 of this text in its tables' header. The serializer is the 30 lines of
`_value` and `_table`.
"""
from __future__ import annotations

import json
import math
import re
from typing import Any

import numpy as np

from stospline.problem.series import Series
from stospline.errors import StosplineError

# `Problem` and `Stage` (stospline.problem.model) are annotations only: the model calls this
# module (Problem.to_toml), so importing it here, even for type checking, would be a cycle.

__all__ = ["problem_to_toml", "document_to_toml", "ProblemTomlError"]


class ProblemTomlError(StosplineError, ValueError):
    """The problem holds something a problem file cannot say (a Python callable)."""


def _value(v: Any) -> str:
    """One TOML value on one line."""
    if isinstance(v, np.ndarray):
        v = v.tolist()
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ProblemTomlError(f"{v} is not a valid problem-file number")
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)           # a JSON string is a valid TOML basic string
    if isinstance(v, Series):
        return _value({"t": v.t, "values": v.values, "interpolation": v.interpolation})
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {_value(x)}" for k, x in v.items()) + " }"
    raise ProblemTomlError(f"cannot write a {type(v).__name__} to a problem file")


def _table(header: str, items: dict) -> list[str]:
    return ["", header] + [f"{k} = {_value(v)}" for k, v in items.items()]


def _noise_of_arrays(stage: Stage, mz: int) -> list[dict]:
    n = stage.A.shape[0]
    out: list[dict] = [{"state": i, "G": stage.G[i]} for i in range(n) if np.any(stage.G[i])]
    if stage.H is not None:
        inputs = [j for j in range(stage.H.shape[0]) if np.any(stage.H[j])]
        # An all-zero H still makes the stage carry input noise terms: keep one entry.
        out += [{"input": j, "G": stage.H[j]} for j in inputs or [0]]
    if not out and mz != 1:
        out = [{"state": 0, "G": np.zeros((n, mz))}]   # keeps the number of components mz
    return out


def _stage_tables(stage: Stage, k: int, mz: int) -> tuple[dict, dict]:
    """``(dynamics, cost)`` tables of one stage."""
    if stage.varying is None:
        dyn = {"A": stage.A, "B": stage.B, "noise": _noise_of_arrays(stage, mz)}
        if stage.f is not None:
            dyn["f"] = stage.f
        cost = {"Q": stage.Q, "S": stage.S, "R": stage.R, "q": stage.q, "r": stage.r,
                "rho": float(stage.rho)}
        return dyn, cost
    origin = stage.origin
    if origin is None:
        raise ProblemTomlError(f"stage {k} has time-varying data given as a Python callable, "
                               f"which a problem file cannot hold; give samples instead")
    n = stage.A.shape[0]
    f = origin.fields
    dyn = {"A": f["A"], "B": f["B"],
           "noise": [{"state": i, "G": g} if i < n else {"input": i - n, "G": g}
                     for i, g, _ in origin.noise]}
    if "f" in f:
        dyn["f"] = f["f"]
    cost = {key: f[key] for key in ("Q", "S", "R", "q", "r", "rho")}
    if origin.tracking is not None:
        C, Qy, y0 = origin.tracking
        cost["tracking"] = {"C": C, "weight": Qy, "t": y0.t, "y0": y0.values,
                            "interpolation": y0.interpolation}
        if origin.tracking_offset is not None and np.any(origin.tracking_offset):
            cost["tracking"]["offset"] = origin.tracking_offset
    return dyn, cost


def _same(a: Stage, b: Stage) -> bool:
    if a is b:
        return True
    if a.varying is not None or b.varying is not None:
        return False
    if (a.H is None) != (b.H is None) or (a.f is None) != (b.f is None):
        return False
    if a.f is not None and not np.array_equal(a.f, b.f):
        return False
    return all(np.array_equal(getattr(a, f), getattr(b, f))
               for f in ("A", "B", "G", "Q", "S", "R", "q", "r", "rho")) and (
        a.H is None or np.array_equal(a.H, b.H))


def _knot(kn, row_scale: dict | None = None) -> dict:
    """A knot's table; `row_scale` (row -> power of two) writes those constraint rows back
    in the units a runtime parameter sets them in (the reader scales them again, exactly)."""
    out: dict = {"t": float(kn.t)}
    if kn.penalty is not None:
        p = kn.penalty
        out["penalty"] = {"C": p.C, "target": p.target, "weight": float(p.weight)}
    if kn.constraint is not None:
        c = kn.constraint
        out["constraint"] = ({"C": c.C, "value": c.value} if c.value is not None
                             else {"C": c.C, "lower": c.lower, "upper": c.upper})
        if row_scale and c.value is not None:
            C, value = c.C.copy(), c.value.copy()
            for i, sc in row_scale.items():
                C[i] /= sc
                value[i] /= sc
            out["constraint"] = {"C": C, "value": value}
    return out


def _partial_drift(p) -> bool:
    """Some parameter sets the drift of some stages only: the stages are then written one by
    one, so that its paths exist."""
    every = set(range(len(p.stages)))
    return any({t.at for t in par.targets if t.kind == kind} not in (set(), every)
               for par in p.parameters for kind in ("f", "offset"))


def _parameters(p, top_level: bool) -> list[str]:
    """``[[parameters]]`` tables, their paths in the file as written (``dynamics.f[i]`` when
    the stages are written once, else ``stages[k].dynamics.f[i]``)."""
    lines = []
    for par in p.parameters:
        sets: list[str] = []
        for t in par.targets:
            if t.kind == "x0":
                path = f"x0[{t.index}]"
            elif t.kind == "value":
                path = f"knots[{t.at}].constraint.value[{t.index}]"
            elif t.kind == "target":
                path = f"knots[{t.at}].penalty.target[{t.index}]"
            elif t.kind == "offset":
                path = (f"cost.tracking.offset[{t.index}]" if top_level
                        else f"stages[{t.at}].cost.tracking.offset[{t.index}]")
            else:
                path = (f"dynamics.f[{t.index}]" if top_level
                        else f"stages[{t.at}].dynamics.f[{t.index}]")
            if path not in sets:
                sets.append(path)
        lines += _table("[[parameters]]", {"name": par.name, "sets": sets,
                                           "range": [float(par.lower), float(par.upper)]})
    return lines


def document_to_toml(doc: dict) -> str:
    """A decoded problem file `doc` (tables, arrays, numbers, strings, as `tomllib` gives
    them) as TOML text that decodes to the same document: its plain keys first, then each
    table as ``[key]`` and each array of tables as ``[[key]]``, nested tables inline."""
    def tables(v) -> bool:
        return isinstance(v, list) and bool(v) and all(isinstance(x, dict) for x in v)
    lines = [f"{_key(k)} = {_value(v)}" for k, v in doc.items()
             if not isinstance(v, dict) and not tables(v)]
    for k, v in doc.items():
        if isinstance(v, dict):
            lines += _table(f"[{_key(k)}]", {_key(a): b for a, b in v.items()})
        elif tables(v):
            for entry in v:
                lines += _table(f"[[{_key(k)}]]", {_key(a): b for a, b in entry.items()})
    return "\n".join(lines) + "\n"


def _key(k: str) -> str:
    return k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else json.dumps(k)


def problem_to_toml(problem: Problem) -> str:
    """The problem file of `problem` (see the module docstring for what is written how).

    Raises
    ------
    ProblemTomlError
        The problem has time-varying data given as a Python callable.
    """
    p = problem
    lines = ["# Problem file written by stospline (problem_to_toml); reference: "
             "docs/guide/problem-file.md",
             f"name = {_value(p.name)}", f"t0 = {_value(float(p.t0))}",
             f"x0 = {_value(p.x0)}", f"tick_hz = {_value(int(p.tick_hz))}"]
    for key in ("u_min", "u_max", "u_hold"):
        limit = getattr(p, key)
        if limit is not None:
            lines.append(f"{key} = {_value(np.asarray(limit, dtype=float))}")
    if p.options:
        lines += _table("[design]", dict(p.options))
    tables = [_stage_tables(s, k, p.mz) for k, s in enumerate(p.stages)]
    top_level = all(_same(s, p.stages[0]) for s in p.stages) and not _partial_drift(p)
    if top_level:
        dyn, cost = tables[0]
        lines += _table("[dynamics]", dyn) + _table("[cost]", cost)
    else:
        # Top level: only the required keys, so no stage inherits a key it does not have.
        lines += _table("[dynamics]", {"A": tables[0][0]["A"], "B": tables[0][0]["B"]})
        lines += _table("[cost]", {"R": tables[0][1]["R"]})
        for dyn, cost in tables:
            lines += ["", "[[stages]]"] + _table("[stages.dynamics]", dyn)[1:]
            lines += _table("[stages.cost]", cost)[1:]
    scales: dict = {}
    for par in p.parameters:
        for t in par.targets:
            if t.kind == "value" and t.scale != 1.0:
                scales.setdefault(t.at, {})[t.index] = t.scale
    for k, kn in enumerate(p.knots):
        lines += _table("[[knots]]", _knot(kn, scales.get(k)))
    for reg in p.tick_regions:
        lines += _table("[[regions]]", {"t": [float(reg.t[0]), float(reg.t[1])], "every": "tick",
                                        "C": reg.C, "lower": reg.lower, "upper": reg.upper,
                                        **({"between_ticks": True} if reg.between else {})})
    if p.plot:
        lines += _table("[plot]", dict(p.plot))
    if p.faults.any:
        lines += _table("[faults]", p.faults.as_dict())
    if p.measurement is not None:
        lines += _table("[measurement]", p.measurement.as_dict())
    for cor in p.corridors:
        items = {"t": [float(cor.t[0]), float(cor.t[1])], "C": cor.C,
                 "polygons": [{"A": A, "b": b} for A, b in cor.polygons]}
        if cor.epsilon is not None:
            items["epsilon"] = float(cor.epsilon)
        lines += _table("[[corridors]]", items)
    lines += _parameters(p, top_level)
    return "\n".join(lines) + "\n"
