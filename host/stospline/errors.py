"""The package's two exceptions; every layer raises them, so this module imports nothing of
the package."""

__all__ = ["ProblemError", "DesignError"]


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
