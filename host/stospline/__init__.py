"""stospline: control-theoretic splines for linear systems with multiplicative noise.

The public API, in the order a script uses it (``docs/guide/library.md`` walks through it)::

    import stospline as ss
    problem = ss.load_problem("robot.toml")          # or ss.problem_from_arrays(A, B, ...)
    d = ss.design_problem(problem)                   # design, float32 table, oracle
    exact = ss.table_of(d.design, quantize=False)    # the design's own per-tick law
    q15 = ss.fixed_point_table(d, "q15")             # fixed-point table with error bound
    header, source = ss.generate_c(d.table)          # the C text the firmware compiles
    ctl = ss.build_controller(d.table)               # the real firmware, through cffi
    mc = ss.simulate_problem(d, paths=1000, seed=1)  # Monte Carlo of the compiled C
    m = ss.evaluate_table(problem, q15)              # exact moments of a table as implemented

Each of these has a numpydoc docstring with Examples that the test command runs.
Names are loaded on first use, so ``import stospline`` stays cheap (no scipy, no compiler).
"""
from __future__ import annotations

from importlib import import_module

# public name -> module that defines it
_EXPORTS = {
    # problems
    "Problem": "problem.model", "ProblemError": "errors", "load_problem": "problem.reader",
    "parse_problem": "problem.reader",
    "problem_from_arrays": "problem.build", "problem_from_statespace": "problem.build",
    "problem_to_toml": "problem.toml_writer",
    # design and evaluation
    "Designed": "pipeline", "design_problem": "pipeline", "design_summary": "report.design_summary",
    "generated_files": "pipeline", "write_outputs": "pipeline", "start_from": "pipeline",
    "fixed_point_table": "pipeline", "DesignError": "errors", "Gains": "gains",
    "flash_bytes": "table.flash",
    # running the compiled firmware
    "simulate_problem": "pipeline", "simulation_summary": "report.simulation_summary",
    "table_of": "table.format", "evaluate_table": "oracle.evaluate",
    "build_controller": "harness.controller", "generate_c": "table.codegen", "plot_corridor": "report.plot",
}

__all__ = ["__version__", *_EXPORTS]


def _version() -> str:
    """The installed distribution's version: the package metadata is the single source."""
    from stospline.dist_version import installed_version
    # None: a source tree on sys.path without installation
    return installed_version() or "0+unknown"


def __getattr__(name: str):
    if name == "__version__":        # read on first use
        globals()["__version__"] = value = _version()
        return value
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'stospline' has no attribute {name!r}")
    value = getattr(import_module(f".{module}", __name__), name)
    globals()[name] = value          # later look-ups skip this function
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
