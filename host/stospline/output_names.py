"""The names of the files a run writes: one place for the pipeline that writes them, the
command line that checks its ``--out`` before any work, and the tests.

The stem is also the C prefix of the tables' symbols (`stospline.table.codegen`), so several
designs link into one image: ``<name>``, ``<name>_<arith>`` for Q15/Q31, and ``_spline``
appended for a spline table.
"""
from __future__ import annotations

__all__ = ["table_stem", "table_files", "corridor_design_files", "TABLE_SUFFIXES"]

TABLE_SUFFIXES = (".h", ".c", ".json")


def table_stem(name: str, arith: str = "float32", spline: bool = False) -> str:
    """``<name>[_<arith>][_spline]``: the arithmetic only when it is not float32."""
    return (name if arith == "float32" else f"{name}_{arith}") + ("_spline" if spline else "")


def table_files(name: str, arith: str = "float32", spline: bool = False) -> list[str]:
    """The header, source and JSON summary of a design's tables, in that order."""
    stem = table_stem(name, arith, spline)
    return [stem + suffix for suffix in TABLE_SUFFIXES]


def corridor_design_files(name: str) -> list[str]:
    """What ``corridor-design`` writes: the designed problem file, its float32 per-tick
    tables and the certificate (the order in which a refused ``--out`` names them)."""
    header, source, summary = table_files(name)
    return [f"{name}.toml", source, header, summary, f"{name}_corridor.json"]
