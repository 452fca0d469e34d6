"""Checked values of a decoded problem file: each helper takes the raw value and its field
path and returns the value checked, or raises `ProblemError` naming the field. Shared by the
reader and the tables it delegates to (`measurement`), which cannot import the reader."""
from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np

from stospline.errors import ProblemError

__all__ = ["check_keys", "join", "kind", "number", "integer", "matrix", "vector"]


def join(path: str, key: str) -> str:
    return f"{path}.{key}" if path else key


def kind(value: Any) -> str:
    """The TOML name of a decoded value's type, for messages."""
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, (int, float)):
        return "a number"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, list):
        return "an array"
    if isinstance(value, dict):
        return "a table"
    return "a date/time"  # the only other TOML type


def check_keys(table: Any, path: str, allowed: set[str], required: set[str], *,
               hint: Callable[[str], str] | None = None) -> dict:
    """`table` if it is a table with only `allowed` keys and every `required` one; an unknown
    key is named with the closest allowed one (and `hint(key)`, if given, appended)."""
    if not isinstance(table, dict):
        raise ProblemError(path or "<file>", f"must be a table, got {kind(table)}")
    for key in table:
        if key not in allowed:
            import difflib               # here: only a misspelt key needs it
            close = difflib.get_close_matches(key, allowed, n=1)
            more = f"did you mean '{close[0]}'? " if close else ""
            more += hint(key) if hint is not None else ""
            raise ProblemError(join(path, key), f"unknown key ({more}allowed here: "
                                                f"{', '.join(sorted(allowed))})")
    for key in sorted(required):
        if key not in table:
            raise ProblemError(join(path, key), "is required")
    return table


def number(value: Any, path: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ProblemError(path, f"must be a number, got {kind(value)} ({value!r})")
    if not math.isfinite(value):
        raise ProblemError(path, f"must be finite, got {value} (NaN and Inf are not allowed)")
    return float(value)


def integer(value: Any, path: str, lo: int, hi: int, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise ProblemError(path, f"must be {what}, an integer in {lo}..{hi}, got {value!r}")
    return value


def matrix(value: Any, path: str, shape: tuple[int | None, int | None],
           why: tuple[str, str] = ("", "")) -> np.ndarray:
    if (not isinstance(value, list) or not value
            or not all(isinstance(r, list) and r for r in value)):
        raise ProblemError(path, "must be a matrix: a non-empty array of non-empty rows, "
                                 f"e.g. [[1, 0], [0, 1]]; got {value!r}")
    widths = {len(r) for r in value}
    if len(widths) != 1:
        raise ProblemError(path, f"rows have different lengths {sorted(widths)}")
    out = np.array([[number(v, f"{path}[{i}][{j}]") for j, v in enumerate(row)]
                    for i, row in enumerate(value)])
    for axis, (got, want) in enumerate(zip(out.shape, shape)):
        if want is not None and got != want:
            what = "rows" if axis == 0 else "columns"
            raise ProblemError(path, f"has {got} {what}, expected {want}{why[axis]} "
                                     f"(shape {out.shape[0]}x{out.shape[1]})")
    return out


def vector(value: Any, path: str, length: int | None, why: str = "") -> np.ndarray:
    if not isinstance(value, list) or not value:
        raise ProblemError(path, f"must be a non-empty array of numbers (a vector), "
                                 f"got {value!r}")
    out = np.array([number(v, f"{path}[{i}]") for i, v in enumerate(value)])
    if length is not None and out.shape[0] != length:
        raise ProblemError(path, f"has length {out.shape[0]}, expected {length}{why}")
    return out
