"""Read a TOML problem file into a validated, typed `stospline.problem.Problem`.

Every error names the offending field by its path in the file (``knots[1].constraint.C``)
and says why, so a user can fix the file without reading this code.
"""
from __future__ import annotations

import hashlib
import math
import re
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from stospline.errors import ProblemError
from stospline.firmware_interface import ARITHS
from stospline.limits import check_problem, check_stage_count, check_state
from stospline.table_options import TABLE_KINDS, check_spline_tolerance
from stospline.problem.faults import parse_faults
from stospline.problem.fields import check_keys, join as _join, kind as _kind
from stospline.problem.fields import integer as _int, matrix as _matrix, number as _number
from stospline.problem.fields import vector as _vector
from stospline.problem.series import series_or
from stospline.problem.measurement import parse_measurement
from stospline.problem.inputfile import decode_problem, read_problem_file
from stospline.problem.corridors import Corridor
from stospline.problem.model import (Constraint, Knot, Penalty, Problem, Series, Stage,
                                     TickRegion)
from stospline.problem.names import check_name
from stospline.problem.parameters import parse_parameters
from stospline.problem.regions import merge_constraints
from stospline.problem.rows import check_no_subnormal, normalise_rows

__all__ = ["load_problem", "parse_problem"]

_TOP_KEYS = {"name", "t0", "x0", "tick_hz", "u_min", "u_max", "u_hold", "dynamics", "cost",
             "knots",
             "stages", "plot", "regions", "design", "faults", "corridors", "measurement",
             "parameters"}
_DESIGN_OPTIONS = {"mode": ("stagewise", "joint"), "discretization": ("exact-zoh", "continuous"),
                   "arith": ARITHS, "delay_ticks": (0, 1), "table": TABLE_KINDS,
                   "spline_tolerance": None}
_TOP_REQUIRED = {"name", "x0", "tick_hz", "dynamics", "cost", "knots"}
_DYN_KEYS, _DYN_REQUIRED = {"A", "B", "f", "noise"}, {"A", "B"}
_COST_KEYS, _COST_REQUIRED = {"Q", "S", "R", "q", "r", "rho", "tracking"}, {"R"}
_C_IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_C_KEYWORDS = frozenset(
    "auto break case char const continue default do double else enum extern float for goto "
    "if inline int long register restrict return short signed sizeof static struct switch "
    "typedef union unsigned void volatile while _Bool _Complex _Imaginary".split())
_U32_MAX = 2**32 - 1  # the C table stores tick counts and the tick rate as uint32_t
_F32_MAX = float(np.finfo(np.float32).max)  # the table stores limits as float32 (FLT_MAX)
_N_IS_LEN_X0 = " (n, the length of x0)"
_OUTPUT_SCALE = (1e-150, 1e150)   # a corridor output row's largest coefficient
_MAX_GRID_POINTS = 100_000  # [[regions]] band points over all regions (parse-time work bound)
# [[corridors]]: outputs and walls the harness checks per path and tick (its C keeps y on the
# stack); enough for any corridor drawn by hand, and a bound on the per-tick work.
_MAX_CORRIDOR_OUTPUTS, _MAX_CORRIDOR_WALLS = 32, 256


# ---------------------------------------------------------------------------------------
# Parsing helpers: each takes the raw value and its field path, returns a checked value.

def _check_keys(table: Any, path: str, allowed: set[str], required: set[str]) -> dict:
    return check_keys(table, path, allowed, required, hint=_top_key_hint(path))


def _top_key_hint(path: str):
    """Inside a table, a top-level key is a misplaced line: say where it goes."""
    def hint(key: str) -> str:
        return ("top-level keys go before the first [table] header; "
                if path and key in _TOP_KEYS else "")
    return hint


def _plain(value: Any) -> Any:
    """A document built in Python as TOML would decode it: numpy arrays and tuples become
    lists, numpy scalars Python numbers (np.bool_ a bool, refused where a number is due), so
    arrays from numpy meet exactly the checks and messages that a file's values meet."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def _tol(M: np.ndarray) -> float:
    return max(1.0, float(np.abs(M).max()))


def _check_symmetric(M: np.ndarray, path: str) -> None:
    asym = float(np.abs(M - M.T).max())
    if asym > 1e-12 * _tol(M):
        i, j = np.unravel_index(np.argmax(np.abs(M - M.T)), M.shape)
        raise ProblemError(path, f"must be symmetric: [{i}][{j}] = {M[i, j]:g} but "
                                 f"[{j}][{i}] = {M[j, i]:g}")


# A stage's data is looked up key by key through "layers": the stage's own table first
# (``stages[k].dynamics``), then the top-level one (``dynamics``).  Every value is checked
# under the path of the table it came from.
_Layers = list[tuple[dict, str]]


def _pick(layers: _Layers, key: str) -> tuple[Any, str | None]:
    for table, path in layers:
        if key in table:
            return table[key], _join(path, key)
    return None, None


def _parse_noise(value: Any, path: str, n: int, m: int) -> list[tuple[int, np.ndarray, str]]:
    """``noise = [{state = i, G = (n x mz)}, {input = j, G = (n x mz)}, ...]`` as
    ``(multiplier index, G, path of G)`` triples; an input j has multiplier index n + j."""
    if not isinstance(value, list):
        raise ProblemError(path, f"must be an array of {{state = i, G = matrix}} or "
                                 f"{{input = j, G = matrix}} tables, got {_kind(value)}")
    items: list[tuple[int, np.ndarray, str]] = []
    seen: dict[int, str] = {}
    for j, item in enumerate(value):
        ip = f"{path}[{j}]"
        if isinstance(item, dict) and "input" in item:
            _check_keys(item, ip, {"input", "G"}, {"input", "G"})
            i = n + _int(item["input"], f"{ip}.input", 0, m - 1, "a 0-based input index")
            key, label = "input", f"input {i - n}"
        else:
            _check_keys(item, ip, {"state", "G"}, {"state", "G"})
            i = _int(item["state"], f"{ip}.state", 0, n - 1, "a 0-based state index")
            key, label = "state", f"state {i}"
        if i in seen:
            raise ProblemError(f"{ip}.{key}", f"{label} already has a noise entry "
                                              f"({seen[i]}); give one entry per {key}")
        seen[i] = ip
        gp = f"{ip}.G"
        want = _first(items[0][1]).shape[1] if items else None
        why = f" (as {items[0][2]}: one column per Brownian component)" if items else ""
        g = _series_or(item["G"], gp, _matrix, (n, want), (_N_IS_LEN_X0, why))
        items.append((i, g, gp))
    return items


def _series_or(value: Any, path: str, parse, *args):
    """`series.series_or` with the reader's hint for a misplaced top-level key."""
    return series_or(value, path, parse, *args, hint=_top_key_hint(path))


def _each(value, path: str):
    """(sample, path) pairs of a constant or a `Series`."""
    if isinstance(value, Series):
        return [(v, f"{path}.values[{i}]") for i, v in enumerate(value.values)]
    return [(value, path)]


def _first(value):
    return value.values[0] if isinstance(value, Series) else value


@dataclass
class _StageData:
    """A parsed stage before the common noise width mz is known; fields may be `Series`."""
    fields: dict
    B_path: str
    noise: list[tuple[int, Any, str]]
    tracking: tuple | None = None      # (C, Qy, y0 Series) of an integral tracking cost
    tracking_path: str | None = None   # "cost.tracking" or "stages[k].cost.tracking"
    tracking_offset: np.ndarray | None = None   # added to every y0 sample (ny,)

    def series(self) -> list[Series]:
        out = [v for v in self.fields.values() if isinstance(v, Series)]
        out += [g for _, g, _ in self.noise if isinstance(g, Series)]
        return out + ([self.tracking[2]] if self.tracking else [])

    def _noise_at(self, n: int, m: int, mz: int, t: float | None) -> np.ndarray:
        GH = np.zeros((n + m, n, mz))
        for i, g, _ in self.noise:
            GH[i] = g(t) if isinstance(g, Series) and t is not None else _first(g)
        return GH

    def _noise_many(self, n: int, m: int, mz: int, ts: np.ndarray) -> np.ndarray:
        GH = np.zeros((ts.size, n + m, n, mz))
        for i, g, _ in self.noise:
            GH[:, i] = g.many(ts) if isinstance(g, Series) else _first(g)
        return GH

    def _fields_at(self, t: float | None) -> dict:
        f = {k: (v(t) if isinstance(v, Series) and t is not None else _first(v))
             for k, v in self.fields.items()}
        if self.tracking is not None:
            # E |C x - y0(t)|^2_Qy adds C'Qy C to Q, -C'Qy y0 to q and y0'Qy y0 to rho.
            C, Qy, y0s = self.tracking
            y0 = (y0s(t) if t is not None else y0s.values[0]) + self.tracking_offset
            f["Q"] = f["Q"] + C.T @ Qy @ C
            f["q"] = f["q"] - C.T @ Qy @ y0
            f["rho"] = f["rho"] + float(y0 @ Qy @ y0)
        return f

    def _fields_many(self, keys, ts: np.ndarray) -> dict:
        """`_fields_at` of the varying `keys` at every time of `ts`, stacked (the same sums)."""
        f = {k: (v.many(ts) if isinstance(v, Series) else np.asarray(_first(v))[None])
             for k, v in self.fields.items() if k in keys}
        if self.tracking is not None:
            C, Qy, y0s = self.tracking
            y0 = y0s.many(ts) + self.tracking_offset           # (T, ny)
            f["Q"] = f["Q"] + C.T @ Qy @ C
            f["q"] = f["q"] - np.array([C.T @ Qy @ y for y in y0])
            f["rho"] = f["rho"] + np.array([float(y @ Qy @ y) for y in y0])
        return {k: np.broadcast_to(v, (ts.size,) + np.shape(v)[1:]) for k, v in f.items()}

    def build(self, n: int, mz: int) -> Stage:
        m = _first(self.fields["B"]).shape[1]
        GH = self._noise_at(n, m, mz, None)
        H = GH[n:] if any(i >= n for i, _, _ in self.noise) else None
        varying = None
        if self.series():
            keys = [k for k, v in self.fields.items() if isinstance(v, Series)]
            if self.tracking is not None:
                keys += ["Q", "q", "rho"]
            noisy = any(isinstance(g, Series) for _, g, _ in self.noise)
            varying = _SampledData(self, tuple(sorted(set(keys))), noisy, n, m, mz,
                                   H is not None)
        base = self._fields_at(None)
        return Stage(G=GH[:n], H=H, varying=varying, origin=self, **base)


class _SampledData:
    """``Stage.varying`` of a parsed stage: its samples at a time (a call) or at many (`many`,
    vectorised, equal to the calls)."""

    def __init__(self, data: _StageData, keys: tuple, noisy: bool, n: int, m: int, mz: int,
                 has_H: bool):
        self.data, self.keys, self.noisy = data, keys, noisy
        self.n, self.m, self.mz, self.has_H = n, m, mz, has_H
        # Between two consecutive sample times of the noise (every series' merged), G and H
        # are affine in t when every noise series is interpolated linearly: the designer
        # builds its diffusion operators per such segment (`stospline.design.varying`).
        series = [g for _, g, _ in data.noise if isinstance(g, Series)]
        self.noise_knots = (np.unique(np.concatenate([g.t for g in series]))
                            if series and all(g.interpolation == "linear" for g in series)
                            else None)

    def __call__(self, t: float) -> dict:
        f = self.data._fields_at(t)
        out = {k: f[k] for k in self.keys}
        if self.noisy:
            GHt = self.data._noise_at(self.n, self.m, self.mz, t)
            out["G"] = GHt[:self.n]
            if self.has_H:
                out["H"] = GHt[self.n:]
        return out

    def many(self, ts) -> dict:
        return self._many(ts, True)

    def many_noise_free(self, ts) -> dict:
        """`many` without G and H (`Stage.samples` with ``noise=False``): not sampled."""
        return self._many(ts, False)

    def _many(self, ts, noise: bool) -> dict:
        ts = np.asarray(ts, dtype=float)
        out = self.data._fields_many(self.keys, ts)
        if self.noisy and noise:
            GHt = self.data._noise_many(self.n, self.m, self.mz, ts)
            out["G"] = GHt[:, :self.n]
            if self.has_H:
                out["H"] = GHt[:, self.n:]
        return out


def _parse_stage(dyn: _Layers, cost: _Layers, n: int,
                 m_ref: tuple[int, str] | None) -> _StageData:
    """Check one stage's dynamics and cost, looked up through `dyn` and `cost` layers."""
    value, path = _pick(dyn, "A")
    A = _series_or(value, path, _matrix, (None, None))
    A0 = _first(A)
    if A0.shape[0] != A0.shape[1]:
        raise ProblemError(path, f"must be square, got shape {A0.shape[0]}x{A0.shape[1]}")
    if A0.shape[0] != n:
        raise ProblemError(path, f"is {A0.shape[0]}x{A0.shape[1]} but x0 has {n} entries; "
                                 f"A must be n x n with n = {n}, the length of x0")
    if isinstance(A, Series):
        _series_or(value, path, _matrix, (n, n))          # every sample n x n
    value, B_path = _pick(dyn, "B")
    B = _series_or(value, B_path, _matrix, (n, None), (_N_IS_LEN_X0, ""))
    m = _first(B).shape[1]
    if isinstance(B, Series):
        _series_or(value, B_path, _matrix, (n, m), (_N_IS_LEN_X0, ""))
    if m_ref is not None and m != m_ref[0]:
        raise ProblemError(B_path, f"has {m} columns (inputs) but {m_ref[1]} has {m_ref[0]}; "
                                   f"every stage must have the same number of inputs m")
    value, path = _pick(dyn, "noise")
    noise = [] if path is None else _parse_noise(value, path, n, m)
    value, f_path = _pick(dyn, "f")
    drift = {} if f_path is None else {"f": _series_or(value, f_path, _vector, n, _N_IS_LEN_X0)}

    def optional(key, parse, default, *args):
        value, path = _pick(cost, key)
        if path is None:
            return default, "0 (default)"
        return _series_or(value, path, parse, *args), path

    why_m = (f" (m, the number of columns of {B_path})",) * 2
    R, R_path = optional("R", _matrix, None, (m, m), why_m)
    Q, Q_path = optional("Q", _matrix, np.zeros((n, n)), (n, n), (_N_IS_LEN_X0,) * 2)
    S, S_path = optional("S", _matrix, np.zeros((n, m)), (n, m), (_N_IS_LEN_X0, why_m[0]))
    q, _ = optional("q", _vector, np.zeros(n), n, _N_IS_LEN_X0)
    r, _ = optional("r", _vector, np.zeros(m), m, why_m[0])
    rho, _ = optional("rho", _number, 0.0)

    for Ri, Rp in _each(R, R_path):
        _check_symmetric(Ri, Rp)
        w = np.linalg.eigvalsh(Ri)
        if w.min() <= 1e-12 * _tol(Ri):
            raise ProblemError(Rp, f"must be positive definite (smallest eigenvalue "
                                   f"{w.min():.6g}); every input needs a positive cost")
    for Qi, Qp in _each(Q, Q_path):
        _check_symmetric(Qi, Qp)
    # Condition (3) at every sample time of Q, S, R: between samples each is affine in t, so
    # the block matrix is too, and positive semidefinite at both ends means in between.
    grid = sorted({float(t) for x in (Q, S, R) if isinstance(x, Series) for t in x.t} or {0.0})
    for t in grid:
        Qt, St, Rt = (x(t) if isinstance(x, Series) else x for x in (Q, S, R))
        H = np.block([[Qt, St], [St.T, Rt]])
        h = np.linalg.eigvalsh(H).min()
        if h < -1e-10 * _tol(H):
            # Name the innermost table that supplies any of Q, S, R.
            where = next(p for tb, p in cost if {"Q", "S", "R"} & set(tb))
            at = f" at t = {t:g}" if len(grid) > 1 or isinstance(Q, Series) else ""
            raise ProblemError(where, f"[[Q, S], [S', R]] must be positive semidefinite (the "
                                      f"paper's condition (3)){at}, smallest eigenvalue "
                                      f"{h:.6g}; here Q is {Q_path}, S is {S_path}, R is {R_path}")
    tracking = offset = None
    value, tpath = _pick(cost, "tracking")
    if tpath is not None:
        tracking = _parse_tracking(value, tpath, n)
        ny = tracking[0].shape[0]
        offset = (np.zeros(ny) if "offset" not in value else
                  _vector(value["offset"], _join(tpath, "offset"), ny,
                          " (one entry per row of C)"))
    return _StageData(dict(A=A, B=B, Q=Q, S=S, R=R, q=q, r=r, rho=rho, **drift), B_path, noise,
                      tracking, tpath, offset)


def _parse_tracking(value: Any, path: str, n: int) -> tuple:
    """``tracking = {C = (ny x n), weight = Qy (ny x ny) or a number, t = [...], y0 = [[...]],
    interpolation = "linear", offset = [...]}``: the integral cost
    ``E int |C x - y0(t) - offset|^2_Qy dt`` (the caller reads ``offset``, a runtime
    parameter may set it: `stospline.problem.parameters`)."""
    _check_keys(value, path, {"C", "weight", "t", "y0", "interpolation", "offset"},
                {"C", "t", "y0"})
    C = _matrix(value["C"], _join(path, "C"), (None, n), (" (one row per tracked output)",
                                                          _N_IS_LEN_X0))
    ny = C.shape[0]
    w = value.get("weight", 1.0)
    if isinstance(w, list):
        Qy = _matrix(w, _join(path, "weight"), (ny, ny))
        _check_symmetric(Qy, _join(path, "weight"))
    else:
        Qy = _number(w, _join(path, "weight")) * np.eye(ny)
    if np.linalg.eigvalsh(Qy).min() < -1e-12 * _tol(Qy):
        raise ProblemError(_join(path, "weight"), "must be positive semidefinite")
    raw = {"t": value["t"], "values": value["y0"],
           "interpolation": value.get("interpolation", "linear")}
    try:
        y0 = _series_or(raw, path, _vector, ny, " (one entry per row of C)")
    except ProblemError as exc:          # the file's key is y0, not values
        raise ProblemError(exc.field.replace(_join(path, "values"), _join(path, "y0")),
                           exc.reason.replace(_join(path, "values"), _join(path, "y0"))
                           ) from None
    # Path of the sample times: a coverage error names cost.tracking.t.
    y0 = Series(y0.t, y0.values, y0.interpolation, path)
    return C, Qy, y0


def _parse_knot(raw: Any, path: str, n: int) -> Knot:
    _check_keys(raw, path, {"t", "penalty", "constraint"}, {"t"})
    t = _number(raw["t"], _join(path, "t"))
    rows = " (one entry per row of C)"
    penalty = constraint = None
    if "penalty" in raw:
        pp = _join(path, "penalty")
        pen = _check_keys(raw["penalty"], pp, {"C", "target", "weight"},
                          {"C", "target", "weight"})
        C = _matrix(pen["C"], _join(pp, "C"), (None, n), ("", _N_IS_LEN_X0))
        target = _vector(pen["target"], _join(pp, "target"), C.shape[0], rows)
        weight = _number(pen["weight"], _join(pp, "weight"))
        if weight < 0:
            raise ProblemError(_join(pp, "weight"), f"must be >= 0, got {weight:g}")
        penalty = Penalty(C, target, weight)
    if "constraint" in raw:
        cp = _join(path, "constraint")
        con = _check_keys(raw["constraint"], cp, {"C", "value", "lower", "upper"}, {"C"})
        C = _matrix(con["C"], _join(cp, "C"), (None, n), ("", _N_IS_LEN_X0))
        if "value" in con:
            for key in ("lower", "upper"):
                if key in con:
                    raise ProblemError(_join(cp, key), "give either value (an equality) or "
                                                       "lower and upper (a band), not both")
            value = _vector(con["value"], _join(cp, "value"), C.shape[0], rows)
            C, b = normalise_rows(C, _join(cp, "C"), {_join(cp, "value"): value})
            constraint = Constraint(C, b[_join(cp, "value")])
        else:
            for key in ("lower", "upper"):
                if key not in con:
                    raise ProblemError(_join(cp, key), "is required: a constraint needs value "
                                                       "(an equality) or lower and upper (a band)")
            lo = _vector(con["lower"], _join(cp, "lower"), C.shape[0], rows)
            hi = _vector(con["upper"], _join(cp, "upper"), C.shape[0], rows)
            bad = np.flatnonzero(lo > hi)
            if bad.size:
                i = int(bad[0])
                raise ProblemError(_join(cp, "lower"), f"row {i}: lower {lo[i]:g} > upper "
                                                       f"{hi[i]:g}; the band is empty")
            C, lo, hi = _normalised_band(C, _join(cp, "C"), _join(cp, "lower"), lo,
                                         _join(cp, "upper"), hi)
            constraint = Constraint(C, None, lo, hi)
    return Knot(t, penalty, constraint)


def _check_times(knots: tuple[Knot, ...], t0: float, tick_hz: int) -> None:
    """Knot times increase strictly from t0 and every stage is a whole number of ticks."""
    prev, prev_name, total = t0, "t0", 0
    for i, kn in enumerate(knots):
        path = f"knots[{i}].t"
        if kn.t <= prev:
            raise ProblemError(path, f"must be later than {prev_name} = {prev:g} (got "
                                     f"{kn.t:g}); knot times must increase strictly")
        ticks = (kn.t - prev) * tick_hz
        if not ticks <= _U32_MAX:    # also Inf (t = 1e308): round() would overflow
            raise ProblemError(path, f"stage {i} ({prev_name} = {prev:g} to {kn.t:g}) lasts "
                                     f"{ticks:.9g} ticks at tick_hz = {tick_hz}; the gain "
                                     f"table counts ticks in 32 bits (at most {_U32_MAX})")
        whole = round(ticks)
        if whole < 1 or abs(ticks - whole) > 1e-9 * max(1.0, ticks):
            raise ProblemError(path, f"stage {i} ({prev_name} = {prev:g} to {kn.t:g}) lasts "
                                     f"{kn.t - prev:g} s = {ticks:.9g} ticks at tick_hz = "
                                     f"{tick_hz}; it must be a whole number of ticks")
        total += whole
        prev, prev_name = kn.t, path
    if total > _U32_MAX:
        raise ProblemError("tick_hz", f"gives {total} ticks in all; the gain table counts "
                                      f"ticks in 32 bits (at most {_U32_MAX})")


def _parse_stage_overrides(raw: Any, n_knots: int) -> list[tuple[dict, dict]]:
    """``[[stages]]``: one entry per knot, each with optional dynamics/cost override tables."""
    if not isinstance(raw, list) or not all(isinstance(s, dict) for s in raw):
        raise ProblemError("stages", f"must be an array of tables ([[stages]]), "
                                     f"got {_kind(raw)}")
    if len(raw) != n_knots:
        raise ProblemError("stages", f"has {len(raw)} entries but there are {n_knots} knots; "
                                     f"give exactly one [[stages]] entry per knot (entry k "
                                     f"is the stage that ends at knots[k].t)")
    out = []
    for k, entry in enumerate(raw):
        sp = f"stages[{k}]"
        for key in entry:
            if key in _DYN_KEYS | _COST_KEYS:
                table = "dynamics" if key in _DYN_KEYS else "cost"
                raise ProblemError(_join(sp, key), f"unknown key; a stage's {key} goes in "
                                                   f"its {table} table: [stages.{table}] "
                                                   f"or {table} = {{ {key} = ... }}")
        _check_keys(entry, sp, {"dynamics", "cost"}, set())
        dyn = _check_keys(entry.get("dynamics", {}), f"{sp}.dynamics", _DYN_KEYS, set())
        cost = _check_keys(entry.get("cost", {}), f"{sp}.cost", _COST_KEYS, set())
        out.append((dyn, cost))
    return out


def _parse_plot(plot: Any, n: int) -> dict:
    _check_keys(plot, "plot", {"walls", "axes"}, set())
    walls = plot.get("walls", [])
    if not isinstance(walls, list):
        raise ProblemError("plot.walls", f"must be an array of polylines, got {_kind(walls)}")
    for i, wall in enumerate(walls):
        _matrix(wall, f"plot.walls[{i}]", (None, 2), ("", " (x, y points)"))
    if "axes" in plot:
        ax = plot["axes"]
        if (not isinstance(ax, list) or len(ax) not in (1, 2)
                or not all(isinstance(a, int) and not isinstance(a, bool) and 0 <= a < n
                           for a in ax)):
            raise ProblemError("plot.axes", f"must be one or two state indices in 0..{n - 1} "
                                            f"(one: that state against time), got {ax!r}")
    return plot


def _fits_float32(v: float) -> bool:
    """True when v rounds to a finite float32 (3.4028235e38 does: it rounds to FLT_MAX)."""
    with np.errstate(over="ignore"):
        return bool(np.isfinite(np.float32(v)))


def _input(path: str, i: int) -> str:
    """Message prefix naming input i, unless the value is one number for every input."""
    return f"input {i}: " if path.endswith("]") else ""


def _parse_limits(doc: dict, m: int) -> tuple[np.ndarray | None, ...]:
    """``u_min``/``u_max``/``u_hold``: a number (every input) or one number per input, with
    ``u_min <= u_hold <= u_max``; ``u_hold`` (the firmware's safe command on a refused step)
    defaults to 0 where 0 is within the limits and is required where it is not."""
    out = {}
    for key in ("u_min", "u_max", "u_hold"):
        if key not in doc:
            out[key] = None
            continue
        raw = doc[key]
        what = "safe command" if key == "u_hold" else "limit"
        if isinstance(raw, list):
            if not raw:
                raise ProblemError(key, f"must be a number (the same {what} for every input) "
                                        f"or an array with one number per input (m = {m}), "
                                        f"got an empty array")
            paths = [f"{key}[{i}]" for i in range(len(raw))]
            items = raw
        elif isinstance(raw, (int, float)) and not isinstance(raw, bool):
            paths, items = [key] * m, [raw] * m
        else:
            raise ProblemError(key, f"must be a number (the same {what} for every input) or "
                                    f"an array with one number per input (m = {m}), got "
                                    f"{_kind(raw)} ({raw!r})")
        vals = []
        for v, vp in zip(items, paths):
            if (isinstance(v, (int, float)) and not isinstance(v, bool)
                    and not math.isnan(v) and not _fits_float32(v)):   # Inf or too large
                hint = ("" if key == "u_hold" else
                        f"; omit {key} for no limit on any input, or give "
                        f"{'-' if key == 'u_min' else ''}{_F32_MAX:.8g} (FLT_MAX, which the "
                        f"firmware treats as unlimited) for one input")
                raise ProblemError(vp, f"must be finite and within the float32 range of the "
                                       f"gain table (|value| <= {_F32_MAX:.8g}), got "
                                       f"{v!r}{hint}")
            vals.append(_number(v, vp))
        if len(vals) != m:
            raise ProblemError(key, f"has length {len(vals)}, expected {m} (m, one entry per "
                                    f"input: the columns of dynamics.B); or give one number "
                                    f"for every input")
        out[key] = (np.array(vals), paths)
    if out["u_min"] is not None and out["u_max"] is not None:
        (lo, lp), (hi, hp) = out["u_min"], out["u_max"]
        bad = np.flatnonzero(lo > hi)
        if bad.size:
            i = int(bad[0])
            raise ProblemError(lp[i], f"{_input(lp[i] + hp[i], i)}u_min = {lo[i]:g} > u_max = "
                                      f"{hi[i]:g}; the range of commands is empty")
    why = ("the firmware commands the safe value u_hold when it refuses a tick or a state "
           "(any error status), so it must be a valid command: u_min <= u_hold <= u_max")
    if out["u_hold"] is not None:
        hold, hold_paths = out["u_hold"]
    else:
        hold, hold_paths = np.zeros(m), None
    for key, sign in (("u_min", 1), ("u_max", -1)):
        if out[key] is None:
            continue
        vals, paths = out[key]
        bad = np.flatnonzero(sign * (vals - hold) > 0)
        if bad.size:
            i = int(bad[0])
            if hold_paths is None:
                rel = "<=" if key == "u_min" else ">="
                raise ProblemError(paths[i], f"{_input(paths[i], i)}is {vals[i]:g}, so 0 is "
                                             f"not a valid command: give u_hold, the safe "
                                             f"command within the limits (u_min <= u_hold <= "
                                             f"u_max; 0 is the default only when {key} {rel} 0)")
            rel = "<" if key == "u_min" else ">"
            raise ProblemError(hold_paths[i], f"{_input(hold_paths[i], i)}{hold[i]:g} is "
                                              f"{rel} {key} = {vals[i]:g}; {why}")
    return tuple(None if out[k] is None else out[k][0] for k in ("u_min", "u_max", "u_hold"))


def _parse_regions(raw: Any, n: int, t0: float, t_end: float, tick_hz: int,
                   ticked: list) -> list[tuple[float, Constraint]]:
    """``[[regions]]``: keep ``lower <= E{C x(t)} <= upper`` on the open interval ``t = [a, b]``,
    imposed as bands at ``a + every, a + 2 every, ...`` strictly before b (the paper's open
    problem f(t) <= E y(t) <= g(t), approximated on a dense grid). ``every = "tick"``: the
    region is appended to `ticked` as a `TickRegion` (bands at every tick, added by the
    design where they are needed) instead."""
    if not isinstance(raw, list):
        raise ProblemError("regions", f"must be an array of tables ([[regions]]), got {_kind(raw)}")
    out = []
    for i, reg in enumerate(raw):
        rp = f"regions[{i}]"
        _check_keys(reg, rp, {"t", "every", "C", "lower", "upper", "between_ticks"},
                    {"t", "every", "C", "lower", "upper"})
        a, b = _vector(reg["t"], _join(rp, "t"), 2)
        if not t0 <= a < b <= t_end:
            raise ProblemError(_join(rp, "t"), f"must be [start, end] with {t0:g} <= start < "
                                               f"end <= {t_end:g} (the last knot)")
        tick = reg["every"] == "tick"
        if isinstance(reg["every"], str) and not tick:
            raise ProblemError(_join(rp, "every"), f'must be a number of seconds or "tick", '
                                                   f'got {reg["every"]!r}')
        every = 1.0 / tick_hz if tick else _number(reg["every"], _join(rp, "every"))
        if every <= 0:
            raise ProblemError(_join(rp, "every"), "must be positive")
        for key, val in (("t", a - t0), ("every", every)):
            ticks = val * tick_hz
            if abs(ticks - round(ticks)) > 1e-9 * max(1.0, ticks):
                raise ProblemError(_join(rp, key), f"{val:g} s is not a whole number of ticks "
                                                   f"at tick_hz = {tick_hz}: the bands must "
                                                   f"fall on ticks")
        C = _matrix(reg["C"], _join(rp, "C"), (None, n), ("", _N_IS_LEN_X0))
        lo = _vector(reg["lower"], _join(rp, "lower"), C.shape[0], " (one entry per row of C)")
        hi = _vector(reg["upper"], _join(rp, "upper"), C.shape[0], " (one entry per row of C)")
        if np.any(lo > hi):
            raise ProblemError(_join(rp, "lower"), "lower > upper: the band is empty")
        C, lo, hi = _normalised_band(C, _join(rp, "C"), _join(rp, "lower"), lo,
                                     _join(rp, "upper"), hi)
        between = reg.get("between_ticks", False)
        if not isinstance(between, bool):
            raise ProblemError(_join(rp, "between_ticks"), f"must be true or false, got "
                                                           f"{_kind(between)}")
        if between and not tick:
            raise ProblemError(_join(rp, "between_ticks"), 'needs every = "tick" (a grid '
                                                           'region holds at its grid points)')
        if tick:   # met by the design's constraint generation, not by a knot per tick
            zero = np.flatnonzero(~np.any(C != 0, axis=1))
            if zero.size:
                raise ProblemError(_join(rp, "C"), f"row {int(zero[0])} is zero: it constrains "
                                                   f"no output")
            region = TickRegion((a, b), C, lo, hi, i, between)
            if region.ticks(t0, tick_hz).size or between:
                ticked.append(region)
            continue
        count = int(np.floor((b - a) / every - 1e-9))
        if len(out) + count > _MAX_GRID_POINTS:   # bound the work before building them
            raise ProblemError(_join(rp, "every"), f"gives {len(out) + count} band points in "
                                                   f"all regions; at most {_MAX_GRID_POINTS}")
        for j in range(1, count + 1):
            out.append((a + j * every, Constraint(C, None, lo, hi)))
    return out


def _check_output_scale(C: np.ndarray, path: str) -> None:
    """A corridor's outputs ``y = C x`` are measured in the file's units (walls, reports and
    plots use them), so their rows are not rescaled: a subnormal coefficient, or a row whose
    largest coefficient is outside [1e-150, 1e150] (beyond which the outputs' covariance
    ``C P C'`` under- or overflows), is refused."""
    check_no_subnormal(C, path)
    top = np.abs(C).max(axis=1)
    bad = np.flatnonzero((top > 0) & ((top < _OUTPUT_SCALE[0]) | (top > _OUTPUT_SCALE[1])))
    if bad.size:
        i = int(bad[0])
        raise ProblemError(f"{path}[{i}]", f"has largest coefficient {top[i]:g}, outside "
                                           f"[{_OUTPUT_SCALE[0]:g}, {_OUTPUT_SCALE[1]:g}] (the "
                                           f"outputs' covariance would under- or overflow); "
                                           f"measure the output in other units")


def _normalised_band(C, c_path, lo_path, lo, hi_path, hi):
    """``(C, lower, upper)`` with every row scaled to a largest coefficient in [1, 2)
    (`stospline.problem.rows`)."""
    C, b = normalise_rows(C, c_path, {lo_path: lo, hi_path: hi})
    return C, b[lo_path], b[hi_path]


def _parse_corridors(raw: Any, n: int, t0: float, t_end: float,
                     tick_hz: int) -> tuple[Corridor, ...]:
    """``[[corridors]]``: ``C x(t)`` inside a union of convex polygons ``{A y <= b}`` at every
    tick of ``t = [a, b]`` (both ends), with an optional risk budget ``epsilon``."""
    if not isinstance(raw, list):
        raise ProblemError("corridors", f"must be an array of tables ([[corridors]]), got "
                                        f"{_kind(raw)}")
    out = []
    for i, cor in enumerate(raw):
        cp = f"corridors[{i}]"
        _check_keys(cor, cp, {"t", "C", "polygons", "epsilon"}, {"t", "C", "polygons"})
        a, b = _vector(cor["t"], _join(cp, "t"), 2)
        if not t0 <= a <= b <= t_end:
            raise ProblemError(_join(cp, "t"), f"must be [start, end] with {t0:g} <= start <= "
                                               f"end <= {t_end:g} (the last knot)")
        for end in (a, b):
            ticks = (end - t0) * tick_hz
            if abs(ticks - round(ticks)) > 1e-9 * max(1.0, ticks):
                raise ProblemError(_join(cp, "t"), f"{end:g} s is not a whole number of ticks "
                                                   f"after t0 at tick_hz = {tick_hz}: the "
                                                   f"corridor is checked at the ticks")
        C = _matrix(cor["C"], _join(cp, "C"), (None, n), (" (one row per output)",
                                                          _N_IS_LEN_X0))
        _check_output_scale(C, _join(cp, "C"))
        p = C.shape[0]
        if p > _MAX_CORRIDOR_OUTPUTS:
            raise ProblemError(_join(cp, "C"), f"has {p} rows; at most {_MAX_CORRIDOR_OUTPUTS} "
                                               f"outputs")
        polys = cor["polygons"]
        pp = _join(cp, "polygons")
        if not isinstance(polys, list) or not polys:
            raise ProblemError(pp, f"must be a non-empty array of {{ A = [[...]], b = [...] }} "
                                   f"tables (A y <= b), got {polys!r}")
        parsed, walls = [], 0
        for k, poly in enumerate(polys):
            kp = f"{pp}[{k}]"
            _check_keys(poly, kp, {"A", "b"}, {"A", "b"})
            A = _matrix(poly["A"], _join(kp, "A"), (None, p),
                        ("", f" (p = {p}, the rows of {_join(cp, 'C')})"))
            bv = _vector(poly["b"], _join(kp, "b"), A.shape[0], " (one entry per row of A)")
            zero = np.flatnonzero(~np.any(A != 0, axis=1))
            if zero.size:
                raise ProblemError(f"{kp}.A[{int(zero[0])}]", "is all zeros: a wall needs a "
                                                              "direction")
            A, scaled = normalise_rows(A, _join(kp, "A"), {_join(kp, "b"): bv})
            bv = scaled[_join(kp, "b")]
            walls += A.shape[0]
            if walls > _MAX_CORRIDOR_WALLS:
                raise ProblemError(_join(kp, "A"), f"gives {walls} walls (rows of A) in the "
                                                   f"corridor; at most {_MAX_CORRIDOR_WALLS}")
            parsed.append((A, bv))
        eps = None
        if "epsilon" in cor:
            eps = _number(cor["epsilon"], _join(cp, "epsilon"))
            if not 0.0 < eps < 1.0:
                raise ProblemError(_join(cp, "epsilon"), f"must be a probability in (0, 1), "
                                                         f"got {eps:g}")
        out.append(Corridor((float(a), float(b)), C, tuple(parsed), eps))
    return tuple(out)


def parse_problem(doc: dict, *, source_sha256: str = "") -> Problem:
    """Validate a decoded TOML document (or the same structure built in Python: any numpy
    array, numpy scalar or tuple is taken as the list or number it holds) and return a
    `Problem`.

    The key reference is ``docs/guide/problem-file.md``.  With ``[[stages]]`` (one entry per knot),
    stage ``k`` takes each key of ``[dynamics]``/``[cost]`` from ``stages[k].dynamics`` /
    ``stages[k].cost`` when given there, else from the top-level table.

    Raises
    ------
    ProblemError
        Naming the field by its path in the file and the reason.
    """
    doc = _plain(doc)   # numpy arrays, numpy scalars and tuples from Python callers
    if not doc:
        raise ProblemError("<file>", "is empty; a problem needs name, x0, tick_hz, "
                                     "[dynamics], [cost] and [[knots]]")
    _check_keys(doc, "", _TOP_KEYS, _TOP_REQUIRED)
    name = doc["name"]
    if not isinstance(name, str) or not _C_IDENTIFIER.fullmatch(name):
        raise ProblemError("name", f"must be a C identifier (ASCII letters, digits, "
                                   f"underscore; not starting with a digit), got {name!r}")
    if name in _C_KEYWORDS or name.startswith("__") or re.match(r"_[A-Z]", name):
        raise ProblemError("name", f"{name!r} is a C keyword or reserved identifier; the "
                                   f"generated tables are named after it")
    check_name(name)
    x0 = _vector(doc["x0"], "x0", None)
    check_state(x0)
    n = x0.shape[0]
    t0 = _number(doc.get("t0", 0.0), "t0")
    tick_hz = _int(doc["tick_hz"], "tick_hz", 1, _U32_MAX, "the tick rate in Hz")

    dyn = _check_keys(doc["dynamics"], "dynamics", _DYN_KEYS, _DYN_REQUIRED)
    cost = _check_keys(doc["cost"], "cost", _COST_KEYS, _COST_REQUIRED)
    default = _parse_stage([(dyn, "dynamics")], [(cost, "cost")], n, None)

    raw_knots = doc["knots"]
    if not isinstance(raw_knots, list) or not raw_knots:
        raise ProblemError("knots", f"must be a non-empty array of tables ([[knots]]), "
                                    f"got {_kind(raw_knots)}")
    knots = tuple(_parse_knot(k, f"knots[{i}]", n) for i, k in enumerate(raw_knots))
    _check_times(knots, t0, tick_hz)

    if "stages" in doc:
        m_ref = (_first(default.fields["B"]).shape[1], default.B_path)
        data = [_parse_stage([(sd, f"stages[{k}].dynamics"), (dyn, "dynamics")],
                             [(sc, f"stages[{k}].cost"), (cost, "cost")], n, m_ref)
                for k, (sd, sc) in enumerate(_parse_stage_overrides(doc["stages"], len(knots)))]
    else:
        data = [default] * len(knots)
    ticked: list[TickRegion] = []
    if "regions" in doc:
        # Region bands become extra knots; each splits the stage it falls in, whose data the
        # pieces share. A band at an existing knot adds rows to that knot's constraint.
        merged = {kn.t: (kn, d) for kn, d in zip(knots, data)}
        user_t = np.array([kn.t for kn in knots])
        bands = _parse_regions(doc["regions"], n, t0, knots[-1].t, tick_hz, ticked)
        check_stage_count([kn.t for kn in knots], [t for t, _ in bands])
        # Every knot and band time falls on a tick: look times up by tick index (a scan of
        # all knots per band point made a grid of 10^5 points take hours).
        at_tick = {round((tk - t0) * tick_hz): tk for tk in merged}
        for t, con in bands:
            hit = at_tick.get(round((t - t0) * tick_hz))
            if hit is None:
                stage_data = data[int(np.searchsorted(user_t, t - 1e-12))]
                merged[t] = (Knot(t, None, con), stage_data)
                at_tick[round((t - t0) * tick_hz)] = t
            else:
                kn, stage_data = merged[hit]
                merged[hit] = (Knot(kn.t, kn.penalty, merge_constraints(kn.constraint, con)),
                               stage_data)
        order = sorted(merged)
        knots = tuple(merged[t][0] for t in order)
        data = [merged[t][1] for t in order]
        _check_times(knots, t0, tick_hz)
    # Every stage has the same number mz of Brownian components: the first noise matrix given
    # sets it; a stage without noise gets zero matrices of that width.
    first = next((g for d in [default, *data] for g in d.noise), None)
    mz = 1 if first is None else _first(first[1]).shape[1]
    for d in data:
        for _, g, gp in d.noise:
            if _first(g).shape[1] != mz:
                raise ProblemError(gp, f"has {_first(g).shape[1]} columns but {first[2]} has "
                                       f"{mz}; "
                                       f"every stage must have the same number of Brownian "
                                       f"components mz (columns of G)")
    times = [t0] + [kn.t for kn in knots]
    for k, d in enumerate(data):
        for ser in d.series():
            if ser.t[0] > times[k] + 1e-12 or ser.t[-1] < times[k + 1] - 1e-12:
                where = f"stages[{k}]" if "stages" in doc else "every stage"
                raise ProblemError(_join(ser.path, "t"), f"samples cover [{ser.t[0]:g}, "
                                   f"{ser.t[-1]:g}] but {where} needs [{times[k]:g}, "
                                   f"{times[k + 1]:g}]")
    built = {id(d): d.build(n, mz) for d in data}
    stages = tuple(built[id(d)] for d in data)

    u_min, u_max, u_hold = _parse_limits(doc, stages[0].B.shape[1])
    plot = _parse_plot(doc.get("plot", {}), n)
    options = _check_keys(doc.get("design", {}), "design", set(_DESIGN_OPTIONS), set())
    for key, value in options.items():
        if key == "delay_ticks" and (isinstance(value, bool) or not isinstance(value, int)
                                     or value not in (0, 1)):
            raise ProblemError("design.delay_ticks", f"must be 0 or 1 (ticks between "
                                                     f"measuring x and applying its command), "
                                                     f"got {value!r}")
        if key == "spline_tolerance":
            options[key] = check_spline_tolerance(value, "design.spline_tolerance")
            continue
        if value not in _DESIGN_OPTIONS[key]:
            raise ProblemError(f"design.{key}", f"must be one of {list(_DESIGN_OPTIONS[key])}, "
                                                f"got {value!r}")
    faults = parse_faults(doc.get("faults", {}), n, stages[0].B.shape[1])
    corridors = (_parse_corridors(doc["corridors"], n, t0, knots[-1].t, tick_hz)
                 if "corridors" in doc else ())
    measurement = None
    if "measurement" in doc:
        measurement = parse_measurement(doc["measurement"], n)
    problem = Problem(name, t0, x0, tick_hz, stages, knots, source_sha256, plot, dict(options),
                      u_min, u_max, faults, u_hold, corridors, tuple(ticked), measurement)
    check_problem(problem, B_path=default.B_path)   # the firmware's limits (limits.py)
    if "parameters" in doc:
        problem = replace(problem, parameters=parse_parameters(
            doc["parameters"], doc, problem, check_keys=_check_keys, number=_number, kind=_kind))
    return problem


def load_problem(path: str | Path) -> Problem:
    """Read and validate a TOML problem file (reference: ``docs/guide/problem-file.md``).

    The file is read with bounds (`stospline.problem.inputfile`): a regular file (or a symlink
    to one) of at most 16 MiB, UTF-8, arrays and tables nested at most 32 deep.

    Parameters
    ----------
    path : str or Path
        The problem file.

    Returns
    -------
    Problem
        Validated data; ``source_sha256`` is the SHA-256 of the file's bytes, which the
        generated tables carry.

    Raises
    ------
    ProblemError
        The file is not valid TOML or not a valid problem; names the field and the reason.
        A file that cannot be read is field ``<file>``; when it does not exist the error is
        also a FileNotFoundError.

    Examples
    --------
    >>> import stospline
    >>> p = stospline.load_problem("examples/robot_corridor.toml")
    >>> p.n, p.m, p.tick_hz, [knot.t for knot in p.knots]
    (4, 2, 1000, [3.0, 6.0])
    """
    data = read_problem_file(path)
    doc = decode_problem(data)
    try:
        return parse_problem(doc, source_sha256=hashlib.sha256(data).hexdigest())
    except (OverflowError, MemoryError, RecursionError) as exc:   # last resort: no traceback
        raise ProblemError("<file>", f"a value is too large or too deeply nested to handle "
                                     f"({type(exc).__name__}: {exc})") from None
