"""Problem specification: read a TOML problem file into a validated, typed `Problem`.

Every error names the offending field by its path in the file (``knots[1].constraint.C``)
and says why, so a user can fix the file without reading this code.
"""
from __future__ import annotations

import hashlib
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["ProblemError", "Stage", "Penalty", "Constraint", "Knot", "Problem",
           "load_problem", "parse_problem"]


class ProblemError(ValueError):
    """A problem file or problem object is invalid.

    Attributes
    ----------
    field : str
        Path of the offending field, e.g. ``"knots[0].penalty.weight"``.
    reason : str
        What is wrong with it.
    """

    def __init__(self, field: str, reason: str):
        super().__init__(f"{field}: {reason}")
        self.field = field
        self.reason = reason


@dataclass(frozen=True)
class Stage:
    """Data of one stage ``[t_k, t_{k+1}]`` (time-invariant within the stage).

    ``G[i]`` (n x mz) multiplies the state component ``x_i`` in the diffusion term.
    The running cost is ``x'Qx + 2x'Su + u'Ru + 2q'x + 2r'u + rho``.
    """
    A: np.ndarray
    B: np.ndarray
    G: np.ndarray          # shape (n, n, mz)
    Q: np.ndarray
    S: np.ndarray
    R: np.ndarray
    q: np.ndarray
    r: np.ndarray
    rho: float

    def without_noise(self) -> "Stage":
        return Stage(self.A, self.B, np.zeros_like(self.G), self.Q, self.S, self.R,
                     self.q, self.r, self.rho)


@dataclass(frozen=True)
class Penalty:
    """Knot penalty ``weight * |C x - target|^2``."""
    C: np.ndarray
    target: np.ndarray
    weight: float


@dataclass(frozen=True)
class Constraint:
    """Knot constraint on the expected output ``E{C x} = value``."""
    C: np.ndarray
    value: np.ndarray


@dataclass(frozen=True)
class Knot:
    t: float
    penalty: Penalty | None
    constraint: Constraint | None

    @property
    def n_constraints(self) -> int:
        return 0 if self.constraint is None else self.constraint.C.shape[0]


@dataclass(frozen=True)
class Problem:
    """A validated stochastic spline problem; knot ``k`` closes stage ``k``."""
    name: str
    t0: float
    x0: np.ndarray
    tick_hz: int
    stages: tuple[Stage, ...]
    knots: tuple[Knot, ...]
    source_sha256: str = ""
    plot: dict = field(default_factory=dict)

    @property
    def n(self) -> int:
        return self.x0.shape[0]

    @property
    def m(self) -> int:
        return self.stages[0].B.shape[1]

    @property
    def mz(self) -> int:
        return self.stages[0].G.shape[2]

    @property
    def times(self) -> np.ndarray:
        """Stage boundaries ``t_0 < t_1 < ... < t_N``."""
        return np.array([self.t0] + [kn.t for kn in self.knots])

    @property
    def ticks_per_stage(self) -> np.ndarray:
        return np.rint(np.diff(self.times) * self.tick_hz).astype(int)

    @property
    def max_constraints(self) -> int:
        return max(kn.n_constraints for kn in self.knots)

    def without_noise(self) -> "Problem":
        """The same problem with every diffusion term removed (the paper's Remark 2)."""
        return Problem(self.name, self.t0, self.x0, self.tick_hz,
                       tuple(s.without_noise() for s in self.stages), self.knots,
                       self.source_sha256, self.plot)


# ---------------------------------------------------------------------------------------
# Parsing helpers: each takes the raw value and its field path, returns a checked value.

def _check_keys(table: Any, path: str, allowed: set[str], required: set[str]) -> dict:
    if not isinstance(table, dict):
        raise ProblemError(path or "<file>", "must be a table")
    for key in table:
        if key not in allowed:
            hint = ", ".join(sorted(allowed))
            raise ProblemError(_join(path, key), f"unknown key (allowed here: {hint})")
    for key in sorted(required):
        if key not in table:
            raise ProblemError(_join(path, key), "is required")
    return table


def _join(path: str, key: str) -> str:
    return f"{path}.{key}" if path else key


def _number(value: Any, path: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ProblemError(path, f"must be a number, got {type(value).__name__}")
    if not math.isfinite(value):
        raise ProblemError(path, "must be finite (NaN and Inf are not allowed)")
    return float(value)


def _matrix(value: Any, path: str, shape: tuple[int | None, int | None]) -> np.ndarray:
    if not isinstance(value, list) or not value or not all(isinstance(r, list) for r in value):
        raise ProblemError(path, "must be a non-empty list of rows (a matrix)")
    widths = {len(r) for r in value}
    if len(widths) != 1:
        raise ProblemError(path, f"rows have different lengths {sorted(widths)}")
    out = np.array([[_number(v, f"{path}[{i}][{j}]") for j, v in enumerate(row)]
                    for i, row in enumerate(value)])
    _check_shape(out, path, shape)
    return out


def _vector(value: Any, path: str, length: int | None) -> np.ndarray:
    if not isinstance(value, list) or not value:
        raise ProblemError(path, "must be a non-empty list of numbers (a vector)")
    out = np.array([_number(v, f"{path}[{i}]") for i, v in enumerate(value)])
    if length is not None and out.shape[0] != length:
        raise ProblemError(path, f"has length {out.shape[0]}, expected {length}")
    return out


def _check_shape(a: np.ndarray, path: str, shape: tuple[int | None, int | None]) -> None:
    for axis, (got, want) in enumerate(zip(a.shape, shape)):
        if want is not None and got != want:
            what = "rows" if axis == 0 else "columns"
            raise ProblemError(path, f"has {got} {what}, expected {want} "
                                     f"(shape {a.shape[0]}x{a.shape[1]})")


def _parse_stage(dyn: dict, cost: dict, n: int, path_dyn: str, path_cost: str) -> Stage:
    _check_keys(dyn, path_dyn, {"A", "B", "noise"}, {"A", "B"})
    _check_keys(cost, path_cost, {"Q", "S", "R", "q", "r", "rho"}, {"R"})
    A = _matrix(dyn["A"], _join(path_dyn, "A"), (n, n))
    B = _matrix(dyn["B"], _join(path_dyn, "B"), (n, None))
    m = B.shape[1]
    noise = dyn.get("noise", [])
    npath = _join(path_dyn, "noise")
    if not isinstance(noise, list):
        raise ProblemError(npath, "must be a list of {state = i, G = matrix} tables")
    mz = None
    for j, item in enumerate(noise):
        _check_keys(item, f"{npath}[{j}]", {"state", "G"}, {"state", "G"})
        g = _matrix(item["G"], f"{npath}[{j}].G", (n, mz))
        mz = g.shape[1]
    G = np.zeros((n, n, mz or 1))
    for j, item in enumerate(noise):
        spath = f"{npath}[{j}].state"
        i = item["state"]
        if isinstance(i, bool) or not isinstance(i, int) or not 0 <= i < n:
            raise ProblemError(spath, f"must be a state index 0..{n - 1}")
        if np.any(G[i]):
            raise ProblemError(spath, f"state {i} appears twice")
        G[i] = np.array(item["G"], dtype=float)

    R = _matrix(cost["R"], _join(path_cost, "R"), (m, m))
    Q = _matrix(cost["Q"], _join(path_cost, "Q"), (n, n)) if "Q" in cost else np.zeros((n, n))
    S = _matrix(cost["S"], _join(path_cost, "S"), (n, m)) if "S" in cost else np.zeros((n, m))
    q = _vector(cost["q"], _join(path_cost, "q"), n) if "q" in cost else np.zeros(n)
    r = _vector(cost["r"], _join(path_cost, "r"), m) if "r" in cost else np.zeros(m)
    rho = _number(cost["rho"], _join(path_cost, "rho")) if "rho" in cost else 0.0

    if not np.allclose(R, R.T, rtol=0, atol=1e-12 * max(1.0, np.abs(R).max())):
        raise ProblemError(_join(path_cost, "R"), "must be symmetric")
    if np.linalg.eigvalsh(R).min() <= 1e-12 * max(1.0, np.abs(R).max()):
        raise ProblemError(_join(path_cost, "R"), "must be positive definite")
    if not np.allclose(Q, Q.T, rtol=0, atol=1e-12 * max(1.0, np.abs(Q).max())):
        raise ProblemError(_join(path_cost, "Q"), "must be symmetric")
    H = np.block([[Q, S], [S.T, R]])
    if np.linalg.eigvalsh(H).min() < -1e-10 * max(1.0, np.abs(H).max()):
        raise ProblemError(path_cost, "[[Q, S], [S', R]] must be positive semidefinite "
                                      "(the paper's condition (3))")
    return Stage(A, B, G, Q, S, R, q, r, rho)


def _parse_knot(raw: dict, path: str, n: int) -> Knot:
    _check_keys(raw, path, {"t", "penalty", "constraint"}, {"t"})
    t = _number(raw["t"], _join(path, "t"))
    penalty = constraint = None
    if "penalty" in raw:
        pp = _join(path, "penalty")
        pen = _check_keys(raw["penalty"], pp, {"C", "target", "weight"},
                          {"C", "target", "weight"})
        C = _matrix(pen["C"], _join(pp, "C"), (None, n))
        target = _vector(pen["target"], _join(pp, "target"), C.shape[0])
        weight = _number(pen["weight"], _join(pp, "weight"))
        if weight < 0:
            raise ProblemError(_join(pp, "weight"), f"must be >= 0, got {weight}")
        penalty = Penalty(C, target, weight)
    if "constraint" in raw:
        cp = _join(path, "constraint")
        con = _check_keys(raw["constraint"], cp, {"C", "value"}, {"C", "value"})
        C = _matrix(con["C"], _join(cp, "C"), (None, n))
        value = _vector(con["value"], _join(cp, "value"), C.shape[0])
        constraint = Constraint(C, value)
    return Knot(t, penalty, constraint)


def parse_problem(doc: dict, *, source_sha256: str = "") -> Problem:
    """Validate a decoded TOML document and return a `Problem`.

    Raises
    ------
    ProblemError
        Naming the field and the reason.
    """
    _check_keys(doc, "", {"name", "t0", "x0", "tick_hz", "dynamics", "cost", "knots", "plot"},
                {"name", "x0", "tick_hz", "dynamics", "cost", "knots"})
    name = doc["name"]
    if not isinstance(name, str) or not name.isidentifier():
        raise ProblemError("name", "must be a C identifier (letters, digits, underscore)")
    x0 = _vector(doc["x0"], "x0", None)
    n = x0.shape[0]
    t0 = _number(doc.get("t0", 0.0), "t0")
    tick_hz = doc["tick_hz"]
    if isinstance(tick_hz, bool) or not isinstance(tick_hz, int) or tick_hz <= 0:
        raise ProblemError("tick_hz", "must be a positive integer (ticks per second)")

    stage = _parse_stage(doc["dynamics"], doc["cost"], n, "dynamics", "cost")

    raw_knots = doc["knots"]
    if not isinstance(raw_knots, list) or not raw_knots:
        raise ProblemError("knots", "must be a non-empty array of tables ([[knots]])")
    knots = tuple(_parse_knot(k, f"knots[{i}]", n) for i, k in enumerate(raw_knots))
    prev = t0
    for i, kn in enumerate(knots):
        if kn.t <= prev:
            raise ProblemError(f"knots[{i}].t", f"knot times must increase strictly "
                                                f"(t = {kn.t} after {prev})")
        ticks = (kn.t - prev) * tick_hz
        if abs(ticks - round(ticks)) > 1e-9 * max(1.0, ticks):
            raise ProblemError(f"knots[{i}].t", f"stage length {kn.t - prev} s is not a whole "
                                                f"number of ticks at tick_hz = {tick_hz}")
        prev = kn.t

    plot = doc.get("plot", {})
    _check_keys(plot, "plot", {"walls", "axes"}, set())
    if "walls" in plot:
        for i, wall in enumerate(plot["walls"]):
            _matrix(wall, f"plot.walls[{i}]", (None, 2))
    if "axes" in plot:
        ax = plot["axes"]
        if (not isinstance(ax, list) or len(ax) != 2
                or not all(isinstance(a, int) and 0 <= a < n for a in ax)):
            raise ProblemError("plot.axes", f"must be two state indices in 0..{n - 1}")

    stages = tuple(stage for _ in knots)
    return Problem(name, t0, x0, int(tick_hz), stages, knots, source_sha256, plot)


def load_problem(path: str | Path) -> Problem:
    """Read and validate a TOML problem file."""
    data = Path(path).read_bytes()
    try:
        doc = tomllib.loads(data.decode("utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ProblemError("<file>", f"not valid TOML: {exc}") from None
    return parse_problem(doc, source_sha256=hashlib.sha256(data).hexdigest())
