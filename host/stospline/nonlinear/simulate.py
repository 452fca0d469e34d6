"""`stospline simulate` of a ``[plant]`` problem: the compiled controller against the C model
(`stospline.harness.user_plant`), compared with the oracle of the linearisation it was designed
on, with confidence intervals: knot means and variances, the cost, corridor exits.

With faults (the file's ``[faults]``, ``--fault``) the loop around the model is the linear
harness's (`stospline.harness.user_plant`) and the prediction is the fault oracle of the
linearisation (`stospline.oracle.faults`); faults without an exact oracle (quantization,
missed ticks) make the verdict "not comparable".

``substeps="auto"`` (`choose_model_substeps`): a pilot of `PILOT_PATHS` paths, on a stream
of its own, at 1, 2, 4, ... substeps, each beside twice as many on the same Brownian paths;
the first count whose estimated bias is below `TOLERANCE` Monte Carlo standard errors of the
planned run, for every knot mean and the cost, is taken; none up to `MAX_AUTO_SUBSTEPS` is
refused.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from stospline.errors import ProblemError
from stospline.harness.controller import build_controller
from stospline.harness.montecarlo import z_value
from stospline.harness.user_plant import PlantRun, model_faults_unsupported, simulate_model
from stospline.oracle.faults import evaluate_with_faults, has_exact_oracle
from stospline.problem.faults import Faults
from stospline.report.json_numbers import rounded

__all__ = ["plant_simulation", "plant_simulation_text", "run_on_model", "plant_summary",
           "ModelRun", "CONFIDENCE", "check_model_faults",
           "choose_model_substeps", "ModelSubsteps", "PILOT_PATHS", "TOLERANCE",
           "MAX_AUTO_SUBSTEPS"]

CONFIDENCE = 0.99
PILOT_PATHS = 1024       # paths of the pilot that decides the substeps
TOLERANCE = 0.25         # bias allowed, in Monte Carlo standard errors of the planned run
MAX_AUTO_SUBSTEPS = 64   # the most substeps "auto" tries (the pilot also runs twice as many)
# The pilot's stream: a child of SeedSequence(seed) the run does not use (the run draws from
# SeedSequence(seed) itself and its fault child).
_PILOT_STREAM = 2**32 - 1


def check_model_faults(faults: Faults, given=()) -> None:
    """Refuse a fault the loop around a [plant] model cannot apply: ProblemError on
    ``faults.<key>``, or ``--fault <key>`` for a key in `given` (set on the command line)."""
    why = model_faults_unsupported(faults)
    if why:
        raise ProblemError(f"--fault {why[0]}" if why[0] in given else f"faults.{why[0]}",
                           why[1])


@dataclass(frozen=True)
class ModelSubsteps:
    """The substeps "auto" chose on the model: ``tried`` holds, per count tried, the largest
    estimated bias over the knot means and the cost in Monte Carlo standard errors of the
    planned run (an upper confidence bound from the pilot)."""
    substeps: int
    tried: tuple            # ((substeps, bias / standard error), ...)
    tolerance: float
    pilot_paths: int


def _bias_ratio(run, paths: int, z: float) -> float:
    """The largest, over every knot mean component and the cost, of the coarse run's bias
    bound 2 (|mean(fine - coarse)| + z se) over the standard error of a `paths`-path run."""
    pairs = [(X, Xf) for X, Xf in zip(run.knots, run.fine_knots)]
    pairs.append((run.cost[:, None], run.fine_cost[:, None]))
    worst = 0.0
    for X, Xf in pairs:
        d = Xf - X
        se_d = d.std(axis=0, ddof=1) / math.sqrt(d.shape[0])
        bias = 2 * (np.abs(d.mean(axis=0)) + z * se_d)
        se_run = X.std(axis=0, ddof=1) / math.sqrt(paths)
        # A quantity without spread (a noiseless component): rounding is the error allowed.
        floor = 1e-9 * np.maximum(1.0, np.abs(X.mean(axis=0)))
        worst = max(worst, float(np.max(bias / np.maximum(se_run, floor))))
    return worst


def choose_model_substeps(d, model, *, paths: int, seed: int, faults: Faults | None = None,
                          tolerance: float = TOLERANCE, limit: int = MAX_AUTO_SUBSTEPS,
                          controller=None) -> ModelSubsteps:
    """The fewest model substeps per tick (1, 2, 4, ..., at most `limit`) whose bias
    on the model, estimated by a pilot of ``min(paths, PILOT_PATHS)`` paths against twice the
    substeps on the same Brownian paths (Richardson, weak order 1), is at most `tolerance`
    standard errors of a `paths`-path run for every knot mean and the cost; the bound is the
    pilot's estimate plus its own joint 99 % error. Raises ProblemError (``--substeps``) when
    no count up to `limit` is enough."""
    problem = d.problem
    faults = problem.faults if faults is None else faults
    controller = build_controller(d.table) if controller is None else controller
    pilot = min(paths, PILOT_PATHS)
    pilot_seed = np.random.SeedSequence(seed, spawn_key=(_PILOT_STREAM,))
    z = z_value(CONFIDENCE, problem.n * len(problem.knots) + 1)
    tried, n = [], 1
    while True:
        run = simulate_model(problem, controller, model, paths=pilot, seed=pilot_seed,
                             substeps=n, faults=faults)
        tried.append((n, _bias_ratio(run, paths, z)))
        if tried[-1][1] <= tolerance:
            return ModelSubsteps(n, tuple(tried), tolerance, pilot)
        if n >= limit:
            shown = ", ".join(f"{k}: {r:.2g}" for k, r in tried)
            raise ProblemError("--substeps", f"auto: no substep count up to {limit} brings "
                               f"the model's scheme bias below {tolerance:g} Monte Carlo "
                               f"standard errors of {paths} paths (bias / error per count: "
                               f"{shown}); give fewer --paths or a fixed --substeps N (the "
                               f"verdict then widens its intervals by the bias)")
        n = min(limit, 2 * n)


def _variance_se(x: np.ndarray) -> np.ndarray:
    """Standard error of the sample variance of each column (normal-theory-free:
    sqrt((m4 - s^4) / N))."""
    c = x - x.mean(axis=0)
    m2, m4 = np.mean(c ** 2, axis=0), np.mean(c ** 4, axis=0)
    return np.sqrt(np.maximum(m4 - m2 ** 2, 0.0) / x.shape[0])


@dataclass(frozen=True)
class ModelRun:
    """A Monte Carlo run on the model (`run_on_model`): the paths (`PlantRun`), how its
    substeps were chosen (None: given), and the prediction it is compared with: the oracle of
    the linearisation, or with faults that have one, its fault oracle (`exact`)."""
    run: PlantRun
    choice: ModelSubsteps | None
    oracle: object              # `stospline.oracle.evaluate.Moments`
    exact: bool


def run_on_model(d, model, *, paths: int, seed: int, substeps: int | str = 4,
                 faults: Faults | None = None) -> ModelRun:
    """Monte Carlo of `d`'s table on `model` in a loop with `faults` (default
    ``d.problem.faults``), beside the prediction of the linear problem (``d.implemented``,
    or the fault oracle of the same loop). `substeps` "auto": `choose_model_substeps`."""
    problem = d.problem
    faults = problem.faults if faults is None else faults
    check_model_faults(faults)
    exact = not faults.any or has_exact_oracle(d.table, faults)
    oracle = (evaluate_with_faults(problem, d.table, faults) if faults.any and exact
              else d.implemented)
    controller = build_controller(d.table)
    choice = None
    if substeps == "auto":
        choice = choose_model_substeps(d, model, paths=paths, seed=seed, faults=faults,
                                       controller=controller)
        substeps = choice.substeps
    run = simulate_model(problem, controller, model, paths=paths, seed=seed,
                         substeps=int(substeps), faults=faults)
    return ModelRun(run, choice, oracle, exact)


def plant_simulation(d, model, *, paths: int, seed: int, substeps: int | str = 4,
                     faults: Faults | None = None) -> dict:
    """`plant_summary` of `run_on_model` with these arguments."""
    return plant_summary(d, run_on_model(d, model, paths=paths, seed=seed, substeps=substeps,
                                         faults=faults))


def plant_summary(d, r: ModelRun) -> dict:
    """The model's run `r` against its prediction, as a JSON-ready summary; every interval
    is Bonferroni-joint over the comparisons at `CONFIDENCE`."""
    problem, run, choice, oracle, exact = d.problem, r.run, r.choice, r.oracle, r.exact
    paths, seed, substeps, faults = run.paths, run.seed, run.substeps, run.faults
    n, K = problem.n, len(problem.knots)
    z = z_value(CONFIDENCE, 2 * n * K + 1)
    knots, agree = [], True
    for k, X in enumerate(run.knots):
        mean, se = X.mean(axis=0), X.std(axis=0, ddof=1) / np.sqrt(paths)
        var, vse = X.var(axis=0, ddof=1), _variance_se(X)
        o_mean, o_var = oracle.knot_mean[k], np.diag(oracle.knot_cov[k])
        Xf = run.fine_knots[k]
        scheme = 2 * np.abs(Xf.mean(axis=0) - mean)         # weak order 1: the coarse bias
        scheme_var = 2 * np.abs(Xf.var(axis=0, ddof=1) - var)
        ok = bool(np.all(np.abs(mean - o_mean) <= z * se + scheme)
                  and np.all(np.abs(var - o_var) <= z * vse + scheme_var))
        agree &= ok
        knots.append({"t": problem.knots[k].t, "mean": mean, "mean_halfwidth": z * se,
                      "oracle_mean": o_mean, "variance": var, "variance_halfwidth": z * vse,
                      "oracle_variance": o_var, "scheme_bias": scheme,
                      "scheme_bias_variance": scheme_var, "agree": ok})
    J, Jse = float(run.cost.mean()), float(run.cost.std(ddof=1) / np.sqrt(paths))
    J_bias = 2 * abs(float(run.fine_cost.mean()) - J)
    cost_ok = abs(J - oracle.J) <= z * Jse + J_bias
    exits = [{"fraction": float(np.mean(e >= 0)), "paths": int(np.sum(e >= 0))}
             for e in run.exits]
    chosen = ({"substeps_chosen": "given"} if choice is None else
              {"substeps_chosen": "auto", "pilot_paths": choice.pilot_paths,
               "tolerance": choice.tolerance,
               "tried": [{"substeps": k, "bias_over_stderr": r} for k, r in choice.tried]})
    if not exact:
        agree = cost_ok = False
    return rounded({
        "plant": {"paths": paths, "seed": seed, "substeps": substeps, "confidence": CONFIDENCE,
                  "joint_comparisons": 2 * n * K + 1, "worst_status": run.worst_status,
                  "saturated": run.saturated, **chosen},
        "faults": {"levels": faults.as_dict(), "exact_oracle": exact,
                   "oracle_cost": float(oracle.J) if faults.any and exact else None,
                   "nominal_cost": float(d.implemented.J)},
        "knots": knots,
        "cost": {"mc": J, "halfwidth": z * Jse, "scheme_bias": J_bias, "oracle": float(oracle.J),
                 "agree": cost_ok},
        "corridor_exits": exits,
        "verdict": {"agree": bool(agree and cost_ok),
                    **({} if exact else {"reason": "not comparable: these faults have no "
                                                   "exact oracle (quantization, missed ticks); "
                                                   "the Monte Carlo numbers stand alone"})},
    })


def _vec(v) -> str:
    return "[" + ", ".join(f"{x:.4g}" for x in np.atleast_1d(v)) + "]"


def plant_simulation_text(s: dict) -> str:
    p = s["plant"]
    f = s.get("faults", {})
    oracle_name = ("fault oracle of the linearisation" if f.get("levels") and f["exact_oracle"]
                   else "oracle of the linearisation")
    how = ""
    if p.get("substeps_chosen") == "auto":
        tried = ", ".join(f"{e['substeps']}: {e['bias_over_stderr']:.2g}" for e in p["tried"])
        how = (f" (auto: bias / error {tried}"
               + f" <= {p['tolerance']:g} on a {p['pilot_paths']}-path pilot)")
    lines = [f"Monte Carlo on the [plant] model: {p['paths']} paths, seed {p['seed']}, "
             f"{p['substeps']} exponential Euler-Maruyama substeps per tick{how}; "
             f"intervals {p['confidence']:.0%} joint over {p['joint_comparisons']}"]
    if f.get("levels"):
        label = " ".join(f"{k}={v}" for k, v in f["levels"].items())
        if f["exact_oracle"]:
            lines.append(f"  faults around the model: {label}; the prediction is the fault "
                         f"oracle of the linearisation (cost {f['oracle_cost']:.5g}; "
                         f"without faults {f['nominal_cost']:.5g})")
        else:
            lines.append(f"  faults around the model: {label}; no exact oracle for these "
                         f"faults (fault-free oracle shown)")
    for k, kn in enumerate(s["knots"]):
        lines.append(f"  knot {k} (t = {kn['t']:g}): mean {_vec(kn['mean'])} "
                     f"+- {_vec(kn['mean_halfwidth'])}")
        lines.append(f"      {oracle_name} {_vec(kn['oracle_mean'])}; "
                     f"scheme bias {_vec(kn['scheme_bias'])}")
        lines.append(f"      variance {_vec(kn['variance'])} +- {_vec(kn['variance_halfwidth'])}"
                     f"; oracle {_vec(kn['oracle_variance'])}"
                     f"  {'agree' if kn['agree'] else 'DIFFER'}")
    c = s["cost"]
    lines.append(f"  cost {c['mc']:.5g} +- {c['halfwidth']:.3g} (scheme bias "
                 f"{c['scheme_bias']:.2g}); oracle {c['oracle']:.5g}  "
                 f"{'agree' if c['agree'] else 'DIFFER'}")
    for i, e in enumerate(s["corridor_exits"]):
        lines.append(f"  corridor {i}: {e['paths']} paths left it ({e['fraction']:.2%})")
    if "reason" in s["verdict"]:
        lines.append(f"  verdict: {s['verdict']['reason']}")
    else:
        verb = "agrees with" if s["verdict"]["agree"] else "differs from"
        lines.append(f"  verdict: the plant {verb} the prediction of its linearisation")
    return "\n".join(lines) + "\n"
