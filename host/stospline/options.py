"""The design options of one run, resolved once: an override (a library argument or a
command-line option) first, then the problem file's ``[design]`` table, then the default.

This is the only reader of ``Problem.options``; everything downstream takes a
`DesignOptions`. Values are checked here as far as they can be without the problem's
structure (the table kind, the spline tolerance); what depends on it (a mode's latch width,
a delay's discretization) is checked when the design starts (`stospline.pipeline`).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, replace

from stospline.table_options import (DEFAULT_SPLINE_TOLERANCE, TABLE_KINDS,
                                     check_spline_tolerance)

__all__ = ["DesignOptions", "resolve_options", "with_file_options", "DISCRETIZATIONS"]

DISCRETIZATIONS = ("exact-zoh", "continuous")


@dataclass(frozen=True)
class DesignOptions:
    """How a problem is designed and written (docs/guide/problem-file.md, ``[design]``); the
    field defaults are the defaults of the options."""
    noise: bool = True                 # False: design as if there were no noise
    mode: str = "stagewise"            # or "joint"
    discretization: str = "exact-zoh"  # or "continuous"
    delay_ticks: int = 0               # 1: designed for a one-tick computation delay
    table: str = "per-tick"            # or "spline"
    spline_tolerance: float = DEFAULT_SPLINE_TOLERANCE
    arith: str = "float32"             # of the written tables: or "q15", "q31"

    @property
    def spline(self) -> bool:
        return self.table == "spline"

    def workload(self) -> dict:
        """The options that size the work, as `stospline.budget.estimate` takes them."""
        return {k: v for k, v in asdict(self).items() if k not in ("noise", "arith")}


def resolve_options(problem, *, noise: bool = True, mode: str | None = None,
                    discretization: str | None = None, delay_ticks: int | None = None,
                    table: str | None = None, spline_tolerance: float | None = None,
                    arith: str | None = None,
                    tolerance_field: str = "spline_tolerance") -> DesignOptions:
    """The options of a run on `problem`: each given value (not None), else the file's
    ``[design]`` value, else the default.

    Raises ValueError for an unknown table kind and ProblemError naming `tolerance_field`
    for a spline tolerance outside its range."""
    file, default = problem.options, DesignOptions()
    table = table or file.get("table", default.table)
    if table not in TABLE_KINDS:
        raise ValueError(f"table must be one of {TABLE_KINDS}, got {table!r}")
    tolerance = file.get("spline_tolerance", default.spline_tolerance) \
        if spline_tolerance is None else spline_tolerance
    return DesignOptions(
        noise=noise,
        mode=mode or file.get("mode", default.mode),
        discretization=discretization or file.get("discretization", default.discretization),
        delay_ticks=file.get("delay_ticks", default.delay_ticks) if delay_ticks is None
        else delay_ticks,
        table=table,
        spline_tolerance=check_spline_tolerance(tolerance, tolerance_field),
        arith=arith or file.get("arith", default.arith))


def with_file_options(problem, **values):
    """`problem` with `values` written into its ``[design]`` table (a designed problem file
    that says how it was designed)."""
    return replace(problem, options={**problem.options, **values})
