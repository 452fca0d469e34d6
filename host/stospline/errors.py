"""The package's exceptions; every layer raises them, so this module imports nothing of the
package. The command line maps each to exit status 2."""

__all__ = ["ProblemError", "DesignError", "BudgetError"]


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



class DesignError(ProblemError):
    """The problem is well-formed but has no solution (infeasible constraint, finite escape)."""


class BudgetError(ProblemError):
    """The run would exceed the memory or time limit; `field` is the problem-file key (or
    command-line option) whose value causes the largest part of the estimate."""
