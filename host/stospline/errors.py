"""The package's exception hierarchy: every exception the package raises derives from
`StosplineError`, so a caller catches them all at once and the command line maps them to exit
status 2 (one line). Every layer raises them, so this module imports nothing of the package.

Each class also derives from the built-in exception a caller would expect (``ValueError`` for a
bad value, ``RuntimeError`` for a failed build, ...), so ``except ValueError`` keeps working.
The subclasses that belong to one module (`stospline.atomic.OutputError`,
`stospline.cache.CompilerMissing`, ...) are defined there, on this base.
"""

__all__ = ["StosplineError", "ProblemError", "DesignError", "BudgetError", "KernelBuildError"]


class StosplineError(Exception):
    """Base class of every exception the package defines."""


class ProblemError(StosplineError, ValueError):
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


class DesignError(ProblemError):
    """The problem is well-formed but has no solution (infeasible constraint, finite escape)."""


class BudgetError(ProblemError):
    """The run would exceed the memory or time limit; `field` is the problem-file key (or
    command-line option) whose value causes the largest part of the estimate."""


class KernelBuildError(StosplineError, RuntimeError):
    """A C kernel of the design or the table could not be compiled or loaded (no C compiler,
    no cffi); the callers fall back to numpy where they can."""
