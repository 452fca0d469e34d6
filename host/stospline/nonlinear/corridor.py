"""``stospline corridor-design`` on a ``[plant]`` model: the search of
`stospline.corridor_search` with every candidate designed on its own linearisation and every
exit counted on the model itself.

A grid point (w, wv) is the user's problem file with the knobs added to each stage's cost
(``[[stages]]`` cost ``Q``, ``q``, ``rho``; the cost must be constant in time):
``w |a'y - c|^2`` for each strip of the polygon the stage's mean path runs in, as for a linear
plant, and ``wv`` times the stage's mean of ``|C A(t) x|^2``, ``A(t)`` the model linearised
along the file's own mean path (the outputs' rate, averaged over the stage so that the data
stay constant). That file keeps its ``[plant]`` and goes through plan -> linearise -> design
(`stospline.nonlinear.iterate`), so each candidate's law is designed for its own mean path;
its cost in the original functional and its union bounds are the exact oracle's on that
linearisation, which only orders the grid. Screening and certification run the compiled C
controller against the C model (`stospline.harness.user_plant`, exponential
Euler-Maruyama about the linearisation with ``substeps`` steps per tick), so the
certificate's Clopper-Pearson bound is about the plant the paths ran on, not about its
linearisation.
"""
from __future__ import annotations

import copy
import hashlib
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from stospline.budget import BASE_SECONDS, Estimate, Term
from stospline.corridor_search import Candidate, Exits, score
from stospline.budget import MODEL_PATH_STEP, MODEL_PATH_TICK
from stospline.design.corridor_design import add_strip_cost
from stospline.errors import ProblemError
from stospline.harness.controller import build_controller
from stospline.harness.user_plant import simulate_model
from stospline.nonlinear.iterate import fit_plant
from stospline.pipeline import design_problem
from stospline.problem.inputfile import decode_problem
from stospline.problem.toml_writer import document_to_toml

__all__ = ["PlantCorridor", "PlantCandidate"]

SAMPLE_SECONDS = 0.01      # the rate term's samples along each stage


@dataclass
class PlantCandidate(Candidate):
    """A grid point of a [plant] problem: `toml` is the problem file with the weights and
    its ``[plant]`` (``source`` the model's copy beside it, `PlantCorridor.source_name`);
    `problem()` is the linearisation it converges to (fitted once)."""
    search: "PlantCorridor | None" = None
    _fitted: tuple | None = field(default=None, repr=False)

    def fitted(self):
        """``(problem, fit)`` of `toml` (`fit_plant`), the model read from the user's
        file; the tables name the SHA-256 of `toml` with the model's text, as ``stospline
        design`` of the written file names them."""
        if self._fitted is None:
            s = self.search
            doc = decode_problem(self.toml.encode("utf-8"))
            doc["plant"]["source"] = str(s.source_path)
            sha = hashlib.sha256(self.toml.encode("utf-8")).hexdigest()
            self._fitted = fit_plant(doc, s.source_path.parent, sha)
        return self._fitted

    def problem(self):
        return self.fitted()[0]


class PlantCorridor:
    """The search's grid points and exit counts for the [plant] problem `doc` (decoded, from
    `base_dir`), named `name`, fitted as `fit` (`fit_plant`)."""

    def __init__(self, doc: dict, base_dir: str | Path, fit, name: str):
        for k, scope in [(-1, doc.get("cost", {}))] + [
                (k, st.get("cost", {})) for k, st in enumerate(doc.get("stages", []))
                if isinstance(st, dict)]:
            for key in ("Q", "q", "rho"):
                if isinstance(scope, dict) and isinstance(scope.get(key), dict):
                    where = "cost" if k < 0 else f"stages[{k}].cost"
                    raise ProblemError(f"{where}.{key}", "varies in time: the corridor design "
                                                         "adds constant weights to it")
        self.doc, self.model, self.name = doc, fit.model, name
        self.source_path = (Path(base_dir) / doc["plant"]["source"]).resolve()
        self.source = self.source_path.read_bytes()
        self.source_name = f"{name}_plant.c"
        self.iterations, self.fit_seconds = fit.iterations, fit.seconds

    def weighted_toml(self, problem, corridor: int, polys: list[int], w: float,
                      wv: float) -> str:
        """The problem file of the weights: the user's document with each stage's cost
        (``[[stages]]``) ``Q``, ``q``, ``rho`` plus the knobs, the corridor's epsilon, its
        model at `source_name`; `problem` the file's linearisation with that epsilon."""
        p, c = problem, problem.corridors[corridor]
        doc = copy.deepcopy(self.doc)
        doc["plant"]["source"] = self.source_name
        doc["corridors"][corridor]["epsilon"] = float(c.epsilon)
        stages = doc.get("stages") or [{} for _ in p.stages]
        ends = np.r_[p.t0, [kn.t for kn in p.knots]]
        out = []
        for k, st in enumerate(p.stages):
            Q, q = np.array(st.Q, dtype=float), np.array(st.q, dtype=float)
            rho = add_strip_cost(c, polys[k], w, Q, q, float(st.rho))
            if wv:
                ts = np.unique(np.r_[np.arange(ends[k], ends[k + 1], SAMPLE_SECONDS),
                                     ends[k + 1]])
                rates = [c.C @ st.at(t).A for t in ts]
                Q += wv * np.mean([r.T @ r for r in rates], axis=0)
            cost = {**stages[k].get("cost", {}), "Q": Q.tolist(), "q": q.tolist(), "rho": rho}
            out.append({**stages[k], "cost": cost})
        doc["stages"] = out
        return document_to_toml(doc)

    def candidate(self, problem, corridor: int, polys: list[int], w: float, wv: float,
                  **design_options) -> PlantCandidate:
        """`stospline.corridor_search.candidate` of a [plant] problem: the grid point's file
        fitted and designed, its oracle's numbers in the original cost on its own
        linearisation (no Monte Carlo)."""
        text = self.weighted_toml(problem, corridor, polys, w, wv)
        cand = PlantCandidate(float(w), float(wv), text, 0.0, 0.0, 0.0, True, search=self)
        own = cand.problem()
        d = design_problem(own, **design_options)
        original = replace(own, stages=tuple(
            replace(s, Q=b.Q, q=b.q, rho=b.rho) for s, b in zip(own.stages, problem.stages)))
        return score(cand, problem, corridor, polys, d.table, plant=original)

    def count_exits(self, problem, corridor: int, cand: PlantCandidate, *, paths: int,
                    seed: int, substeps: int = 1, workers=None, scheduler=None,
                    force_workers: bool = False, **design_options) -> Exits:
        """`stospline.corridor_search.count_exits` on the model: the candidate's compiled C
        controller against the C model, `paths` paths from the seed `seed` (one process)."""
        d = design_problem(cand.problem(), **design_options)
        run = simulate_model(d.problem, build_controller(d.table), self.model, paths=paths,
                             seed=seed, substeps=substeps)
        return Exits(int(np.sum(run.exits[corridor] >= 0)), int(paths), int(seed))

    def work_estimate(self, problem, *, grid: int, search_paths: int, certify_paths: int,
                      attempts: int, substeps: int, refine: int, **design_options
                      ) -> Estimate:
        """The most the search can take: every grid and bisection point fitted (twice the
        CPU time the file's own iterations took) and screened, `attempts` certifications, on
        one core."""
        ticks = int(np.sum(problem.ticks_per_stage))
        grid += refine

        def mc(paths):
            return paths * ticks * (MODEL_PATH_TICK + substeps * MODEL_PATH_STEP)

        est = Estimate("corridor-design")
        est.terms += [
            Term("start-up (imports, compiled kernels)", "--max-time", seconds=BASE_SECONDS),
            Term(f"plan -> linearise -> design of {grid} grid points (the file's took "
                 f"{self.iterations} iterations)", "tick_hz",
                 seconds=grid * 2 * self.fit_seconds),
            Term(f"Monte Carlo screening on the model ({grid} grid points x {search_paths} "
                 f"paths)", "--search", seconds=grid * mc(search_paths)),
            Term(f"Monte Carlo certification on the model ({attempts} x {certify_paths} "
                 f"paths)", "--certify", seconds=attempts * mc(certify_paths)),
        ]
        return est

    def certificate(self, cert: dict, substeps: int) -> dict:
        """`stospline.corridor_search.certificate` with the model the paths ran on."""
        return {**cert, "plant": {
            "source": self.source_name, "sha256": hashlib.sha256(self.source).hexdigest(),
            "scheme": "exponential Euler-Maruyama about the linearisation",
            "substeps": substeps},
            "method": cert["method"].replace(
                "through the compiled C controller",
                "through the compiled C controller against the [plant] model itself (each "
                "grid point designed on its own linearisation)")}

    def files(self) -> dict:
        """The model's copy written beside the designed problem file."""
        return {self.source_name: self.source.decode("ascii")}
