"""Designs for a corridor's risk budget: the search behind ``stospline corridor-design``.

A problem file whose corridor carries ``epsilon`` asks for ``P(a path leaves the corridor at
some tick of [a, b]) <= epsilon``. The knob (`stospline.design.corridor_design`) adds to each
stage's running cost a pull ``w |a'y - c|^2`` towards the centre line of the polygon the
stage's mean path runs in, and a velocity damping ``wv |C A x|^2``. The search, over a grid
of (w, wv):

1. designs every grid point (from the problem file the weights make, written and read back,
   so the tables name that file's SHA-256) and evaluates its law with the exact oracle in the
   *original* cost functional (cheap: no Monte Carlo), with the Cantelli and Gaussian union
   bounds of the exit probability;
2. screens the candidates in increasing order of that cost by Monte Carlo through the
   compiled C controller (`search_paths`, `search_seed`): a candidate passes when the
   one-sided 99 % Clopper-Pearson upper bound of its exits is at most epsilon. The first
   that passes is the cheapest on the grid that passes: the others are not screened;
3. certifies it on fresh paths (`certify_paths`, another seed: selecting on one sample and
   certifying on the same would bias the bound); if the certified bound exceeds epsilon,
   the next cheapest candidate that passes screening is certified, at most `attempts` times.

Every number depends only on the problem, the grid, the path counts and the seeds (the Monte
Carlo result is the same for any number of workers). `docs/evidence/corridor-exit.md` has the
robot's designs for eps = 0.1 ... 0.001.
"""
from __future__ import annotations

import hashlib
import itertools
import math
from dataclasses import dataclass, field, replace

import numpy as np

from stospline import progress
from stospline.budget import (BASE_SECONDS, Estimate, Term, estimate)
from stospline.design.corridor_design import stage_polygons, strip_weights_problem
from stospline.errors import ProblemError
from stospline.pipeline import design_problem
from stospline.problem.inputfile import decode_problem
from stospline.problem.reader import parse_problem
from stospline.harness.controller import build_controller
from stospline.oracle.exit_bound import exit_bounds
from stospline.harness.exit_stats import CONFIDENCE, clopper_pearson_upper
from stospline.harness.montecarlo import simulate
from stospline.oracle.evaluate import evaluate_table

__all__ = ["STRIP_WEIGHTS", "RATE_WEIGHTS", "SEARCH_SEED", "CERTIFY_SEED", "ATTEMPTS",
           "Candidate", "Exits", "SearchResult", "target_corridor", "with_weights", "candidate",
           "evaluate_grid", "count_exits", "score", "search", "certificate", "work_estimate",
           "summary_text", "failure_reason", "check_reachable", "paths_to_certify"]

STRIP_WEIGHTS = (0.0, 2.0, 5.0, 10.0, 20.0, 40.0)     # w, the centre-line pull
RATE_WEIGHTS = (0.0, 0.5, 1.0, 2.0, 5.0)              # wv, the velocity damping
SEARCH_SEED, CERTIFY_SEED = 20261126, 20261127
ATTEMPTS = 3            # certification runs at most (each after a screening that passed)


@dataclass(frozen=True)
class Exits:
    """A Monte Carlo count of the paths that left the corridor."""
    exits: int
    paths: int
    seed: int

    @property
    def estimate(self) -> float:
        return self.exits / self.paths

    @property
    def upper(self) -> float:
        """One-sided 99 % Clopper-Pearson upper bound of the exit probability."""
        return clopper_pearson_upper(self.exits, self.paths)

    def as_dict(self) -> dict:
        return {"exits": self.exits, "paths": self.paths, "seed": self.seed,
                "estimate": self.estimate, "upper99": self.upper}


@dataclass
class Candidate:
    """One grid point: its weights, the problem they make (read back from `toml`), and the
    exact oracle's numbers of its table in the original cost functional."""
    w: float
    wv: float
    toml: str
    J: float                 # the original cost of the law (exact oracle, table as run)
    cantelli: float          # union bounds of the exit probability (Cantelli: valid)
    gaussian: float
    legs_unchanged: bool     # its own mean path runs in the legs the weights assume
    screening: Exits | None = None
    certification: Exits | None = None

    @property
    def key(self) -> tuple:
        return (self.J, self.w, self.wv)

    def problem(self):
        data = self.toml.encode("utf-8")
        return parse_problem(decode_problem(data), source_sha256=hashlib.sha256(data).hexdigest())


@dataclass
class SearchResult:
    epsilon: float
    corridor: int            # index of the corridor designed for
    J0: float                # the original design's cost (the table as run)
    polygons: list[int]      # the polygon each stage's mean path runs in
    candidates: list[Candidate]          # the whole grid, cheapest first
    screened: list[Candidate] = field(default_factory=list)      # in the order screened
    certified: list[Candidate] = field(default_factory=list)     # in the order certified
    refined: list[Candidate] = field(default_factory=list)       # bisection points screened
    chosen: Candidate | None = None
    designed: object = None  # pipeline.Designed of the chosen candidate


def target_corridor(problem, epsilon: float | None = None, *, varying: bool = False):
    """``(problem, index)``: the problem with the corridor to design for, and its index.

    Without `epsilon`: exactly one corridor must carry ``epsilon``. With it (``--epsilon``):
    the problem must have exactly one corridor, whose epsilon it sets. Raises ProblemError
    naming the field or option otherwise, and for stage data that vary in time (unless
    `varying`: the linearisation of a [plant] model, whose weights the caller adds)."""
    cors = problem.corridors
    if epsilon is not None:
        if not (isinstance(epsilon, float) and 0.0 < epsilon < 1.0):
            raise ProblemError("--epsilon", f"must be a number in (0, 1), got {epsilon!r}")
        if len(cors) != 1:
            raise ProblemError("--epsilon", f"sets the epsilon of the file's only corridor, but "
                                            f"the file has {len(cors)} corridors"
                                            + ("; give epsilon in the file on the one to "
                                               "design for" if cors else ""))
        problem = replace(problem, corridors=(replace(cors[0], epsilon=float(epsilon)),))
        index = 0
    else:
        marked = [i for i, c in enumerate(cors) if c.epsilon is not None]
        if not marked:
            raise ProblemError("corridors", "no corridor has an epsilon (the risk budget to "
                                            "design for); add epsilon to one [[corridors]] "
                                            "entry or give --epsilon")
        if len(marked) > 1:
            raise ProblemError(f"corridors[{marked[1]}].epsilon",
                               f"{len(marked)} corridors have an epsilon; the search designs "
                               f"for one: remove the others' epsilon")
        index = marked[0]
    for k, st in enumerate(problem.stages):
        if st.varying is not None and not varying:
            raise ProblemError(f"stages[{k}]", "the corridor design adds constant weights to "
                                               "each stage: stage data must not vary in time")
    return problem, index


def paths_to_certify(epsilon: float) -> float:
    """The fewest Monte Carlo paths whose one-sided 99 % bound can be at most `epsilon`: with
    no exit among n paths the bound is ``1 - 0.01**(1/n)``."""
    return math.log(1.0 - CONFIDENCE) / math.log1p(-epsilon)


def check_reachable(problem, corridor: int, *, search_paths: int, certify_paths: int,
                    epsilon_option: bool = False) -> None:
    """Refuse, before any design or screening, a search that cannot succeed: an epsilon
    below what the path counts can certify even with no exit, or a polygon of the corridor
    with no interior (no path can stay in it). Raises ProblemError."""
    c = problem.corridors[corridor]
    field = "--epsilon" if epsilon_option else f"corridors[{corridor}].epsilon"
    need = paths_to_certify(c.epsilon)
    for option, paths in (("--search", search_paths), ("--certify", certify_paths)):
        if paths < need:
            best = clopper_pearson_upper(0, paths)
            raise ProblemError(field, f"{c.epsilon!r} cannot be certified: even with no path "
                                      f"leaving, {paths} paths ({option}) bound the exit "
                                      f"probability by {best:.3g} at best (one-sided 99 %); "
                                      f"it takes {option} {need:.3g} or more "
                                      f"paths, or a larger epsilon")
    for k, (A, b) in enumerate(c.polygons):
        if not _has_interior(A, b):
            raise ProblemError(f"corridors[{corridor}].polygons[{k}]",
                               "is empty (no output y lies strictly inside A y <= b), so no "
                               "path can stay in it: check its A and b")


def _has_interior(A: np.ndarray, b: np.ndarray) -> bool:
    """Whether ``{y : A y <= b}`` has an interior point: the largest ball inside it (the
    Chebyshev centre, an LP over rows scaled to unit length) has a positive radius."""
    from scipy.optimize import linprog
    A, b = np.asarray(A, float), np.asarray(b, float)
    scale = np.max(np.abs(A), axis=1)
    zero = scale == 0
    if np.any(zero & (b < 0)):
        return False                 # a row 0 <= b with b < 0
    A, b, scale = A[~zero], b[~zero], scale[~zero]
    if not len(b):
        return True
    A, b = A / scale[:, None], b / scale
    norms = np.linalg.norm(A, axis=1)
    p = A.shape[1]
    res = linprog(np.r_[np.zeros(p), -1.0], A_ub=np.c_[A, norms], b_ub=b,
                  bounds=[(None, None)] * p + [(None, 1.0)], method="highs")
    return res.status == 0 and -res.fun > 1e-12 * max(1.0, float(np.max(np.abs(b))))


def with_weights(problem, corridor: int, polygons: list[int], w: float, wv: float) -> str:
    """The problem file (TOML text) of `problem` with the weights added as stage data."""
    return strip_weights_problem(problem, problem.corridors[corridor], polygons, w,
                                 wv).to_toml()


def _outputs(problem, table, corridor: int):
    """``(J, y_mean, y_cov)`` of the corridor's outputs at every tick: the exact oracle of the
    table as run, or, with a [measurement] sensor, of the loop on the flashed filter's
    estimate (`harness.estimator_run.sensor_outputs`: the same mean, a larger spread)."""
    c = problem.corridors[corridor]
    if problem.measurement is not None:
        from stospline.harness.estimator_run import sensor_outputs
        return sensor_outputs(problem, table, c.C)
    mom = evaluate_table(problem, table, path=False, output=c.C)
    return mom.J, mom.path_y_mean, mom.path_y_cov


def evaluate_grid(problem, corridor: int, *, strip=STRIP_WEIGHTS, rate=RATE_WEIGHTS,
                  make=None, **design_options) -> SearchResult:
    """Design the problem and every grid point; the result's candidates sorted by their cost
    in the original cost functional (ties by w, wv), nothing screened yet. `make`: how a
    grid point is made (default `candidate`)."""
    c = problem.corridors[corridor]
    base = design_problem(problem, **design_options)
    J0, ym, _ = _outputs(problem, base.table, corridor)
    polys = stage_polygons(problem, c, ym)
    grid = list(itertools.product(strip, rate))
    bar = progress.start("corridor designs", len(grid), unit="design")
    out = []
    try:
        for w, wv in grid:
            out.append((make or candidate)(problem, corridor, polys, w, wv, **design_options))
            progress.advance()
    finally:
        progress.finish(bar)
    out.sort(key=lambda cd: cd.key)
    return SearchResult(float(c.epsilon), corridor, float(J0), polys, out)


def candidate(problem, corridor: int, polys: list[int], w: float, wv: float,
              **design_options) -> Candidate:
    """The design of weights (w, wv) with its exact oracle's numbers (no Monte Carlo)."""
    text = with_weights(problem, corridor, polys, w, wv)
    cand = Candidate(float(w), float(wv), text, 0.0, 0.0, 0.0, True)
    d = design_problem(cand.problem(), **design_options)
    return score(cand, problem, corridor, polys, d.table)


def score(cand: Candidate, problem, corridor: int, polys: list[int], table,
          plant=None) -> Candidate:
    """Set the candidate's oracle numbers: the cost of `table` in `problem`'s cost functional
    (with the dynamics of `plant`, a problem of the same shape, when given), the union
    bounds of its exits and whether its mean path keeps the legs `polys`."""
    c = problem.corridors[corridor]
    J, ym, yc = _outputs(problem if plant is None else plant, table, corridor)
    b = exit_bounds(c, ym, yc, problem.t0, problem.tick_hz)
    cand.J, cand.cantelli, cand.gaussian = (float(J), b["cantelli"].total,
                                            b["gaussian"].total)
    cand.legs_unchanged = stage_polygons(problem, c, ym) == polys
    return cand


def count_exits(problem, corridor: int, cand: Candidate, *, paths: int, seed: int,
                substeps: int = 1, workers=None, scheduler=None, force_workers: bool = False,
                **design_options) -> Exits:
    """Monte Carlo of the candidate's compiled C controller with the problem's plant (and
    faults): how many of `paths` paths leave the corridor. With a [measurement] sensor, the
    loop on the filter's estimate (`harness.estimator_run.count_sensor_exits`), spread over
    `workers` or `scheduler` as the full-state loop is (the same count for any number)."""
    d = design_problem(cand.problem(), **design_options)
    if problem.measurement is not None:
        from stospline.harness.estimator_run import count_sensor_exits
        return Exits(count_sensor_exits(problem, d.table, corridor, paths=paths, seed=seed,
                                        substeps=substeps, workers=workers,
                                        scheduler=scheduler, force_workers=force_workers),
                     int(paths), int(seed))
    mc = simulate(problem, build_controller(d.table, plant=problem), paths=paths, seed=seed,
                  substeps=substeps, workers=workers, scheduler=scheduler,
                  force_workers=force_workers)
    return Exits(mc.exit_count(corridor), int(paths), int(seed))


def search(problem, corridor: int, result: SearchResult, *, search_paths: int,
           certify_paths: int, search_seed: int = SEARCH_SEED,
           certify_seed: int = CERTIFY_SEED, attempts: int = ATTEMPTS, substeps: int = 1,
           workers=None, scheduler=None, refine: int = 0, force_workers: bool = False,
           exits=count_exits, make=candidate, **design_options) -> SearchResult:
    """Screen `result.candidates` cheapest first and certify the first that passes (the
    next that passes if certification fails, at most `attempts` certifications). A
    candidate's `screening` already set (e.g. by a full-grid run with the same paths and
    seed) is used as it is. Sets ``screened``, ``certified``, ``chosen`` and ``designed``
    (None when no grid point meets epsilon).

    ``refine`` > 0: before certifying the first grid point P that passes, bisect `refine`
    times on the segment of weights from the last grid point screened before it (F, which
    failed) to P, screening each point; the cheapest point of the segment that passes (in
    the original cost) is certified first, P after it if that fails. Between two grid points
    the cheapest passing design is usually inside the segment, and the grid alone overpays
    by up to the cost step between them.

    `exits` and `make`: how a candidate's exits are counted and a bisection point made, with
    the signatures of `count_exits` and `candidate` (`stospline.nonlinear.corridor`: on a
    [plant] model)."""
    eps = result.epsilon
    run = dict(substeps=substeps, workers=workers, scheduler=scheduler,
               force_workers=force_workers, **design_options)
    queue: list[Candidate] = []
    for i, cand in enumerate(result.candidates):
        if len(result.certified) >= attempts:
            break
        known = cand.screening
        if known is None or (known.paths, known.seed) != (search_paths, search_seed):
            progress.note(f"screening w = {cand.w:g}, wv = {cand.wv:g} (J = {cand.J:.6g}, "
                          f"{i + 1} of {len(result.candidates)} by cost): {search_paths} paths")
            cand.screening = exits(problem, corridor, cand, paths=search_paths,
                                   seed=search_seed, **run)
        result.screened.append(cand)
        if cand.screening.upper > eps:
            continue
        queue = [cand]
        if refine and not result.refined and len(result.screened) > 1:
            queue = _bisect(problem, corridor, result, result.screened[-2], cand, refine,
                            search_paths, search_seed, run, design_options, exits,
                            make) + queue
        for q in queue:
            if len(result.certified) >= attempts:
                break
            progress.note(f"certifying w = {q.w:g}, wv = {q.wv:g}: {certify_paths} fresh "
                          f"paths")
            q.certification = exits(problem, corridor, q, paths=certify_paths,
                                    seed=certify_seed, **run)
            result.certified.append(q)
            if q.certification.upper <= eps:
                result.chosen = q
                result.designed = design_problem(q.problem(), **design_options)
                return result
    return result


def _bisect(problem, corridor: int, result: SearchResult, fail: Candidate, ok: Candidate,
            steps: int, paths: int, seed: int, run: dict, design_options: dict,
            exits, make) -> list[Candidate]:
    """`steps` bisections of the weights between `fail` and `ok`; the points that pass
    screening and cost less than `ok`, cheapest first (each also in ``result.refined``)."""
    lo, hi = 0.0, 1.0
    passed = []
    for _ in range(steps):
        th = 0.5 * (lo + hi)
        w = fail.w + th * (ok.w - fail.w)
        wv = fail.wv + th * (ok.wv - fail.wv)
        q = make(problem, corridor, result.polygons, w, wv, **design_options)
        progress.note(f"refining: w = {q.w:.6g}, wv = {q.wv:.6g} (J = {q.J:.6g}): "
                      f"{paths} paths")
        q.screening = exits(problem, corridor, q, paths=paths, seed=seed, **run)
        result.refined.append(q)
        if q.screening.upper <= result.epsilon:
            hi = th
            if q.J < ok.J:
                passed.append(q)
        else:
            lo = th
    return sorted(passed, key=lambda cd: cd.key)


def certificate(result: SearchResult, *, problem_sha256: str, design_options: dict,
                substeps: int) -> dict:
    """The JSON certificate of a search (plain numbers, all finite)."""
    c = result.chosen

    def row(cd: Candidate) -> dict:
        return {"w": cd.w, "wv": cd.wv, "J": cd.J, "cantelli_bound": cd.cantelli,
                "gaussian_bound": cd.gaussian, "legs_unchanged": cd.legs_unchanged,
                "screening": cd.screening.as_dict()
                if any(cd is s for s in result.screened) else None,
                "certification": None if cd.certification is None
                else cd.certification.as_dict()}

    return {
        "epsilon": result.epsilon, "corridor": result.corridor, "confidence": CONFIDENCE,
        "meets_epsilon": c is not None,
        "J0": result.J0,
        "chosen": None if c is None else {
            "w": c.w, "wv": c.wv, "J": c.J, "extra": c.J - result.J0,
            "extra_percent": 100.0 * (c.J / result.J0 - 1.0) if result.J0 else 0.0,
            "screening": c.screening.as_dict(), "certification": c.certification.as_dict(),
            "cantelli_bound": c.cantelli, "gaussian_bound": c.gaussian,
            "problem_sha256": problem_sha256},
        "stage_polygons": result.polygons,
        "design": dict(design_options), "substeps": substeps,
        "screened": len(result.screened), "certified": len(result.certified),
        "grid": [row(cd) for cd in result.candidates],
        "refined": [{**row(cd), "screening": cd.screening.as_dict()}
                    for cd in result.refined],
        "method": "grid of (w, wv), cheapest in the original cost first"
                  + (", refined by bisection between the last failing and the first passing "
                     "grid point" if result.refined else "")
                  + "; screened by Monte Carlo through the compiled C controller (one-sided "
                    "99 % Clopper-Pearson upper bound <= epsilon), then certified on fresh "
                    "paths with another seed",
    }


def work_estimate(problem, *, grid: int, search_paths: int, certify_paths: int,
                  attempts: int = ATTEMPTS, substeps: int = 1, refine: int = 0,
                  workers: int = 1, **design_options) -> Estimate:
    """The most the search can take: every grid point designed and screened, `refine`
    bisection points designed and screened, `attempts` certifications. The Monte Carlo terms
    are path-ticks at the harness throughput measured for `stospline.budget` (one core;
    `tools/bench/harness_throughput.py`), with a [measurement] sensor at the sensor loop's
    (`budget.SENSOR_PATH_TICK`; `tools/bench/sensor_loop_rate.py`)."""
    opts = {k: v for k, v in design_options.items() if k in ("mode", "discretization")}
    design = estimate(problem, command="design", **opts)
    per_design = sum(t.seconds for t in design.terms
                     if not t.what.startswith(("start-up", "C text")))
    tables = max((t.bytes for t in design.terms), default=0.0)

    def mc(paths: int):
        e = estimate(problem, command="simulate", paths=paths, substeps=substeps,
                     workers=workers, **opts)
        mc_term = next(t for t in e.terms if t.what.startswith("Monte Carlo"))
        compiled = next(t for t in e.terms if t.what.startswith("C text"))
        more = [t for t in e.terms if t.key == "--workers" or t.what.startswith("the paths'")]
        return Term(mc_term.what, mc_term.key, mc_term.seconds + sum(t.seconds for t in more),
                    mc_term.bytes + sum(t.bytes for t in more)), compiled

    screen, compiled = mc(search_paths)
    cert, _ = mc(certify_paths)
    grid += refine           # a bisection point costs what a grid point costs
    est = Estimate("corridor-design")
    est.terms += [
        Term("start-up (imports, compiled kernels)", "--max-time", seconds=BASE_SECONDS),
        Term(f"designs and oracles of {grid + 1} grid points", "tick_hz",
             seconds=(grid + 1) * 1.5 * per_design, bytes=tables),
        Term(f"compiling {grid} controllers", "tick_hz", seconds=grid * compiled.seconds,
             bytes=compiled.bytes),
        Term(f"Monte Carlo screening ({grid} grid points x {search_paths} paths)",
             "--search", seconds=grid * screen.seconds, bytes=screen.bytes),
        Term(f"Monte Carlo certification ({attempts} x {certify_paths} paths)",
             "--certify", seconds=attempts * cert.seconds, bytes=cert.bytes),
    ]
    return est


def summary_text(result: SearchResult) -> str:
    """What the search did, one line per screened candidate, and its outcome."""
    n = len(result.candidates)
    lines = [f"corridor {result.corridor}, epsilon {result.epsilon:g}: {n} grid points, the "
             f"original design J0 = {result.J0:.6g}; screened cheapest first: "
             f"{len(result.screened)} of {n}, certified: {len(result.certified)}"]
    for label, cd in ([("", cd) for cd in result.screened]
                      + [("refined ", cd) for cd in result.refined]):
        s, c = cd.screening, cd.certification
        line = (f"  {label}w = {cd.w:g}, wv = {cd.wv:g}: J = {cd.J:.6g} "
                f"({cd.J - result.J0:+.4g}); screening {s.exits} of {s.paths} paths left, "
                f"upper99 {s.upper:.4g} -> {'pass' if s.upper <= result.epsilon else 'fail'}")
        if c is not None:
            line += (f"; certification {c.exits} of {c.paths}, upper99 {c.upper:.4g} -> "
                     f"{'certified' if c.upper <= result.epsilon else 'FAILED'}")
        lines.append(line)
    c = result.chosen
    if c is not None:
        lines.append(f"chosen: w = {c.w:g}, wv = {c.wv:g}, J = {c.J:.6g} "
                     f"({100 * (c.J / result.J0 - 1) if result.J0 else 0.0:+.3g} % over J0); "
                     f"P(leave) <= {c.certification.upper:.4g} (one-sided 99 %, "
                     f"{c.certification.paths} fresh paths) <= epsilon {result.epsilon:g}")
    return "\n".join(lines)


def failure_reason(result: SearchResult) -> str:
    """Why no design was chosen (for the error line)."""
    eps = result.epsilon
    if result.certified:
        best = min(cd.certification.upper for cd in result.certified)
        return (f"no grid point was certified: {len(result.certified)} that passed screening "
                f"failed certification (best one-sided 99 % bound {best:.4g} > {eps:g})")
    best = min((cd.screening.upper for cd in result.screened), default=1.0)
    return (f"no grid point meets {eps:g}: the best screening bound (one-sided 99 %) is "
            f"{best:.4g}; raise the weights (--strip, --rate), the paths, or epsilon")
