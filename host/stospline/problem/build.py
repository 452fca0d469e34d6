"""Problems built in Python: from plain ``A, B, Q, R`` arrays or a ``control.StateSpace``.

Both build the same document a TOML file decodes to and hand it to `parse_problem`, so a
problem built here meets exactly the checks a file meets, and an error names the field by its
key in the file (``dynamics.A``, ``knots[1].constraint.C``, ``cost.R``). Any array-like
(numpy arrays, nested lists or tuples) is accepted wherever the file takes an array.
"""
from __future__ import annotations

import hashlib
from dataclasses import replace
from typing import Any, Iterable, Mapping

import numpy as np

from stospline.errors import ProblemError
from stospline.problem.model import Problem
from stospline.problem.reader import parse_problem
from stospline.problem.toml_writer import problem_to_toml

__all__ = ["problem_from_arrays", "problem_from_statespace", "noise_entries"]


def noise_entries(G: Any) -> list[dict]:
    """``noise`` entries from a state-multiplicative tensor ``G`` of shape (n, n, mz):
    ``G[i]`` (n x mz) multiplies state ``x_i``; all-zero slices are left out."""
    G = np.asarray(G, dtype=float)
    if G.ndim != 3 or G.shape[0] != G.shape[1]:
        raise ProblemError("dynamics.noise", f"a noise tensor must have shape (n, n, mz), got "
                                             f"{G.shape}")
    return [{"state": i, "G": G[i]} for i in range(G.shape[0]) if np.any(G[i])]


def problem_from_arrays(A: Any, B: Any, Q: Any = None, R: Any = None, *, x0: Any,
                        knots: Iterable[Mapping], tick_hz: int, t0: float = 0.0,
                        name: str = "problem", noise: Any = None, S: Any = None,
                        q: Any = None, r: Any = None, rho: float | None = None,
                        u_min: Any = None, u_max: Any = None, u_hold: Any = None,
                        f: Any = None, faults: Mapping | None = None,
                        design: Mapping | None = None, plot: Mapping | None = None,
                        stages: Iterable[Mapping] | None = None,
                        regions: Iterable[Mapping] | None = None,
                        corridors: Iterable[Mapping] | None = None) -> Problem:
    """A validated `Problem` from arrays, with the same meaning as the problem file's keys
    (``docs/guide/problem-file.md``).

    Parameters
    ----------
    A, B : array-like, (n, n) and (n, m)
        Drift ``dx = (A x + B u + f) dt + ...``.
    f : array-like (n,), optional
        The affine drift (gravity, an offset), as the file's ``[dynamics] f``.
    Q, R : array-like, (n, n) and (m, m)
        Running cost ``x'Qx + u'Ru`` (Q defaults to zero; R is required).
    x0 : array-like, (n,)
    knots : iterable of mappings
        One per stage end, as the file's ``[[knots]]``: ``{"t": 3.0, "penalty": {"C": ...,
        "target": ..., "weight": ...}, "constraint": {"C": ..., "value": ...}}`` (or
        ``"lower"``/``"upper"`` for a band).
    tick_hz : int
        Controller tick rate; every stage must last a whole number of ticks.
    noise : array-like (n, n, mz), or a list of ``{"state": i, "G": ...}`` /
        ``{"input": j, "G": ...}`` entries as in the file. None: no noise.
    S, q, r, rho, u_min, u_max, u_hold, faults, design, plot, stages, regions, corridors
        As the file's keys of the same names.

    The problem's ``source_sha256`` is that of its TOML form (`problem_to_toml`), so the
    tables designed from it carry the hash of the file that ``problem.to_toml()`` writes.

    Returns
    -------
    Problem

    Raises
    ------
    ProblemError
        Naming the field by its key in the problem file, and the reason.

    Examples
    --------
    Steer ``dX = u dt + 0.3 X dZ`` from 1 so that ``E X(1) = 2``, with least effort and least
    variance at t = 1 (weight 10):

    >>> import stospline
    >>> p = stospline.problem_from_arrays(
    ...     [[0.0]], [[1.0]], R=[[1.0]], x0=[1.0], tick_hz=10, name="growth",
    ...     noise=[{"state": 0, "G": [[0.3]]}],
    ...     knots=[{"t": 1.0, "constraint": {"C": [[1.0]], "value": [2.0]},
    ...             "penalty": {"C": [[1.0]], "target": [2.0], "weight": 10.0}}])
    >>> p.n, p.m, len(p.knots)
    (1, 1, 1)
    """
    dynamics: dict = {"A": A, "B": B}
    if f is not None:
        dynamics["f"] = f
    if noise is not None:
        is_tensor = not (isinstance(noise, (list, tuple)) and noise
                         and all(isinstance(e, Mapping) for e in noise))
        dynamics["noise"] = noise_entries(noise) if is_tensor else list(noise)
    cost = {key: value for key, value in (("Q", Q), ("S", S), ("R", R), ("q", q), ("r", r),
                                          ("rho", rho)) if value is not None}
    doc: dict = {"name": name, "t0": t0, "x0": x0, "tick_hz": tick_hz,
                 "dynamics": dynamics, "cost": cost, "knots": list(knots)}
    for key, value in (("u_min", u_min), ("u_max", u_max), ("u_hold", u_hold),
                       ("faults", faults), ("design", design), ("plot", plot),
                       ("stages", stages), ("regions", regions), ("corridors", corridors)):
        if value is not None:
            doc[key] = dict(value) if isinstance(value, Mapping) else list(value)
    problem = parse_problem(doc)
    text = problem_to_toml(problem)
    return replace(problem, source_sha256=hashlib.sha256(text.encode()).hexdigest())


def problem_from_statespace(sys: Any, Q: Any = None, R: Any = None, **kwargs) -> Problem:
    """`problem_from_arrays` with ``A``, ``B`` taken from a continuous-time
    ``control.StateSpace`` (python-control, ``pip install stospline[control]``).

    The system's ``C`` and ``D`` are not used: the design is full-state feedback (the firmware
    measures x), and each knot names its own output matrix ``C`` for its penalty and
    constraint. A discrete-time system is refused: the design discretizes the continuous
    dynamics itself at ``tick_hz``.
    """
    for attr in ("A", "B"):
        if not hasattr(sys, attr):
            raise ProblemError("dynamics", f"expected a control.StateSpace (with A and B), got "
                                           f"{type(sys).__name__}")
    dt = getattr(sys, "dt", 0)
    if dt not in (0, None):
        raise ProblemError("dynamics", f"the state-space system is discrete-time (dt = {dt}); "
                                       f"give the continuous-time system (dt = 0): the design "
                                       f"discretizes it exactly at tick_hz")
    return problem_from_arrays(np.asarray(sys.A), np.asarray(sys.B), Q, R, **kwargs)
