"""The ``[plant]`` table of a problem file: a nonlinear plant model in C, its parameters and
how the design linearises it (`stospline.nonlinear`). Checked here, compiled by
`stospline.problem.plant_c`."""
from __future__ import annotations

import os
import stat
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from stospline.errors import ProblemError
from stospline.problem.fields import check_keys, integer, kind, matrix, number, vector

__all__ = ["PlantSpec", "parse_plant", "PLANT_KEYS", "MAX_SOURCE_BYTES"]

PLANT_KEYS = {"source", "params", "guess", "tolerance", "max_iterations"}
MAX_SOURCE_BYTES = 1024 * 1024      # a model is a few functions; a larger file is a mistake
DEFAULT_TOLERANCE = 1e-6
DEFAULT_MAX_ITERATIONS = 20


@dataclass(frozen=True)
class PlantSpec:
    """A checked ``[plant]`` table. ``guess`` is the first path linearised around, as
    ``(t, x, u)`` samples (linear interpolation; `u` None: zero input), or None: x0 held with
    zero input."""
    path: Path                 # the model file, resolved against the problem file's directory
    source: bytes
    params: np.ndarray
    guess: tuple | None
    tolerance: float
    max_iterations: int


def _read_source(value, base_dir: Path) -> tuple[Path, bytes]:
    if not isinstance(value, str) or not value:
        raise ProblemError("plant.source", f"must be a path to a C file (relative to the "
                                           f"problem file), got {kind(value)}")
    path = (base_dir / value) if not os.path.isabs(value) else Path(value)
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError as exc:
        raise ProblemError("plant.source", f"cannot read {value!r}: "
                                           f"{exc.strerror.lower()}") from None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise ProblemError("plant.source", f"{value!r} is not a regular file")
        with os.fdopen(fd, "rb", closefd=False) as f:
            data = f.read(MAX_SOURCE_BYTES + 1)
    finally:
        os.close(fd)
    if len(data) > MAX_SOURCE_BYTES:
        raise ProblemError("plant.source", f"{value!r} is larger than {MAX_SOURCE_BYTES} bytes")
    try:
        data.decode("ascii")
    except UnicodeDecodeError:
        raise ProblemError("plant.source", f"{value!r} is not ASCII C text") from None
    if b"\0" in data:
        raise ProblemError("plant.source", f"{value!r} contains a NUL byte")
    return path, data


def _parse_guess(raw, n: int) -> tuple:
    check_keys(raw, "plant.guess", {"t", "x", "u"}, {"t", "x"})
    t = vector(raw["t"], "plant.guess.t", None)
    if t.size < 2 or np.any(np.diff(t) <= 0):
        raise ProblemError("plant.guess.t", "must be at least 2 strictly increasing times")
    x = matrix(raw["x"], "plant.guess.x", (t.size, n),
               (" (one per time of plant.guess.t)", " (n, the length of x0)"))
    u = None
    if "u" in raw:
        u = matrix(raw["u"], "plant.guess.u", (t.size, None),
                   (" (one per time of plant.guess.t)", ""))
    return t, x, u


def parse_plant(raw, base_dir: str | Path, n: int) -> PlantSpec:
    """Check a decoded ``[plant]`` table; `base_dir` is the problem file's directory, `n` the
    length of x0. Raises `ProblemError` naming ``plant.<key>``."""
    check_keys(raw, "plant", PLANT_KEYS, {"source"})
    path, source = _read_source(raw["source"], Path(base_dir))
    params = raw.get("params", [])
    params = np.zeros(0) if params == [] else vector(params, "plant.params", None)
    guess = _parse_guess(raw["guess"], n) if "guess" in raw else None
    tol = DEFAULT_TOLERANCE
    if "tolerance" in raw:
        tol = number(raw["tolerance"], "plant.tolerance")
        if not 0 < tol < 1:
            raise ProblemError("plant.tolerance", f"must be in (0, 1) (the largest change of "
                                                  f"the mean path between two iterations, "
                                                  f"relative to its size), got {tol}")
    iters = DEFAULT_MAX_ITERATIONS
    if "max_iterations" in raw:
        iters = integer(raw["max_iterations"], "plant.max_iterations", 1, 1000,
                        "iterations of plan -> linearise -> design")
    return PlantSpec(path, source, params, guess, tol, iters)
