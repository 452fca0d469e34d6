"""Runtime parameters: values of a problem that are set on the device, each within a range.

A ``[[parameters]]`` entry names one scalar ``theta`` and the values of the file it sets::

    [[parameters]]
    name = "goal_x"
    sets = ["knots[1].constraint.value[0]", "knots[1].penalty.target[0]"]
    range = [-1.5, -0.5]

The file's values are the nominal: every value a parameter sets must be equal in the file,
and the range must contain it. Supported values (`Target`): a knot constraint's equality
``value[i]`` (in the row's units as written, whatever scale the reader gives the row),
a knot penalty's ``target[i]``, the affine drift ``f[i]`` (constant, at the top level or in a
``[[stages]]`` entry), a tracking path's constant ``offset[i]`` (``cost.tracking.offset[i]``
or ``stages[k].cost.tracking.offset[i]``: the path ``y0(t) + offset``, nominal the file's
``offset``, 0 when not written) and the start state ``x0[i]``. The feedback does not depend on
any of them and the feed-forward is affine in them (`stospline.design.sensitivity`). Band
limits, the tracking samples ``y0`` and time-varying drift are refused: a band's active set,
and so its law, can change over a range. A problem with bands or ``[[regions]]`` keeps its nominal active set
over the range, and its bands are met over the whole box (`stospline.oracle.over_box`).
"""
from __future__ import annotations

import copy
import math
import re
from dataclasses import dataclass, field as _field, replace
from typing import Any

import numpy as np

from stospline.errors import ProblemError

__all__ = ["Target", "Parameter", "parse_parameters", "apply_to_doc", "problem_at",
           "check_theta", "MAX_PARAMETERS"]

MAX_PARAMETERS = 32          # parameters per problem: a table's sensitivity columns
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]{0,15}")
_SUPPORTED = ("x0[i], knots[k].constraint.value[i], knots[k].penalty.target[i], "
              "dynamics.f[i], stages[k].dynamics.f[i], cost.tracking.offset[i], "
              "stages[k].cost.tracking.offset[i]")


@dataclass(frozen=True)
class Target:
    """One value a parameter sets: ``kind`` "x0", "value" (knot constraint), "target" (knot
    penalty), "f" (a stage's drift) or "offset" (a stage's tracking-path offset, the problem
    stage's index); ``at`` the knot or stage (-1 for x0); ``index`` the
    component; ``scale`` the power of two the reader scaled a constraint row by
    (`stospline.problem.rows`): the problem holds ``scale * theta``; ``where`` the file's
    table that holds the value (``knots[k].constraint``, ``stages[k].dynamics``,
    ``cost.tracking``, ...: ``[[regions]]`` add knots, so the file's indices may differ)."""
    kind: str
    at: int
    index: int
    scale: float = 1.0
    where: str = _field(default="", compare=False)   # as written; not part of equality


@dataclass(frozen=True)
class Parameter:
    """A runtime parameter: its C-identifier `name`, the values it sets, its nominal (the
    file's value) and its range ``[lower, upper]``."""
    name: str
    targets: tuple[Target, ...]
    nominal: float
    lower: float
    upper: float


def _get(doc: Any, tokens: list) -> Any:
    for tok in tokens:
        if isinstance(tok, int):
            if not isinstance(doc, list) or tok >= len(doc):
                return None
        elif not isinstance(doc, dict) or tok not in doc:
            return None
        doc = doc[tok]
    return doc


def _tokens(path: str) -> list | None:
    """``"knots[1].penalty.target[0]"`` -> ``["knots", 1, "penalty", "target", 0]``."""
    out: list = []
    for part in path.split("."):
        m = re.fullmatch(r"([a-z_][a-z0-9_]*)((?:\[\d+\])*)", part)
        if not m:
            return None
        out.append(m.group(1))
        out += [int(i) for i in re.findall(r"\[(\d+)\]", m.group(2))]
    return out


def _targets(path: str, field: str, doc: dict, problem) -> list[Target]:
    """The targets of one ``sets`` entry (``dynamics.f[i]``: one per stage that takes the
    top-level drift), or ProblemError naming `field`."""
    tok = _tokens(path) if isinstance(path, str) else None
    if tok is None:
        raise ProblemError(field, f"must be the path of a value in the file (e.g. "
                                  f"\"knots[0].penalty.target[1]\"), got {path!r}")
    shape = [t if isinstance(t, str) else 0 for t in tok]
    n = problem.n
    if shape in (["knots", 0, "constraint", "lower", 0], ["knots", 0, "constraint", "upper", 0]):
        raise ProblemError(field, "band limits cannot be runtime parameters: the band's "
                                  "active set, and so the law, can change over the range")
    if shape in (["cost", "tracking", "offset", 0],
                 ["stages", 0, "cost", "tracking", "offset", 0]):
        return _offset_targets(tok, path, field, doc, problem)
    if "tracking" in shape:
        raise ProblemError(field, "of a tracking path only its constant offset can be a "
                                  "runtime parameter (cost.tracking.offset[i]; the samples "
                                  f"y0, C and the weight cannot; supported: {_SUPPORTED})")
    if shape == ["x0", 0]:
        if tok[1] >= n:
            raise ProblemError(field, f"x0 has {n} entries, no entry {tok[1]}")
        return [Target("x0", -1, tok[1])]
    if shape in (["knots", 0, "constraint", "value", 0], ["knots", 0, "penalty", "target", 0]):
        k, i = tok[1], tok[4]
        if k >= len(doc["knots"]) or _get(doc, tok) is None:
            raise ProblemError(field, f"is not a value of the file ({path} does not exist)")
        kp = _knot_of(doc, problem, k)
        if tok[3] == "target":
            return [Target("target", kp, i, where=f"knots[{k}].penalty")]
        con = problem.knots[kp].constraint
        raw_top = float(np.abs(np.asarray(doc["knots"][k]["constraint"]["C"][i],
                                          dtype=float)).max())
        scale = float(np.abs(con.C[i]).max()) / raw_top if raw_top > 0 else 1.0
        return [Target("value", kp, i, scale, where=f"knots[{k}].constraint")]
    top_f = shape == ["dynamics", "f", 0]
    if top_f or shape == ["stages", 0, "dynamics", "f", 0]:
        where = "dynamics" if top_f else f"stages[{tok[1]}].dynamics"
        raw = _get(doc, tok[:-1])
        if isinstance(raw, dict):
            raise ProblemError(field, f"{where}.f is given as samples: only a constant drift "
                                      f"can be a runtime parameter")
        if _get(doc, tok) is None:
            raise ProblemError(field, f"is not a value of the file ({path} does not exist; "
                                      f"write {where}.f to make its entries parameters)")
        entry = _entries(doc, problem)
        if not top_f:
            return [Target("f", k, tok[-1], where=where) for k, e in enumerate(entry)
                    if e == tok[1]]
        over = doc.get("stages")
        ks = [k for k, e in enumerate(entry)
              if not (isinstance(over, list) and "f" in (over[e].get("dynamics") or {}))]
        if not ks:
            raise ProblemError(field, "every stage overrides dynamics.f in [[stages]]: set "
                                      "stages[k].dynamics.f[i] instead")
        return [Target("f", k, tok[-1], where=where) for k in ks]
    raise ProblemError(field, f"{path!r} cannot be a runtime parameter (supported: "
                              f"{_SUPPORTED})")


def _knot_of(doc: dict, problem, k: int) -> int:
    """The problem's index of the file's knot `k` (``[[regions]]`` add knots between)."""
    t = float(doc["knots"][k]["t"])
    return next(j for j, kn in enumerate(problem.knots) if kn.t == t)


def _entries(doc: dict, problem) -> list[int]:
    """Per stage of the problem, the file's knot (and ``[[stages]]`` entry) whose stage it is
    part of (``[[regions]]`` split stages, as the reader does)."""
    user_t = np.array([float(kn["t"]) for kn in doc["knots"]])
    return [int(np.searchsorted(user_t, kn.t - 1e-12)) for kn in problem.knots]


def _offset_targets(tok: list, path: str, field: str, doc: dict, problem) -> list[Target]:
    """``cost.tracking.offset[i]``: one target per problem stage whose tracking cost is the
    top-level one; ``stages[k].cost.tracking.offset[i]``: the stages of entry k (several when
    ``[[regions]]`` split it)."""
    where = "cost.tracking" if tok[0] == "cost" else f"stages[{tok[1]}].cost.tracking"
    if _get(doc, tok[:-2]) is None:
        raise ProblemError(field, f"is not a value of the file ({where} does not exist)")
    ks = [k for k, st in enumerate(problem.stages)
          if getattr(st.origin, "tracking_path", None) == where]
    if not ks:
        raise ProblemError(field, f"no stage takes {where} (every stage overrides "
                                  f"cost.tracking in [[stages]]): set "
                                  f"stages[k].cost.tracking.offset[i] instead")
    ny = problem.stages[ks[0]].origin.tracking[0].shape[0]
    if tok[-1] >= ny:
        raise ProblemError(field, f"{where} has {ny} tracked output{'s' * (ny != 1)} (rows "
                                  f"of C), no output {tok[-1]}")
    return [Target("offset", k, tok[-1], where=where) for k in ks]


def _nominal_of(problem, t: Target) -> float:
    if t.kind == "x0":
        return float(problem.x0[t.index])
    if t.kind == "offset":
        return float(problem.stages[t.at].origin.tracking_offset[t.index])
    if t.kind == "value":
        return float(problem.knots[t.at].constraint.value[t.index]) / t.scale
    if t.kind == "target":
        return float(problem.knots[t.at].penalty.target[t.index])
    return float(problem.stages[t.at].f[t.index])


def parse_parameters(raw: Any, doc: dict, problem, *, check_keys, number,
                     kind) -> tuple[Parameter, ...]:
    """Validate ``[[parameters]]`` (`raw`) against the decoded file `doc` and the `problem`
    read from it; ProblemError naming ``parameters[i].<key>`` and the reason. The reader
    passes its helpers (`check_keys`, `number`, `kind`), so messages match its own."""
    _check_keys, _number, _kind = check_keys, number, kind
    if not isinstance(raw, list) or not raw:
        raise ProblemError("parameters", f"must be a non-empty array of tables "
                                         f"([[parameters]]), got {_kind(raw)}")
    if len(raw) > MAX_PARAMETERS:
        raise ProblemError("parameters", f"has {len(raw)} entries; at most {MAX_PARAMETERS}")
    out: list[Parameter] = []
    names: set[str] = set()
    seen: dict[Target, str] = {}
    for j, entry in enumerate(raw):
        path = f"parameters[{j}]"
        _check_keys(entry, path, {"name", "sets", "range"}, {"name", "sets", "range"})
        name = entry["name"]
        if not isinstance(name, str) or not _NAME.fullmatch(name):
            raise ProblemError(f"{path}.name", f"must be a C identifier of at most 16 "
                                               f"characters, got {name!r}")
        if name.lower() in names:
            raise ProblemError(f"{path}.name", f"{name!r} names an earlier parameter "
                                               f"(names are compared ignoring case)")
        names.add(name.lower())
        sets = entry["sets"]
        if not isinstance(sets, list) or not sets:
            raise ProblemError(f"{path}.sets", f"must be a non-empty array of paths, got "
                                               f"{_kind(sets)}")
        targets: list[Target] = []
        values: list[tuple[float, str]] = []
        for i, p in enumerate(sets):
            field = f"{path}.sets[{i}]"
            for t in _targets(p, field, doc, problem):
                if t in seen:
                    raise ProblemError(field, f"{p} is already set by {seen[t]}")
                seen[t] = field
                targets.append(t)
                values.append((_nominal_of(problem, t), p))
        nominal = values[0][0]
        for v, p in values[1:]:
            if v != nominal:
                raise ProblemError(f"{path}.sets", f"the values a parameter sets must be "
                                                   f"equal in the file (its nominal): "
                                                   f"{values[0][1]} = {nominal:g} but {p} = "
                                                   f"{v:g}")
        rng = entry["range"]
        if not isinstance(rng, list) or len(rng) != 2:
            raise ProblemError(f"{path}.range", f"must be [lower, upper], got {rng!r}")
        lo = _number(rng[0], f"{path}.range[0]")
        hi = _number(rng[1], f"{path}.range[1]")
        if not lo < hi:
            raise ProblemError(f"{path}.range", f"lower {lo:g} must be below upper {hi:g}")
        if not lo <= nominal <= hi:
            raise ProblemError(f"{path}.range", f"[{lo:g}, {hi:g}] does not contain the "
                                                f"nominal value {nominal:g} (the file's)")
        if max(abs(lo), abs(hi)) > float(np.finfo(np.float32).max):
            raise ProblemError(f"{path}.range", "must lie within the float32 range "
                                                "(|v| <= 3.4028235e38) the device stores it in")
        out.append(Parameter(name, tuple(targets), nominal, lo, hi))
    return tuple(out)


def check_theta(parameters, theta) -> np.ndarray:
    """`theta` as an array of one finite value per parameter inside its range; ValueError
    naming the parameter otherwise."""
    th = np.asarray(theta, dtype=float).reshape(-1)
    if th.shape != (len(parameters),):
        raise ValueError(f"theta needs {len(parameters)} values (one per parameter), got "
                         f"{th.size}")
    for v, par in zip(th, parameters):
        if not (math.isfinite(v) and par.lower <= v <= par.upper):
            raise ValueError(f"{par.name}: {float(v)!r} is outside its range [{par.lower:g}, "
                             f"{par.upper:g}]")
    return th


def apply_to_doc(doc: dict, parameters, theta) -> dict:
    """A copy of the decoded file `doc` with every value each parameter sets replaced by its
    entry of `theta` (a fresh design at `theta` reads this)."""
    th = check_theta(parameters, theta)
    out = copy.deepcopy(doc)
    for par, v in zip(parameters, th):
        for t in par.targets:
            if t.kind == "x0":
                out["x0"][t.index] = float(v)
            elif t.kind == "value":
                _get(out, _tokens(t.where))["value"][t.index] = float(v)
            elif t.kind == "target":
                _get(out, _tokens(t.where))["target"][t.index] = float(v)
            elif t.kind == "offset":
                table = _get(out, _tokens(t.where))
                ny = len(table["C"])
                table.setdefault("offset", [0.0] * ny)[t.index] = float(v)
            else:
                _get(out, _tokens(t.where))["f"][t.index] = float(v)
    return out


def problem_at(problem, theta):
    """`problem` with every value its parameters set replaced by `theta` (what the oracle
    evaluates a table at `theta` against)."""
    th = check_theta(problem.parameters, theta)
    x0 = problem.x0.copy()
    knots, stages = list(problem.knots), list(problem.stages)
    for par, v in zip(problem.parameters, th):
        for t in par.targets:
            if t.kind == "x0":
                x0[t.index] = v
            elif t.kind == "value":
                kn = knots[t.at]
                val = kn.constraint.value.copy(); val[t.index] = v * t.scale
                knots[t.at] = replace(kn, constraint=replace(kn.constraint, value=val))
            elif t.kind == "target":
                kn = knots[t.at]
                tg = kn.penalty.target.copy(); tg[t.index] = v
                knots[t.at] = replace(kn, penalty=replace(kn.penalty, target=tg))
            elif t.kind == "offset":
                stages[t.at] = _with_offset(stages[t.at], t.index, v)
            else:
                f = stages[t.at].f.copy(); f[t.index] = v
                stages[t.at] = replace(stages[t.at], f=f)
    return replace(problem, x0=x0, knots=tuple(knots), stages=tuple(stages))


def _with_offset(stage, index: int, v: float):
    """`stage` with its tracking path's offset ``index`` at `v`: ``q`` and ``rho`` (and their
    samples) rebuilt from the parsed data, every other field kept."""
    off = stage.origin.tracking_offset.copy()
    off[index] = v
    data = replace(stage.origin, tracking_offset=off)
    built = data.build(stage.A.shape[0], stage.G.shape[2])
    return replace(stage, q=built.q, rho=built.rho, varying=built.varying, origin=data)
