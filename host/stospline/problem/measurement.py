"""The ``[measurement]`` table of a problem file: what the controller's sensor sees.

    y_j = C x(t_j) + sum_i x_i(t_j) D_i nu_j + v_j        at the ticks j = 0, every, 2 every, ...

with ``v_j ~ N(0, V(t_j))`` and ``nu_j ~ N(0, I)`` independent of each other, of the plant's
noise and from tick to tick; ``D_i`` (p x mnu) scales a noise proportional to the state ``x_i``
(a range sensor's error grows with the range). ``x0_cov`` is the covariance of the start around ``x0``,
which the controller does not know exactly once it estimates the state (zero by default).
``V`` may be given as samples over time (``{t = [...], values = [...], interpolation = ...}``,
as the stages' data, `problem.series`): the filter's gains then follow it tick by tick. ``C``
is constant (the firmware's estimator table holds one C); so are ``D`` and ``every``.

The design ignores the table: the law it designs runs on the estimate ``x̂`` of the filter of
`stospline.estimator` (docs/theory/estimator.md).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from stospline.errors import ProblemError
from stospline.problem.fields import check_keys as _check_keys, integer as _int, join as _join
from stospline.problem.fields import kind as _kind, matrix as _matrix
from stospline.problem.series import Series, series_or
from stospline.limits import MAX_NX

__all__ = ["Measurement", "parse_measurement", "MEASUREMENT_KEYS"]

MEASUREMENT_KEYS = {"C", "V", "every", "noise", "x0_cov"}
_U32_MAX = 2**32 - 1
_F32_MAX = float(np.finfo(np.float32).max)


@dataclass(frozen=True, eq=False)
class Measurement:
    """A validated sensor model (see the module docstring); ``D`` is (n, p, mnu) with zero
    matrices for states without a noise entry (mnu = 0 without any)."""
    C: np.ndarray                       # (p, n)
    V: np.ndarray                       # (p, p), symmetric positive semidefinite
    every: int = 1
    D: np.ndarray = field(default_factory=lambda: np.zeros((0, 0, 0)))
    x0_cov: np.ndarray | None = None    # (n, n); None: the start is known exactly
    V_series: Series | None = None      # V sampled over time (V is then its first sample)

    def __eq__(self, other) -> bool:
        return isinstance(other, Measurement) and self.as_dict() == other.as_dict()

    def __hash__(self) -> int:
        return hash(repr(self.as_dict()))

    @property
    def p(self) -> int:
        return self.C.shape[0]

    def prior_cov(self, n: int) -> np.ndarray:
        return np.zeros((n, n)) if self.x0_cov is None else self.x0_cov

    def V_at(self, t: float | None) -> np.ndarray:
        """The additive noise's covariance at time `t` (the constant V when not sampled)."""
        if self.V_series is None or t is None:
            return self.V
        V = self.V_series(t)
        return 0.5 * (V + V.T)

    def noise_cov(self, Mxx: np.ndarray, t: float | None = None) -> np.ndarray:
        """``E rr'`` of the sensor's noise ``r = y - C x`` at time `t` given ``E xx' = Mxx``:
        ``V(t) + sum_ab E[x_a x_b] D_a D_b'`` (the state-proportional part is linear in
        Mxx)."""
        V = self.V_at(t)
        if not self.D.size:
            return V.copy()
        R = V + np.einsum("ab,apk,bqk->pq", Mxx, self.D, self.D)
        return 0.5 * (R + R.T)

    def samples_at(self, tick: int) -> bool:
        return tick % self.every == 0

    def as_dict(self) -> dict[str, Any]:
        """The ``[measurement]`` table that reads back as this model."""
        out: dict[str, Any] = {"C": self.C.tolist(), "V": self.V.tolist()}
        if self.V_series is not None:
            vs = self.V_series
            out["V"] = {"t": vs.t.tolist(), "values": vs.values.tolist(),
                        "interpolation": vs.interpolation}
        if self.every != 1:
            out["every"] = self.every
        noise = [{"state": i, "D": self.D[i].tolist()} for i in range(self.D.shape[0])
                 if self.D[i].any()]
        if noise:
            out["noise"] = noise
        if self.x0_cov is not None:
            out["x0_cov"] = self.x0_cov.tolist()
        return out


def _bounded(M: np.ndarray, path: str) -> None:
    """Entries within float32 range: the controller measures in float32, and a larger
    covariance overflows the squared moments."""
    big = np.argwhere(np.abs(M) > _F32_MAX)
    if big.size:
        idx = "".join(f"[{int(i)}]" for i in big[0])
        raise ProblemError(f"{path}{idx}", f"{M[tuple(big[0])]:g} is beyond the float32 range "
                                           f"(<= {_F32_MAX:.8g}) the controller measures in")


def _covariance(value: Any, path: str, size: int, why: str) -> np.ndarray:
    M = _matrix(value, path, (size, size), (why, why))
    _bounded(M, path)
    asym = np.abs(M - M.T)
    if asym.max() > 1e-12 * max(1.0, float(np.abs(M).max())):
        i, j = np.unravel_index(np.argmax(asym), M.shape)
        raise ProblemError(path, f"must be symmetric: [{i}][{j}] = {M[i, j]:g} but "
                                 f"[{j}][{i}] = {M[j, i]:g}")
    lo = float(np.linalg.eigvalsh(0.5 * (M + M.T)).min())
    if lo < -1e-12 * max(1.0, float(np.abs(M).max())):
        raise ProblemError(path, f"must be positive semidefinite (a covariance); its smallest "
                                 f"eigenvalue is {lo:.6g}")
    return 0.5 * (M + M.T)


def _parse_noise(value: Any, path: str, n: int, p: int) -> np.ndarray:
    """``noise = [{state = i, D = (p x mnu)}, ...]`` as the (n, p, mnu) array."""
    if not isinstance(value, list):
        raise ProblemError(path, f"must be an array of {{state = i, D = matrix}} tables, got "
                                 f"{_kind(value)}")
    D = None
    seen: dict[int, str] = {}
    first = ""
    for j, item in enumerate(value):
        ip = f"{path}[{j}]"
        _check_keys(item, ip, {"state", "D"}, {"state", "D"})
        i = _int(item["state"], f"{ip}.state", 0, n - 1, "a 0-based state index")
        if i in seen:
            raise ProblemError(f"{ip}.state", f"state {i} already has a noise entry "
                                              f"({seen[i]}); give one entry per state")
        seen[i] = ip
        want = None if D is None else D.shape[2]
        why = "" if D is None else f" (as {first}: one column per sensor noise component)"
        Di = _matrix(item["D"], f"{ip}.D", (p, want), (" (p, the rows of measurement.C)", why))
        _bounded(Di, f"{ip}.D")
        if D is None:
            D, first = np.zeros((n, p, Di.shape[1])), f"{ip}.D"
        D[i] = Di
    return np.zeros((0, 0, 0)) if D is None else D


def parse_measurement(raw: Any, n: int, *, path: str = "measurement") -> Measurement:
    """Validate a ``[measurement]`` table for a problem with n states.

    Raises
    ------
    ProblemError
        Naming the key (``measurement.V``, ``measurement.noise[0].D[1][0]``) and the reason.
    """
    raw = _check_keys(raw, path, MEASUREMENT_KEYS, {"C", "V"})
    for key in ("C", "every", "noise"):
        if isinstance(raw.get(key), dict):
            raise ProblemError(_join(path, key), "must be constant: only measurement.V may be "
                                                 "given as samples over time (the firmware's "
                                                 "estimator table holds one C)")
    C = _matrix(raw["C"], _join(path, "C"), (None, n), ("", " (n, the length of x0)"))
    _bounded(C, _join(path, "C"))
    p = C.shape[0]
    if p > MAX_NX:
        raise ProblemError(_join(path, "C"), f"has {p} rows (outputs); the firmware takes at "
                                             f"most {MAX_NX} (STSP_MAX_NX)")
    zero = np.flatnonzero(~C.any(axis=1))
    if zero.size:
        raise ProblemError(f"{path}.C[{int(zero[0])}]", "is a zero row: that output measures "
                                                        "nothing; remove it")
    V = series_or(raw["V"], _join(path, "V"), _covariance, p, " (p, the rows of measurement.C)")
    V_series = None
    if isinstance(V, Series):
        V_series, V = V, V.values[0]
    every = (_int(raw["every"], _join(path, "every"), 1, _U32_MAX,
                  "the ticks between two samples") if "every" in raw else 1)
    D = (_parse_noise(raw["noise"], _join(path, "noise"), n, p) if "noise" in raw
         else np.zeros((0, 0, 0)))
    x0_cov = (_covariance(raw["x0_cov"], _join(path, "x0_cov"), n, " (n, the length of x0)")
              if "x0_cov" in raw else None)
    return Measurement(C, V, every, D, x0_cov, V_series)
