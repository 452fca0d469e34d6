"""A problem with runtime parameters: its nominal design with the sensitivity columns
(`design_parametric`), the exact moments of the table at any parameter vector
(`evaluate_at`) or with the parameters changed at a stage start (`evaluate_switched`), and the
exact expected cost as a quadratic in the parameters
(`cost_quadratic`).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from stospline.design.continuous import design_continuous
from stospline.design.sensitivity import check_parametric, source_designs
from stospline.design.zoh import check_delay, design_zoh
from stospline.errors import DesignError
from stospline.oracle.evaluate import Moments, evaluate_table
from stospline.problem.parameters import problem_at
from stospline.table.parametric import ParametricTable, parametric_table

__all__ = ["ParametricDesign", "check_parametric_options", "design_parametric", "evaluate_at",
           "evaluate_switched", "cost_quadratic", "parametric_c_files"]


@dataclass
class ParametricDesign:
    """The nominal design and the table with its sensitivity columns."""
    problem: object
    design: object
    table: ParametricTable
    discretization: str


def design_parametric(problem, *, discretization: str = "exact-zoh", mode: str = "stagewise",
                      delay_ticks: int = 0, noise: bool = True) -> ParametricDesign:
    """Design the problem at its nominal parameters and each parameter's source problem with
    the same designer (`stospline.design.sensitivity`): exact zero-order hold (with a one-tick
    delay when asked) or continuous, stage-wise or joint.

    Raises
    ------
    DesignError
        Naming ``parameters`` for bands or regions, or the designer's own errors.
    """
    check_parametric(problem)
    delay = check_delay(problem, delay_ticks, discretization)
    if discretization == "exact-zoh":
        def designer(p):
            return design_zoh(p, noise=noise, mode=mode, delay_ticks=delay)
    elif discretization == "continuous":
        def designer(p):
            return design_continuous(p, noise=noise, mode=mode)
    else:
        raise DesignError("design.discretization", f"must be exact-zoh or continuous, got "
                                                   f"{discretization!r}")
    nominal = designer(problem)
    hz, stages = nominal.tick_gains()
    table = parametric_table(problem, hz, stages, source_designs(problem, designer),
                             delay_ticks=delay)
    return ParametricDesign(problem, nominal, table, discretization)


def evaluate_at(problem, table: ParametricTable, theta, *, quantize: bool = False,
                path: bool = False) -> Moments:
    """Exact moments and cost of the table at parameters `theta`, run on the problem at
    `theta` (its targets, constraint values, drift and start set to them)."""
    return evaluate_table(problem_at(problem, theta), table.at(theta, quantize=quantize),
                          path=path)


def evaluate_switched(problem, table: ParametricTable, theta, stage: int, theta2, *,
                      quantize: bool = False) -> Moments:
    """Exact moments and cost of the table with the parameters `theta` until stage `stage`
    and `theta2` set just before its first tick (the firmware's stsp_set_params() then: the
    feed-forward of that tick on and the latches of that stage on at `theta2`), run on the
    problem at `theta` up to that stage and at `theta2` from it."""
    a, b = table.at(theta, quantize=quantize), table.at(theta2, quantize=quantize)
    j = int(a.stage_start[stage])
    mixed = replace(a, k0=np.concatenate([a.k0[:j], b.k0[j:]]),
                    lambda0=np.concatenate([a.lambda0[:stage], b.lambda0[stage:]]))
    pa, pb = problem_at(problem, theta), problem_at(problem, theta2)
    p = replace(pa, stages=pa.stages[:stage] + pb.stages[stage:],
                knots=pa.knots[:stage] + pb.knots[stage:])
    return evaluate_table(p, mixed, path=False)


def cost_quadratic(problem, table: ParametricTable, *, quantize: bool = False):
    """``(J_nom, g, H)`` with the exact expected cost of the table at ``theta`` equal to
    ``J_nom + 2 g'd + d'H d``, ``d = theta - theta_nom``.

    The cost of an affine law is a quadratic in the parameters (the means are affine in
    them, the covariances do not depend on them), so it is fixed by its values at the
    nominal, at ``+-s_i e_i`` and at ``s_i e_i + s_j e_j`` (``s_i`` the half-width of the
    range, towards its far end): ``1 + 2P + P(P-1)/2`` oracle runs."""
    nom = np.array([p.nominal for p in table.parameters])
    P = nom.size
    step = np.array([max(p.upper - p.nominal, p.nominal - p.lower) for p in table.parameters])
    step *= np.where(nom + step <= [p.upper for p in table.parameters], 1.0, -1.0)

    def J(d):
        return evaluate_at(problem, table, nom + d, quantize=quantize).J

    J0 = J(np.zeros(P))
    plus = [J(np.eye(P)[i] * step[i]) for i in range(P)]
    g = np.zeros(P)
    H = np.zeros((P, P))
    for i in range(P):
        # J(s e_i) = J0 + 2 g_i s + H_ii s^2 and J(-s e_i) would need -s inside the range:
        # use J(s e_i / 2) instead, also inside.
        half = J(np.eye(P)[i] * step[i] / 2)
        H[i, i] = 2 * (plus[i] - 2 * half + J0) / step[i] ** 2
        g[i] = (plus[i] - J0 - H[i, i] * step[i] ** 2) / (2 * step[i])
    for i in range(P):
        for j in range(i + 1, P):
            d = np.zeros(P); d[i], d[j] = step[i], step[j]
            H[i, j] = H[j, i] = (J(d) - plus[i] - plus[j] + J0) / (2 * step[i] * step[j])
    return J0, g, H


def parametric_c_files(problem, source_name: str = "", options=None) -> dict[str, str]:
    """``{"<name>_params.h": ..., "<name>_params.c": ...}``: the sensitivity columns of the
    problem's design with `options` (`stospline.options.DesignOptions`; default its
    ``[design]`` options: mode, discretization, delay) as C text
    (`stospline.table.parametric_c`), beside the ``<name>.{c,h}`` that `stospline design`
    writes for the nominal."""
    from stospline.table.parametric_c import generate_parametric_c
    opts = check_parametric_options(problem, options)
    pd = design_parametric(problem, discretization=opts.discretization, mode=opts.mode,
                           delay_ticks=opts.delay_ticks)
    header, source = generate_parametric_c(pd.table, source_name=source_name)
    return {f"{problem.name}_params.h": header, f"{problem.name}_params.c": source}


def check_parametric_options(problem, options=None):
    """`options` (default the problem's resolved ``[design]``), or DesignError naming the
    option when the table they ask for has no sensitivity columns."""
    from stospline.options import resolve_options
    opts = options if options is not None else resolve_options(problem)
    # The columns are those of the float32 per-tick law: a spline table re-solves its latch
    # for its own gains, and fixed-point tables scale k0; neither has columns yet.
    for key, plain in (("table", "per-tick"), ("arith", "float32")):
        if getattr(opts, key) != plain:
            raise DesignError(f"design.{key}", f"runtime parameters have sensitivity columns "
                                               f"for {key} = \"{plain}\" only, got "
                                               f"{getattr(opts, key)!r}")
    return opts
