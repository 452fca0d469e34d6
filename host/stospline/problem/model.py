"""The problem's data model: stages, knots and their constraints, the whole `Problem`, and
sampled time-varying data (`Series`). Built by `stospline.problem.reader` from a problem file or
by `stospline.problem.build` from arrays."""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Callable

import numpy as np

from stospline.errors import ProblemError

from stospline.problem.corridors import Corridor
from stospline.problem.faults import Faults
from stospline.problem.series import Series, sample_varying

__all__ = ["ProblemError", "Stage", "Penalty", "Constraint", "Knot", "Problem", "Series",
           "Corridor", "TickRegion", "ticks_per_stage"]


@dataclass(frozen=True)
class Stage:
    """Data of one stage ``[t_k, t_{k+1}]`` (time-invariant within the stage).

    The diffusion is ``sum_i x_i G[i] dZ + sum_j u_j H[j] dZ``: ``G[i]`` (n x mz) multiplies
    the state component ``x_i``, ``H[j]`` (n x mz) the input ``u_j`` (None: no such noise).
    The running cost is ``x'Qx + 2x'Su + u'Ru + 2q'x + 2r'u + rho``. The drift is
    ``A x + B u + f`` (``f`` None: zero), e.g. gravity.
    """
    A: np.ndarray
    B: np.ndarray
    G: np.ndarray          # shape (n, n, mz)
    Q: np.ndarray
    S: np.ndarray
    R: np.ndarray
    q: np.ndarray
    r: np.ndarray
    rho: float
    H: np.ndarray | None = None   # shape (m, n, mz)
    # The affine drift f of dX = (A X + B u + f) dt + ... (n,); None: no drift.
    f: np.ndarray | None = None
    # Time-varying data: t -> {field: value at t} for the fields that vary (None: constant).
    varying: Callable[[float], dict] | None = field(default=None, compare=False)
    # What the stage was parsed from (samples of time-varying data, tracking), so that
    # `stospline.problem.toml_writer` can write it back; None for stages built directly in Python.
    origin: Any = field(default=None, compare=False, repr=False)

    def at(self, t: float) -> "Stage":
        """The stage's data frozen at time t (itself if nothing varies)."""
        return self if self.varying is None else replace(self, varying=None, **self.varying(t))

    @property
    def noise_tensor(self) -> np.ndarray:
        """Diffusion multipliers of ``[x; u]``: shape (n + m, n, mz), ``[G; H]``."""
        H = self.H if self.H is not None else np.zeros((self.B.shape[1],) + self.G.shape[1:])
        return np.concatenate([self.G, H])

    @property
    def has_control_noise(self) -> bool:
        return self.H is not None and bool(np.any(self.H))

    def samples(self, times, noise: bool = True) -> dict:
        """Every field at every time of `times`, stacked on a first axis (``f`` and ``H`` may
        be None): vectorised when the varying data offer ``many(times)`` (samples read from a
        file do), else one call per time. `noise` False: ``G`` and ``H`` None, not sampled."""
        times = np.asarray(times, dtype=float)
        names = ("A", "B", "G", "H", "Q", "S", "R", "q", "r", "rho", "f")
        varied = {} if self.varying is None else sample_varying(self.varying, times, noise)
        out = {"G": None, "H": None}
        if not noise:
            names = tuple(k for k in names if k not in ("G", "H"))
        for k in names:
            v = varied.get(k, getattr(self, k))
            if v is None:
                out[k] = None
            elif k in varied:
                out[k] = np.asarray(v, dtype=float)
            else:
                v = np.asarray(v, dtype=float)
                out[k] = np.broadcast_to(v, (times.size,) + v.shape)
        return out

    def without_noise(self) -> "Stage":
        varying = None if self.varying is None else _Dropped(self.varying, ("G", "H"))
        return Stage(self.A, self.B, np.zeros_like(self.G), self.Q, self.S, self.R,
                     self.q, self.r, self.rho, None, self.f, varying)


class _Dropped:
    """Varying data without some fields (``without_noise``), at one time or at many."""

    def __init__(self, outer, drop: tuple):
        self.outer, self.drop = outer, drop

    def __call__(self, t: float) -> dict:
        return {k: v for k, v in self.outer(t).items() if k not in self.drop}

    def many(self, times) -> dict:
        return {k: v for k, v in sample_varying(self.outer, times).items()
                if k not in self.drop}


@dataclass(frozen=True)
class Penalty:
    """Knot penalty ``weight * |C x - target|^2``."""
    C: np.ndarray
    target: np.ndarray
    weight: float


@dataclass(frozen=True)
class Constraint:
    """Knot constraint on the expected output: ``E{C x} = value``, or a band
    ``lower <= E{C x} <= upper`` (then `value` is None; the paper's Section 4)."""
    C: np.ndarray
    value: np.ndarray | None
    lower: np.ndarray | None = None
    upper: np.ndarray | None = None

    @property
    def is_band(self) -> bool:
        return self.value is None

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """``(lower, upper)``; both equal `value` for an equality."""
        if self.value is not None:
            return self.value, self.value
        return self.lower, self.upper


@dataclass(frozen=True)
class Knot:
    t: float
    penalty: Penalty | None
    constraint: Constraint | None

    @property
    def n_constraints(self) -> int:
        return 0 if self.constraint is None else self.constraint.C.shape[0]


@dataclass(frozen=True)
class TickRegion:
    """A ``[[regions]]`` entry with ``every = "tick"``: ``lower <= E{C x(t)} <= upper`` at every
    controller tick of ``t = [a, b]``, both ends included, except t0 (where the mean is x0).
    It is not expanded into knots: the design adds band knots at the ticks that need them
    (`stospline.refine.every_tick`)."""
    t: tuple[float, float]
    C: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    index: int = field(default=0, compare=False)   # its place in the file's [[regions]]
    # ``between_ticks = true``: also at every time between the ticks of [a, b] (the mean is a
    # polynomial over a tick when the stage is an integrator chain; `stospline.design.tick_qp`)
    between: bool = False

    def ticks(self, t0: float, tick_hz: int) -> np.ndarray:
        """Indices (from t0) of the ticks in [a, b], t0 excluded."""
        first = max(1, int(round((self.t[0] - t0) * tick_hz)))
        last = int(np.floor((self.t[1] - t0) * tick_hz + 1e-9))
        return np.arange(first, last + 1)


@dataclass(frozen=True)
class Problem:
    """A validated stochastic spline problem; knot ``k`` closes stage ``k``."""
    name: str
    t0: float
    x0: np.ndarray
    tick_hz: int
    stages: tuple[Stage, ...]
    knots: tuple[Knot, ...]
    source_sha256: str = ""
    plot: dict = field(default_factory=dict)
    options: dict = field(default_factory=dict)   # [design]: mode, discretization
    # Actuator limits (m,) written into the gain table; None: unlimited on that side. The
    # design ignores them: the firmware clips the unconstrained optimal law.
    u_min: np.ndarray | None = None
    u_max: np.ndarray | None = None
    # The loop's faults ([faults]): what the harness and the fault oracle add around the
    # controller; the design ignores them.
    faults: Faults = field(default_factory=Faults)
    # The safe command (m,) the firmware writes on a refused step; None: 0 (within the limits).
    u_hold: np.ndarray | None = None
    # [[corridors]]: where realisations of outputs must stay (measured; the design ignores
    # them).
    corridors: tuple[Corridor, ...] = ()
    # [[regions]] with every = "tick": bands at every tick, met by the design's constraint
    # generation rather than by knots written into the problem.
    tick_regions: tuple[TickRegion, ...] = ()
    # [measurement]: the sensor the controller estimates the state from
    # (`problem.measurement.Measurement`); None: it measures the whole state exactly.
    measurement: Any = None
    # [[parameters]]: values set on the device within a range
    # (`problem.parameters.Parameter`); the design is for their nominal values.
    parameters: tuple = ()

    @property
    def n(self) -> int:
        return self.x0.shape[0]

    @property
    def m(self) -> int:
        return self.stages[0].B.shape[1]

    @property
    def mz(self) -> int:
        return self.stages[0].G.shape[2]

    @property
    def times(self) -> np.ndarray:
        """Stage boundaries ``t_0 < t_1 < ... < t_N``."""
        return np.array([self.t0] + [kn.t for kn in self.knots])

    @property
    def ticks_per_stage(self) -> np.ndarray:
        return np.rint(np.diff(self.times) * self.tick_hz).astype(int)

    @property
    def max_constraints(self) -> int:
        return max(kn.n_constraints for kn in self.knots)

    def to_toml(self) -> str:
        """The problem as a TOML problem file (`stospline.problem.toml_writer.problem_to_toml`)."""
        from stospline.problem.toml_writer import problem_to_toml
        return problem_to_toml(self)

    def without_noise(self) -> "Problem":
        """The same problem with every diffusion term removed (the paper's Remark 2)."""
        return Problem(self.name, self.t0, self.x0, self.tick_hz,
                       tuple(s.without_noise() for s in self.stages), self.knots,
                       self.source_sha256, self.plot, self.options, self.u_min, self.u_max,
                       self.faults, self.u_hold, self.corridors, self.tick_regions)


def ticks_per_stage(problem, tick_hz: int) -> np.ndarray:
    """Ticks in each stage; raises ValueError if the rate does not divide a stage length."""
    lengths = np.diff(problem.times) * tick_hz
    counts = np.rint(lengths).astype(int)
    if np.any(np.abs(lengths - counts) > 1e-9 * np.maximum(counts, 1)) or np.any(counts < 1):
        raise ValueError(f"tick rate {tick_hz} Hz does not divide every stage length")
    return counts
