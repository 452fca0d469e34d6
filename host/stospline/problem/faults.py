"""Faults of the loop around the controller: what the ``[faults]`` table of a problem file (and
``simulate --fault KEY=VALUE``) describes, for the harness and the fault oracle.

The design never sees them: the gain table is designed for the nominal plant, and the faults
say how the loop it runs in differs. Per tick ``j`` (``docs/guide/problem-file.md``):

* the controller measures ``x(t_j) + sensor_noise * N(0, I)``, rounded to a multiple of
  ``sensor_quantum`` (per state; noise first, then the converter's rounding);
* with probability ``miss_probability`` the controller is not run at all and the actuator keeps
  its command;
* with ``delay_ticks = 1`` the command computed at tick j is applied from tick j + 1 (over tick
  0 the actuator holds the safe command ``u_hold``, 0 unless the problem sets it);
* the plant receives the applied command plus ``actuator_noise * N(0, I)``, held over the tick;
* the plant's ``A``, ``B`` and diffusion (``G``, ``H``) are the design's times ``plant_A_scale``,
  ``plant_B_scale`` and ``plant_noise_scale`` (model mismatch).

Sensor noise, delay, actuator noise and model mismatch keep the loop linear, so the fault
oracle (`stospline.oracle.faults`) predicts their moments exactly; quantization and missed
ticks do not, and are measured by Monte Carlo only.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from stospline.errors import ProblemError

__all__ = ["Faults", "parse_faults", "FAULT_KEYS"]

# key -> (what it is, per state "n" / per input "m" / one number "1")
FAULT_KEYS = {
    "sensor_noise": ("standard deviation of the additive measurement noise", "n"),
    "sensor_quantum": ("step of the measurement quantizer (0: none)", "n"),
    "delay_ticks": ("ticks between measuring and applying a command (0 or 1)", "1"),
    "miss_probability": ("probability that a tick is missed (the actuator holds)", "1"),
    "actuator_noise": ("standard deviation of the additive command noise", "m"),
    "plant_A_scale": ("the plant's A is the design's times this", "1"),
    "plant_B_scale": ("the plant's B is the design's times this", "1"),
    "plant_noise_scale": ("the plant's diffusion (G, H) is the design's times this", "1"),
}
_SCALE_LIMIT = 1e3      # a model mismatch beyond this factor is a typo, not a test
# Noise and quantizer steps beyond the float32 range make every measurement of the float32
# controller infinite (and their squares overflow the moments): refused, as x0 is.
_F32_MAX = float(np.finfo(np.float32).max)


def _zeros() -> np.ndarray:
    return np.zeros(0)


@dataclass(frozen=True)
class Faults:
    """The faults of the loop (all absent by default; vectors empty when absent)."""
    sensor_noise: np.ndarray = field(default_factory=_zeros)     # (n,) or empty
    sensor_quantum: np.ndarray = field(default_factory=_zeros)   # (n,) or empty
    delay_ticks: int = 0
    miss_probability: float = 0.0
    actuator_noise: np.ndarray = field(default_factory=_zeros)   # (m,) or empty
    plant_A_scale: float = 1.0
    plant_B_scale: float = 1.0
    plant_noise_scale: float = 1.0

    def __eq__(self, other) -> bool:
        return isinstance(other, Faults) and self.as_dict() == other.as_dict()

    def __hash__(self) -> int:
        return hash(repr(self.as_dict()))

    @property
    def any(self) -> bool:
        return bool(self.as_dict())

    @property
    def mismatch(self) -> bool:
        return (self.plant_A_scale, self.plant_B_scale, self.plant_noise_scale) != (1.0, 1.0, 1.0)

    @property
    def exact(self) -> bool:
        """True when the loop stays linear (no quantization, no missed ticks): the fault oracle
        then predicts it exactly."""
        return not np.any(self.sensor_quantum) and self.miss_probability == 0.0

    def as_dict(self) -> dict[str, Any]:
        """The keys that differ from "no fault", as plain numbers and lists (a ``[faults]``
        table)."""
        out: dict[str, Any] = {}
        for key in FAULT_KEYS:
            v = getattr(self, key)
            if isinstance(v, np.ndarray):
                if np.any(v):
                    out[key] = [float(x) for x in v]
            elif v != getattr(_NONE, key):
                out[key] = v
        return out

    def label(self) -> str:
        """A short description, e.g. ``sensor_noise=[0.01, 0.01] delay_ticks=1``."""
        def show(v):
            if isinstance(v, list):
                return ("[" + ", ".join(f"{x:g}" for x in v) + "]") if len(set(v)) > 1 \
                    else f"{v[0]:g}"
            return f"{v:g}"
        return " ".join(f"{k}={show(v)}" for k, v in self.as_dict().items()) or "none"

    def plant_of(self, problem):
        """`problem` with the plant the loop really has (model mismatch applied to every
        stage); the same object without mismatch."""
        if not self.mismatch:
            return problem
        return replace(problem, stages=tuple(self._stage(s) for s in problem.stages))

    def _stage(self, s):
        a, b, g = self.plant_A_scale, self.plant_B_scale, self.plant_noise_scale
        varying = None if s.varying is None else _Scaled(
            s.varying, {"A": a, "B": b, "G": g, "H": g})
        return replace(s, A=s.A * a, B=s.B * b, G=s.G * g,
                       H=None if s.H is None else s.H * g, varying=varying)


class _Scaled:
    """Varying data with some fields scaled (model mismatch), at one time or at many."""

    def __init__(self, outer, factors: dict):
        self.outer, self.factors = outer, factors

    def _scale(self, values: dict) -> dict:
        return {k: (v * self.factors[k] if k in self.factors and v is not None else v)
                for k, v in values.items()}

    def __call__(self, t: float) -> dict:
        return self._scale(self.outer(t))

    def many(self, times) -> dict:
        from stospline.problem.series import sample_varying
        return self._scale(sample_varying(self.outer, times))


_NONE = Faults()


def _per(value: Any, path: str, length: int, what: str) -> np.ndarray:
    """A number (for every entry) or a list of `length` numbers, each finite and >= 0."""
    if isinstance(value, list):
        if len(value) != length:
            raise ProblemError(path, f"has length {len(value)}, expected {length} (one per "
                                     f"{what}) or one number for every {what}")
        items = [(_nonneg(v, f"{path}[{i}]")) for i, v in enumerate(value)]
    else:
        items = [_nonneg(value, path)] * length
    return np.array(items, dtype=float)


def _nonneg(value: Any, path: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ProblemError(path, f"must be a number, got {type(value).__name__} ({value!r})")
    if not math.isfinite(value) or value < 0:
        raise ProblemError(path, f"must be finite and >= 0, got {value}")
    if value > _F32_MAX:
        raise ProblemError(path, f"must be within the float32 range the controller measures "
                                 f"in (<= {_F32_MAX:.8g}), got {value:g}")
    return float(value)


def parse_faults(raw: Any, n: int, m: int, *, prefix: str = "faults.") -> Faults:
    """Validate a ``[faults]`` table (a dict) for a problem with n states and m inputs.

    `prefix` is put before each key in the field named by a ProblemError (``"faults."`` in a
    problem file, ``"--fault "`` on the command line)."""
    if not isinstance(raw, dict):
        raise ProblemError(prefix.rstrip(". ") or "faults",
                           f"must be a table, got {type(raw).__name__}")
    out: dict[str, Any] = {}
    for key, value in raw.items():
        path = prefix + key
        if key not in FAULT_KEYS:
            raise ProblemError(path, f"unknown fault (known: {', '.join(FAULT_KEYS)})")
        kind = FAULT_KEYS[key][1]
        if kind in ("n", "m"):
            out[key] = _per(value, path, n if kind == "n" else m,
                            "state" if kind == "n" else "input")
        elif key == "delay_ticks":
            if isinstance(value, bool) or value not in (0, 1) or not isinstance(value, int):
                raise ProblemError(path, f"must be 0 or 1, got {value!r}")
            out[key] = int(value)
        elif key == "miss_probability":
            p = _nonneg(value, path)
            if p >= 1.0:
                raise ProblemError(path, f"must be below 1 (a controller that never runs), "
                                         f"got {value}")
            out[key] = p
        else:
            s = _nonneg(value, path)
            if not 0.0 < s <= _SCALE_LIMIT:
                raise ProblemError(path, f"must be in (0, {_SCALE_LIMIT:g}], got {value}")
            out[key] = s
    return Faults(**out)
