"""The machine-readable summary of a Monte Carlo run (``stospline simulate --json``): its
statistics beside the oracle's exact numbers, the plant scheme's bias, and the verdict.

``d`` is a `stospline.pipeline.Designed` throughout (not imported: the pipeline imports this).
"""
from __future__ import annotations

import numpy as np

from stospline import strict
from stospline.precision import verbatim
from stospline.problem.faults import Faults
from stospline.report.design_summary import actuator_limits
from stospline.report.json_numbers import rounded
from stospline.oracle.faults import evaluate_with_faults, has_exact_oracle
from stospline.harness.montecarlo import MonteCarloResult, joint_verdict, z_value
from stospline.oracle.evaluate import Moments
from stospline.harness.plant_scheme import scheme_moments

__all__ = ["simulation_summary", "verdict", "loop_moments", "predicted_cost", "knot_entry",
           "cost_and_bias", "saturation", "exact_standard_errors"]

# Why a z-score (or another ratio to a Monte Carlo standard error) is null.
_ZERO_SE = ("every path gave the same value (a problem without noise, or a deterministic "
            "quantity): the Monte Carlo standard error is 0 up to rounding, so the ratio is "
            "undefined")


def loop_moments(d, faults: Faults | None = None) -> Moments:
    """The exact moments the Monte Carlo run is compared with: the implemented law's
    (`Designed.implemented`) without faults, the fault oracle's (`oracle.faults`) in a loop
    with linear `faults` (default ``d.problem.faults``). Nonlinear faults (quantization, missed
    ticks) have none: the fault-free loop's moments are returned, and the verdict says the run
    is not comparable."""
    faults = d.problem.faults if faults is None else faults
    if not faults.any or not has_exact_oracle(d.table, faults):
        return d.implemented
    return evaluate_with_faults(d.problem, d.table, faults)


def predicted_cost(d) -> float:
    """The designer's optimal expected cost from ``d.problem.x0`` (which `start_from` may have
    moved away from the design's own start)."""
    return d.design.cost_from(d.problem.x0)


def knot_entry(mc: MonteCarloResult, exact: Moments, k: int, t, zero_se: str = _ZERO_SE, *,
               tails=None) -> dict:
    """Knot `k` (at `t`): the Monte Carlo mean, its standard error and covariance beside the
    exact ones, and the z-scores of the mean (None, with `zero_se` as the reason, where every
    path gave the same value), dividing by the exact standard error where `tails` (the
    fourth-moment oracle, `exact_standard_errors`) is given, else by the sample's."""
    m, s = mc.knot_mean_se(k)
    alike = mc.knot_moments[k].alike()   # s is then 0 or rounding error
    s_z = s if tails is None else tails.knot_mean_se(k, mc.paths)
    z, why = strict.ratio_or_null(m - exact.knot_mean[k], np.where(alike, 0.0, s_z), zero_se)
    return {"t": verbatim(t),
            "mc_mean": m, "mc_mean_stderr": s, "mc_cov": mc.knot_cov(k),
            "oracle_mean": exact.knot_mean[k], "oracle_cov": exact.knot_cov[k],
            "z_stderr": s_z,
            "z": z, **({"z_undefined": why} if why else {})}


def cost_and_bias(d, mc: MonteCarloResult, exact: Moments, scheme: Moments,
                  zero_se: str = _ZERO_SE, *, tails=None) -> tuple[dict, dict]:
    """The summary's ``cost`` (the Monte Carlo mean cost, its standard error and confidence
    intervals beside the exact and the predicted cost, and its z-score) and
    ``simulation_bias`` (the plant scheme's moments, `scheme`, against the exact ones) entries.
    The ratios divide by the exact standard error where `tails` is given, else by the
    sample's; a ratio to a standard error of 0 is None with `zero_se` as the reason."""
    mean, hw95 = mc.cost_mean_ci(0.95)
    _, hw99 = mc.cost_mean_ci(0.99)
    se = hw95 / z_value(0.95)
    se_exact = se if tails is None else tails.cost_mean_se(mc.paths)
    se_z = 0.0 if mc.cost_moments.alike()[0] else se_exact
    cost_z, cost_why = strict.ratio_or_null(mean - exact.J, se_z, zero_se)
    bias_z, bias_why = strict.ratio_or_null(scheme.J - exact.J, se_z, zero_se)
    cost = {
        "mc_mean": mean, "mc_stderr": se,
        "ci95": [mean - hw95, mean + hw95], "ci99": [mean - hw99, mean + hw99],
        "oracle_implemented": exact.J, "predicted_J0": predicted_cost(d),
        "z_stderr": se_exact, "z": cost_z, **({"z_undefined": cost_why} if cost_why else {}),
    }
    bias = {
        "cost": scheme.J - exact.J,
        "cost_over_stderr": bias_z,
        **({"cost_over_stderr_undefined": bias_why} if bias_why else {}),
        **_substep_choice(mc),
        "knot_cov_max_abs": [float(np.abs(scheme.knot_cov[k] - exact.knot_cov[k]).max())
                             for k in range(len(d.problem.knots))],
    }
    return cost, bias


def saturation(d, mc: MonteCarloResult, commands: dict) -> dict:
    """The summary's ``saturation`` entry: whether the table limits the command, the fraction
    of steps and of paths the controller saturated, and the range of `commands` issued."""
    return {"limited": d.table.limited, "tick_fraction": mc.saturated_fraction,
            "path_fraction": mc.saturated_path_fraction, **commands}


def simulation_summary(d, mc: MonteCarloResult, *, seed: int,
                       confidence: float = 0.99) -> dict:
    """Monte Carlo statistics beside the oracle's exact numbers, the plant scheme's bias, and
    the verdict (`verdict`) on whether they agree at the joint `confidence`.

    ``saturation.tick_fraction`` is the fraction of (path, tick) steps on which the C controller
    returned STSP_WARN_SATURATED; when it is nonzero the oracle's numbers (which assume the
    law is never clipped) do not describe the simulated controller.

    A ratio to a Monte Carlo standard error that is 0 (every path alike, as without noise) is
    undefined: it is None (JSON null) and a sibling ``<key>_undefined`` says why. Raises
    ProblemError if some other number is not finite.

    With faults (``mc.faults``) the exact numbers are the fault oracle's (`loop_moments`) and
    ``faults`` says which; faults without an oracle make the verdict "not comparable"."""
    substeps = mc.substeps
    choice = mc.substep_choice
    faults = mc.faults
    exact = loop_moments(d, faults)
    exact_oracle = has_exact_oracle(d.table, faults)
    euler = (choice.scheme if choice is not None and choice.substeps == substeps
             else scheme_moments(d.problem, d.table, substeps, faults))
    tails, tails_why = exact_standard_errors(d, mc, euler)
    knots = [knot_entry(mc, exact, k, kn.t, tails=tails) for k, kn in enumerate(d.problem.knots)]
    cost, bias = cost_and_bias(d, mc, exact, euler, tails=tails)
    summary = rounded({
        "name": d.problem.name, "paths": mc.paths, "seed": seed, "substeps": substeps,
        "x0": verbatim(d.problem.x0),
        "tick_hz": d.table.tick_hz, "worst_status": mc.worst_status,
        "cost": cost,
        "faults": {
            "levels": verbatim(faults.as_dict()), "exact_oracle": exact_oracle,
            "oracle_cost": exact.J if exact_oracle else None,
            "nominal_cost": d.implemented.J,
        },
        "simulation_bias": bias,
        "knots": knots,
        "standard_errors": {
            "used": "sample" if tails is None else "exact",
            "why": tails_why,
        },
        "saturation": saturation(d, mc, _command_range(mc)),
        **actuator_limits(d),
        **_corridors(d, mc),
    })
    summary["verdict"] = verdict(summary, confidence)
    strict.check_summary_finite(d.problem, summary, "simulated numbers",
                                faults if faults.any else None)
    return summary


def exact_standard_errors(d, mc: MonteCarloResult, scheme: Moments):
    """``(tails, why)``: the exact moments up to the fourth (`oracle.tails.evaluate_tails`) of
    the loop the run simulates, with its plant scheme (`scheme`, the second-moment oracle of
    the same scheme, checked against them), and why the z-scores divide by them or by the
    sample's own standard errors (tails None): faults, a delay or time-varying data have no
    fourth-moment oracle."""
    from stospline.oracle.tails import (TailMoments, check_second_moments, evaluate_tails,
                                        tails_unsupported)
    if mc.faults.any:
        return None, "sample: the loop has faults (no fourth-moment oracle)"
    why = tails_unsupported(d.problem, d.table)
    if why is not None:
        return None, f"sample: {why} (no fourth-moment oracle)"
    if mc.cost_moments.alike()[0]:
        return None, "sample: every path alike (no noise)"
    tails = mc.alongside             # computed while the paths ran (`simulate_problem`)
    if isinstance(tails, TailMoments) and tails.substeps == mc.substeps:
        check_second_moments(tails, scheme)
    else:
        tails = evaluate_tails(d.problem, d.table, substeps=mc.substeps, check=scheme)
    return tails, ("exact: the oracle's cost variance and knot covariances of the plant "
                   f"scheme ({mc.substeps} steps per tick)")


def _command_range(mc: MonteCarloResult) -> dict:
    """``u_low``/``u_high``: the least and greatest command issued per input; None (with a
    reason) for an input the controller never commanded (every tick missed: the harness's
    running minimum is still its initial +inf)."""
    low, high = np.asarray(mc.u_low, float), np.asarray(mc.u_high, float)
    issued = np.isfinite(low) & np.isfinite(high)
    out = {"u_low": [float(v) if ok else None for v, ok in zip(low, issued)],
           "u_high": [float(v) if ok else None for v, ok in zip(high, issued)]}
    if not issued.all():
        out["u_range_undefined"] = ("no command was issued on any path (every tick missed, "
                                    "the actuator held u_hold throughout)")
    return out


def _corridors(d, mc: MonteCarloResult) -> dict:
    """``{"corridors": [...]}`` when the problem has corridors (`harness.exit_stats`): the Monte
    Carlo exit probability with its one-sided 99 % upper bound, and the exact oracle's
    Cantelli (valid) and Gaussian (assumed) union bounds, for the fault-free loop (None for a
    table designed for a delay)."""
    if not d.problem.corridors or mc.exits is None:
        return {}
    from stospline.harness.exit_stats import corridor_report
    # The oracle's output moments exist for tables designed without a delay.
    bounded = not getattr(d.table, "delay_ticks", 0)
    rep = corridor_report(d.problem, d.table, mc.exits, with_bounds=bounded)
    for entry in rep:
        if entry["bound"] is not None:
            entry["bound"]["loop"] = ("fault-free (the bounds ignore [faults])"
                                      if mc.faults.any else "the implemented table")
    return {"corridors": rep}


def _substep_choice(mc: MonteCarloResult) -> dict:
    c = mc.substep_choice
    if c is None:
        return {"substeps_chosen": "given"}
    return {"substeps_chosen": "auto", "target": c.target, "predicted_stderr": c.stderr,
            "pilot_paths": c.pilot_paths, "target_met": c.met}


def verdict(summary: dict, confidence: float = 0.99) -> dict:
    """Whether the Monte Carlo run agrees with the oracle (`harness.montecarlo.joint_verdict`):
    the mean cost and every knot-mean component, each by its z-score in the summary, within
    the two-sided normal bound Bonferroni-corrected so that a correct controller passes all
    of them at once with probability `confidence`. The z-scores divide by the exact standard
    errors where the oracle has the loop's fourth moments (``standard_errors`` says which:
    `exact_standard_errors`), else by the sample's own. Saturation makes the run incomparable: the
    oracle assumes the law is never clipped."""
    c = summary["cost"]
    stats = [("cost", c["z"], c["mc_mean"], c["oracle_implemented"])]
    for k, kn in enumerate(summary["knots"]):
        stats += [(f"knot {k} mean[{i}]", z, kn["mc_mean"][i], kn["oracle_mean"][i])
                  for i, z in enumerate(kn["z"])]
    v = joint_verdict(stats, confidence)
    if not summary.get("faults", {}).get("exact_oracle", True):
        agree, reason = False, ("not comparable: these faults have no exact oracle "
                                "(quantization, missed ticks, or sensor noise before the band "
                                "latch); the Monte Carlo numbers stand alone")
    elif summary["saturation"]["tick_fraction"] > 0:
        agree, reason = False, ("the controller saturated: the oracle assumes the law is never "
                                "clipped, so it does not predict this run")
    elif v.outside:
        agree, reason = False, "outside the joint interval: " + ", ".join(v.outside)
    else:
        agree, reason = True, "every statistic inside the joint interval"
    return {"agree": agree, "confidence": confidence, "correction": "Bonferroni",
            "standard_errors": summary.get("standard_errors", {}).get("used", "sample"),
            "statistics": v.statistics, "z_limit": v.z_limit, "max_abs_z": v.max_abs_z,
            "max_abs_z_of": v.max_abs_z_of, "reason": reason}
