#!/usr/bin/env python3
"""Size of the problem files `problem_to_toml` writes, against tomli-w's layout of the same
document, for every example.

    PYTHONPATH=host python tools/bench/toml_writer.py

For each example: our text (bytes, lines, longest line), and ``tomli_w.dumps`` of the document
that text parses to (tomli-w writes every array element on a line of its own, so a matrix
loses its rows). Both are checked to parse back to the same document. tomli-w is not a
dependency of the package: install it into the venv that runs this (``pip install tomli-w``).
"""
from __future__ import annotations

import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def layout(text: str) -> tuple[int, int, int]:
    """Bytes, lines and the longest line of `text`."""
    lines = text.splitlines()
    return len(text.encode()), len(lines), max(map(len, lines))


def main() -> None:
    try:
        import tomli_w
    except ImportError:
        sys.exit("toml_writer: needs tomli-w in this Python (pip install tomli-w)")
    import stospline
    from stospline.problem.toml_writer import problem_to_toml
    print(f"tomli-w {getattr(tomli_w, '__version__', '?')}")
    print("| example | ours: bytes | lines | longest line | tomli-w: bytes | lines | "
          "longest line |")
    print("|---|---|---|---|---|---|---|")
    for path in sorted((ROOT / "examples").glob("*.toml")):
        ours = problem_to_toml(stospline.load_problem(path))
        doc = tomllib.loads(ours)
        theirs = tomli_w.dumps(doc)
        if tomllib.loads(theirs) != doc:
            sys.exit(f"toml_writer: tomli-w's text of {path.name} parses to another document")
        a, b = layout(ours), layout(theirs)
        print(f"| {path.name} | {a[0]} | {a[1]} | {a[2]} | {b[0]} | {b[1]} | {b[2]} |")


if __name__ == "__main__":
    main()
