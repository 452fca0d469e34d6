"""Design on the linearisation of a ``[plant]`` model: plan -> linearise -> design until the
mean path the design is made for is the one it was linearised around.

Iteration i linearises the model at the midpoint of every tick of the path P_i (the first
path is ``plant.guess``, else x0 held with zero input), designs on that linear problem with
the file's design options, and takes the oracle's mean path of the implemented table (state
at the ticks, command over each tick) as P_{i+1}. It stops when
``path_change(P_i, P_{i+1}) <= plant.tolerance`` and returns the linear problem of P_i, whose
design reproduces P_i within the tolerance; after ``plant.max_iterations`` it refuses.
"""
from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from stospline.design.linearise import linearise
from stospline.errors import ProblemError
from stospline.nonlinear.linear_problem import linear_doc
from stospline.nonlinear.path import MeanPath, path_change
from stospline.nonlinear.plant_file import has_plant
from stospline.problem.fields import kind, vector
from stospline.problem.inputfile import decode_problem, read_problem_file
from stospline.problem.plant_c import build_plant
from stospline.problem.plant_model import parse_plant
from stospline.problem.reader import parse_problem

__all__ = ["PlantFit", "has_plant", "load_plant_problem", "fit_plant", "SAMPLE_HZ"]

# Linearisation points per second of the path (and every stage's ends); the linear model is
# interpolated linearly between them, an O(h^2) error of at most h = 10 ms.
SAMPLE_HZ = 100


@dataclass
class PlantFit:
    """How the linearisation converged: the path change after each iteration, the tolerance,
    the largest estimated error of a derivative, and the final mean path."""
    changes: list[float] = field(default_factory=list)
    tolerance: float = 0.0
    derivative_error: float = 0.0
    path: MeanPath | None = None
    model: object = None        # the compiled model (`stospline.problem.plant_c.PlantModel`)
    seconds: float = 0.0        # CPU time of the iterations

    @property
    def iterations(self) -> int:
        return len(self.changes)

    def text(self) -> str:
        return (f"[plant] linearised along the mean path: converged in {self.iterations} "
                f"iteration(s), last change {self.changes[-1]:.2g} <= tolerance "
                f"{self.tolerance:g}; derivatives' estimated error {self.derivative_error:.1g}")


def _skeleton(doc: dict, n: int, m: int) -> dict:
    """`doc` with placeholder linear dynamics, parsed once to check everything but [plant]."""
    if "dynamics" in doc:
        raise ProblemError("dynamics", "cannot be given with [plant]: the design linearises "
                                       "the model of plant.source")
    stages = doc.get("stages")
    if isinstance(stages, list):
        for k, st in enumerate(stages):
            if isinstance(st, dict) and "dynamics" in st:
                raise ProblemError(f"stages[{k}].dynamics", "cannot be given with [plant]")
    return {**{k: v for k, v in doc.items() if k != "plant"},
            "dynamics": {"A": np.zeros((n, n)).tolist(), "B": np.zeros((n, m)).tolist()}}


def _design_path(problem) -> MeanPath:
    from stospline.oracle.evaluate import evaluate_table
    from stospline.options import resolve_options
    from stospline.pipeline import design_problem
    d = design_problem(problem, options=resolve_options(problem), max_memory=None,
                       max_time=None)
    mo = evaluate_table(problem, d.table, path=True)
    t = problem.t0 + np.arange(mo.path_mean.shape[0]) / problem.tick_hz
    return MeanPath(t, np.asarray(mo.path_mean), np.asarray(mo.path_u_mean))


def fit_plant(doc: dict, base_dir: str | Path, source_sha256: str = ""):
    """``(problem, fit)``: the linear problem of the converged mean path of the decoded
    problem file `doc` with ``[plant]`` (`base_dir`: the file's directory), and `PlantFit`.

    Raises
    ------
    ProblemError
        On ``plant.<key>`` (a bad model, a failed or unconverged iteration) or any other
        field of the file.
    """
    if "x0" not in doc:
        raise ProblemError("x0", "is required")
    if not isinstance(doc["x0"], list):
        raise ProblemError("x0", f"must be a non-empty array of numbers, got "
                                 f"{kind(doc['x0'])}")
    n = vector(doc["x0"], "x0", None).size
    spec = parse_plant(doc["plant"], base_dir, n)
    model = build_plant(spec, n)
    sha = hashlib.sha256((source_sha256 + ":").encode() + spec.source).hexdigest()
    skeleton = parse_problem(_skeleton(doc, n, model.m), source_sha256=sha)
    if spec.guess is not None and spec.guess[2] is not None \
            and spec.guess[2].shape[1] != model.m:
        raise ProblemError("plant.guess.u", f"has {spec.guess[2].shape[1]} columns, expected "
                                            f"m = {model.m} (stospline_plant_dims)")
    ticks = skeleton.ticks_per_stage
    t = skeleton.t0 + np.arange(int(ticks.sum()) + 1) / skeleton.tick_hz
    user_t = [float(kn["t"]) for kn in doc["knots"]]
    ends = np.cumsum(ticks)[[k for k, kn in enumerate(skeleton.knots)
                             if any(abs(kn.t - ut) < 1e-12 for ut in user_t)]]
    idx, uidx, stages = _grid(skeleton.tick_hz, [0, *ends.tolist()])
    path = MeanPath.from_guess(t, skeleton.x0, model.m, spec.guess)
    fit = PlantFit(tolerance=spec.tolerance, model=model)
    start = time.process_time()
    mixer = _Anderson()
    for i in range(spec.max_iterations):
        lin = linearise(model, t[idx], path.x[idx], path.u[uidx])
        fit.derivative_error = max(fit.derivative_error, lin.error)
        try:
            problem = parse_problem(linear_doc(doc, lin, t[idx], stages), source_sha256=sha)
            new = _design_path(problem)
        except ProblemError as exc:
            if exc.field.startswith("plant."):
                raise
            # The fault is the model's (or the path's), not the generated sample's field.
            raise ProblemError("plant", f"the design on the model linearised along path "
                                        f"{i + 1} failed: {exc.reason} (if the first path is "
                                        f"far from the solution, give plant.guess)") from None
        fit.changes.append(path_change(path, new))
        if fit.changes[-1] <= spec.tolerance:
            fit.path, fit.seconds = path, time.process_time() - start
            return problem, fit
        path = path.with_vector(mixer.next(path.vector(), new.vector()))
    raise ProblemError("plant.max_iterations", f"the mean path did not converge in "
                       f"{spec.max_iterations} iterations: the last change is "
                       f"{fit.changes[-1]:.3g} > plant.tolerance {spec.tolerance:g} "
                       f"(changes {', '.join(f'{c:.2g}' for c in fit.changes[-4:])})")


def _grid(tick_hz: int, firsts: list[int]):
    """The ticks the model is linearised at (every stage's ends and every `SAMPLE_HZ`-th of a
    second between), the ticks whose command goes with each (a stage's last tick's at its
    end), and each stage's slice of them."""
    stride = max(1, round(tick_hz / SAMPLE_HZ))
    idx, uidx, stages = [], [], []
    for a, b in zip(firsts[:-1], firsts[1:]):
        pts = np.unique(np.r_[np.arange(a, b, stride), b])
        stages.append(slice(len(idx), len(idx) + pts.size))
        idx.extend(pts)
        uidx.extend(np.minimum(pts, b - 1))
    return np.array(idx), np.array(uidx), stages


class _Anderson:
    """Anderson acceleration of the fixed-point map P -> design path(P) (depth `depth`): the
    next path combines the last maps so as to cancel their residuals in least squares. Only
    the point tried changes; convergence is still judged on the plain map's residual."""

    def __init__(self, depth: int = 4):
        self.depth, self.p, self.g = depth, [], []

    def next(self, p: np.ndarray, g: np.ndarray) -> np.ndarray:
        r = g - p
        if self.p and np.linalg.norm(r) > 2 * np.linalg.norm(self.g[-1] - self.p[-1]):
            self.p, self.g = [], []          # a step that made things worse: start over
        self.p, self.g = (self.p + [p])[-self.depth - 1:], (self.g + [g])[-self.depth - 1:]
        if len(self.p) < 2:
            return g
        R = np.stack([gi - pi for gi, pi in zip(self.g, self.p)], axis=1)
        dR, dG = np.diff(R, axis=1), np.diff(np.stack(self.g, axis=1), axis=1)
        gamma = np.linalg.lstsq(dR, r, rcond=None)[0]
        return g - dG @ gamma


def load_plant_problem(path: str | Path):
    """`fit_plant` of the problem file at `path`."""
    data = read_problem_file(path)
    doc = decode_problem(data)
    return fit_plant(doc, Path(path).resolve().parent, hashlib.sha256(data).hexdigest())
