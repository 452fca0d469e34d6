"""The problem: its data model (`model`), the TOML reader that builds it (`inputfile`, `model`),
name rules for the generated C (`names`), builders from arrays (`build`) and the writer back to
TOML (`toml_writer`). The lowest layer: imports nothing of design, table, sim or report."""
from stospline.problem.model import (Constraint, Knot, Penalty, Problem, ProblemError, Series,
                                     Stage)
from stospline.problem.reader import load_problem, parse_problem

__all__ = ["ProblemError", "Stage", "Penalty", "Constraint", "Knot", "Problem", "Series",
           "load_problem", "parse_problem"]
