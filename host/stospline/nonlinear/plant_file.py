"""Whether a problem file is a ``[plant]`` problem: what the command line asks of every file
before it picks a loader, kept apart from the linearisation so that asking loads none of it."""
from __future__ import annotations

from pathlib import Path

from stospline.errors import ProblemError
from stospline.problem.inputfile import decode_problem, read_problem_file

__all__ = ["has_plant"]


def has_plant(path: str | Path) -> bool:
    """Whether the problem file at `path` has a ``[plant]`` table (False when it cannot be
    read: the ordinary loader then says why)."""
    try:
        doc = decode_problem(read_problem_file(path))
    except ProblemError:
        return False
    return isinstance(doc, dict) and "plant" in doc
