"""stospline: control-theoretic splines for linear systems with multiplicative noise.

The public API (``docs/guide/library.md`` shows the design -> table -> simulate path)::

    import stospline as ss
    problem = ss.load_problem("robot.toml")            # or ss.problem_from_arrays(A, B, Q, R, ...)
    d = ss.design_problem(problem)                     # design, float32 table, oracle
    g = d.gains()                                      # t, K (n_ticks, m, n), k0, L as numpy
    files = ss.generated_files(d, "robot.toml")        # C tables + JSON summary, as text
    mc = ss.simulate_problem(d, paths=1000, seed=1)    # Monte Carlo of the compiled C

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
    "Designed": "pipeline", "design_problem": "pipeline", "design_summary": "pipeline",
    "generated_files": "pipeline", "write_outputs": "pipeline", "start_from": "pipeline",
    "fixed_table": "pipeline", "DesignError": "errors", "Gains": "gains",
    "flash_bytes": "table.flash",
    # running the compiled firmware
    "simulate_problem": "pipeline", "simulation_summary": "pipeline",
    "build_controller": "sim.controller", "generate_c": "table.codegen", "plot_corridor": "report.plot",
}

__all__ = ["__version__", *_EXPORTS]


def _version() -> str:
    """The installed distribution's version: the package metadata is the single source."""
    from importlib.metadata import PackageNotFoundError, version
    try:
        return version("stospline")
    except PackageNotFoundError:     # a source tree on sys.path without installation
        return "0+unknown"


def __getattr__(name: str):
    if name == "__version__":        # read on first use: importlib.metadata is slow to import
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
