"""`stospline simulate` of a ``[plant]`` problem: the compiled controller against the C model
(`stospline.harness.user_plant`), compared with the oracle of the linearisation it was designed
on, with confidence intervals: knot means and variances, the cost, corridor exits."""
from __future__ import annotations

import numpy as np

from stospline.harness.controller import build_controller
from stospline.harness.montecarlo import z_value
from stospline.harness.user_plant import simulate_model
from stospline.report.json_numbers import rounded

__all__ = ["plant_simulation", "plant_simulation_text", "CONFIDENCE"]

CONFIDENCE = 0.99


def _variance_se(x: np.ndarray) -> np.ndarray:
    """Standard error of the sample variance of each column (normal-theory-free:
    sqrt((m4 - s^4) / N))."""
    c = x - x.mean(axis=0)
    m2, m4 = np.mean(c ** 2, axis=0), np.mean(c ** 4, axis=0)
    return np.sqrt(np.maximum(m4 - m2 ** 2, 0.0) / x.shape[0])


def plant_simulation(d, model, *, paths: int, seed: int, substeps: int = 4) -> dict:
    """Monte Carlo of `d`'s float32 table on `model` against ``d.implemented`` (the oracle of
    the linear problem), as a JSON-ready summary; every interval is Bonferroni-joint over the
    comparisons at `CONFIDENCE`."""
    problem, oracle = d.problem, d.implemented
    run = simulate_model(problem, build_controller(d.table), model, paths=paths, seed=seed,
                         substeps=substeps)
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
    return rounded({
        "plant": {"paths": paths, "seed": seed, "substeps": substeps, "confidence": CONFIDENCE,
                  "joint_comparisons": 2 * n * K + 1, "worst_status": run.worst_status,
                  "saturated": run.saturated},
        "knots": knots,
        "cost": {"mc": J, "halfwidth": z * Jse, "scheme_bias": J_bias, "oracle": float(oracle.J),
                 "agree": cost_ok},
        "corridor_exits": exits,
        "verdict": {"agree": bool(agree and cost_ok)},
    })


def _vec(v) -> str:
    return "[" + ", ".join(f"{x:.4g}" for x in np.atleast_1d(v)) + "]"


def plant_simulation_text(s: dict) -> str:
    p = s["plant"]
    lines = [f"Monte Carlo on the [plant] model: {p['paths']} paths, seed {p['seed']}, "
             f"{p['substeps']} Euler-Maruyama substeps per tick; intervals "
             f"{p['confidence']:.0%} joint over {p['joint_comparisons']}"]
    for k, kn in enumerate(s["knots"]):
        lines.append(f"  knot {k} (t = {kn['t']:g}): mean {_vec(kn['mean'])} "
                     f"+- {_vec(kn['mean_halfwidth'])}")
        lines.append(f"      oracle of the linearisation {_vec(kn['oracle_mean'])}; "
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
    verb = "agrees with" if s["verdict"]["agree"] else "differs from"
    lines.append(f"  verdict: the plant {verb} the prediction of its linearisation")
    return "\n".join(lines) + "\n"
