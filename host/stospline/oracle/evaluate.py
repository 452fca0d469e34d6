"""Exact moment oracle: mean, covariance and expected cost of a latched affine law.

The oracle never looks at Riccati solutions (one exception below). It takes a law (a
continuous design's gain functions, or a quantized per-tick `GainTable`) and propagates the
first and second moments of the augmented state ``y = [x; v; 1]`` (``v`` the latched
multiplier, constant on a stage) through the Ito moment equation

    d/dt M = Abar M + M Abar' + sum_ij M_ij Gbar_i Gbar_j'

For a table the control is held over each tick, so one tick is an exact linear map of the
moments of ``z = [x; u; v; 1]`` (computed once per stage with a block matrix exponential).

The exception: a continuous design's stage solved exactly (`HamiltonianSolution`: constant
data, no noise), evaluated on its own noise-free plant, takes the closed loop from the same
Hamiltonian flow (`HamiltonianSolution.closed_loop`). That is the law's exact cost, equal to
the design's J0 to rounding, not an independent integration; the table's oracle is, and
``tests/python/design/test_hamiltonian_stage.py`` checks the flow against the moment ODE.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from stospline.expm import require_finite

from stospline import progress
from stospline.design.moments import running_cost_matrix
from stospline.problem.model import Problem
# The tick loops' building blocks; the private names stay importable from here.
from stospline.oracle.tick_moments import (_MAPS, Moments, _c_kernel, _euler_varying_maps,  # noqa: F401
                                        _factored_kernel, _factored_maps, _has_drift,
                                        _knot_terms, _latch_transform, _packed_maps,
                                        _PathRecord, _plant_tick, _stage_maps, _table_latch,
                                        _tick_maps, _tick_varying, _w_map)
from stospline.table.format import GainTable
from stospline.table_options import DEFAULT_SIGMAS

if TYPE_CHECKING:
    from stospline.design.continuous import ContinuousDesign

__all__ = ["Moments", "evaluate_continuous", "evaluate_table"]


def evaluate_table(problem: Problem, table: GainTable, *, propagator="exact",
                   substeps: int = 4, path: bool = True,
                   output: np.ndarray | None = None) -> Moments:
    """Exact moments of the controller as implemented: ZOH at the table's tick rate, with the
    table's (quantized) values, latched at each stage's first tick.

    The augmented state is ``y = [x; v; 1]``. Over a tick, ``E xx'`` depends only on the
    moments of ``w = [x; u; 1]`` (u = F y is held; v enters neither the dynamics nor the
    cost), and ``E x v'`` follows the mean map ``E x+ v' = [Ad, Bd, fd] E [x; u; 1] v'``; so
    each tick costs a small fixed map however many multipliers are latched.

    Parameters
    ----------
    problem : Problem
        The plant, cost, knots and start state.
    table : GainTable or FixedPointTable
        The law as the firmware runs it.
    propagator : {"exact", "euler"}
        "exact" propagates the SDE exactly; "euler" reproduces the Monte Carlo plant scheme
        with `substeps` steps per tick, so the difference is the simulation bias.
    path : bool
        Also keep the mean and variance at every tick (``path_mean``, ``path_var``).
    output : ndarray, optional
        An output matrix ``Cy`` (p x n): also keep the mean and covariance of ``Cy x`` at
        every tick (``path_y_mean``, ``path_y_cov``; the corridors' exit bounds). Time-varying
        stages then run by the DOP853 moment integration (`_tick_varying`) rather than the
        Gauss-point C loop, which records only variances.
        Not for tables designed for a delay (ValueError).

    Returns
    -------
    Moments
        The expected cost ``J``, knot means, covariances and constrained outputs.

    Examples
    --------
    >>> import numpy as np, stospline
    >>> p = stospline.load_problem("examples/robot_corridor.toml")
    >>> m = stospline.evaluate_table(p, stospline.design_problem(p).table, path=False)
    >>> print(f"{m.J:.4f}", np.round(m.knot_mean[-1], 6) + 0.0)   # cost; mean state at t = 6
    27.7745 [-1.  0.  5.  0.]

    A table designed for a one-tick delay (``table.delay_ticks``) is evaluated by the fault
    oracle's loop (`fault_oracle.evaluate_with_faults` without faults), whose state carries
    the command waiting to be applied.
    """
    if output is not None and getattr(table, "delay_ticks", 0):
        raise ValueError("evaluate_table: output moments are not recorded for a table "
                         "designed for a one-tick delay")
    if getattr(table, "delay_ticks", 0):
        from stospline.oracle.faults import evaluate_delayed_table   # a delay table only
        return evaluate_delayed_table(problem, table, propagator=propagator,
                                      substeps=substeps, path=path)
    n, m, n_latch = table.dims
    h = 1.0 / table.tick_hz
    d_y = n + n_latch + 1
    x0 = problem.x0
    y0 = np.concatenate([x0, np.zeros(n_latch), [1.0]])
    M = np.outer(y0, y0)
    J = 0.0
    means, covs, cons = [], [], []
    Cy = None if output is None else np.atleast_2d(np.asarray(output, dtype=float))
    if Cy is not None and Cy.shape[1] != n:
        raise ValueError(f"evaluate_table: output has {Cy.shape[1]} columns, expected n = {n}")
    rec = _PathRecord(x0, path, Cy)
    xs, vs = slice(0, n), slice(n, n + n_latch)
    bar = progress.start("oracle", table.n_ticks)
    for k in range(table.n_stages):
        stage = problem.stages[k]
        if k == 0 or table.stage_n_latch[k] > 0:      # else: v latched earlier is kept
            T = _table_latch(table, k, x0, d_y)
            M = T @ M @ T.T
        varying = stage.varying is not None
        maps = None if varying else _tick_maps(stage, n, m, h, propagator, substeps)
        Tw = _w_map(n, m, d_y, slice(0, n))
        ticks = range(int(table.stage_start[k]), int(table.stage_start[k + 1]))
        # The C loop carries the mean map without the constant column: not with a drift.
        kernel = None if varying or _has_drift(problem) else _c_kernel()
        if varying and Cy is None and _c_kernel() is not None:
            # Time-varying data: the Gauss-point Taylor loop in C, or the plant scheme's steps
            # (design.varying).
            from stospline.design.varying import euler_oracle_ticks, oracle_ticks
            sl = slice(ticks.start, ticks.stop)
            gains = (table.K[sl], table.L[sl], table.k0[sl], M, J, path)
            t_first = table.t0 + ticks.start * h
            M, J, xm, xv, um, uv = (oracle_ticks(stage, t_first, h, *gains)
                                    if propagator == "exact" else
                                    euler_oracle_ticks(stage, t_first, h, substeps, *gains))
            rec.extend(xm, xv, um, uv)
            progress.advance(len(ticks))
            ticks = range(0)
        elif kernel is not None:           # the same loop in C (oracle/tick_kernel.c)
            sl = slice(ticks.start, ticks.stop)
            factored = _factored_maps(stage, n, m, h, propagator, substeps)
            if factored is not None and _factored_kernel() is not None:
                # Without noise: M+ = F M F' per tick (tick_kernel.c), O(n d²).
                kernel, tick_map = _factored_kernel(), factored
            else:
                tick_map = _packed_maps(stage, n, m, h, propagator, substeps)
            M, J, *tick_path = kernel(table.K[sl], table.L[sl], table.k0[sl], *tick_map,
                                      np.ascontiguousarray(maps[2][:, :n + m]), M, J,
                                      path=path, moments=Cy is not None)
            if Cy is not None:
                rec.outputs(tick_path.pop())
            if path:
                xm, xv, um, uv = tick_path
                rec.extend(xm, xv, um, uv)
                progress.advance(len(ticks))
            ticks = range(0)
        for j in ticks:
            Tw[n:n + m, :n] = -table.K[j]
            Tw[n:n + m, n:n + n_latch] = -table.L[j]
            Tw[n:n + m, -1] = -table.k0[j]
            TM = Tw @ M                               # E w y'
            Mw = TM @ Tw.T
            Mwv = TM[:, vs]                           # E [x; u; 1] v'
            rec.command(Mw, n, m)
            if varying:
                maps = _stage_maps(stage, True, n, m, table.t0 + j * h, h, propagator, substeps)
            Mw, dJ, Fmean = _plant_tick(stage, maps, Mw, table.t0 + j * h, h, n, m)
            J += dJ
            Mxv = Fmean @ Mwv
            M = M.copy()
            M[xs, xs] = Mw[:n, :n]
            M[xs, -1] = M[-1, xs] = Mw[:n, -1]
            M[xs, vs] = Mxv
            M[vs, xs] = Mxv.T
            rec.state(M, n)
            progress.advance()
        pen, mean, cov, con = _knot_terms(problem, k, M, n)
        J += pen
        means.append(mean); covs.append(cov); cons.append(con)
    progress.finish(bar)
    return rec.moments(J, means, covs, cons, problem.t0, h, table.n_ticks)


def _exact_flow(st) -> bool:
    """Whether the stage solution `st` is a `HamiltonianSolution`: its closed loop is known
    exactly (the continuous designer, imported only for a continuous design)."""
    from stospline.design.continuous import HamiltonianSolution
    return isinstance(st._sol, HamiltonianSolution)


def evaluate_continuous(problem: Problem, design: ContinuousDesign, *, rtol: float = 1e-12,
                        atol: float = 1e-14, points_per_stage: int = 0) -> Moments:
    """Exact moments of a continuous design's latched law ``u = -K(t)x - k0(t) - L(t) v``
    applied to `problem`'s plant (which may differ from the plant it was designed for)."""
    n, m = problem.n, problem.m
    x0 = problem.x0
    J = 0.0
    means, covs, cons = [], [], []
    pts_t, pts_m = [], []
    M = None
    for k, st in enumerate(design.stages):
        stage = problem.stages[k]
        p = st.n_constraints
        d = n + p + 1
        if M is None:
            y0 = np.concatenate([x0, np.zeros(p), [1.0]])
            M = np.outer(y0, y0)
        if st.Lambda.shape[0]:                 # latch; otherwise the earlier v is kept
            T = _latch_transform(n, p, st.Lambda, st.lambda0, M.shape[0])
            M = T @ M @ T.T
        elif M.shape[0] != d:                  # no multipliers act here: drop v
            keep = np.r_[0:n, M.shape[0] - 1]
            M = M[np.ix_(keep, keep)]

        if (_exact_flow(st) and stage is st.stage
                and not points_per_stage and not stage.noise_tensor.any()):
            # The law of an exactly solved stage on its own noise-free plant: the closed loop
            # is the Hamiltonian flow's, exact (HamiltonianSolution.closed_loop).
            order = np.r_[0:n, d - 1, n:n + p]               # y = [x; v; 1] -> [x; 1; v]
            Ma, dJ = st._sol.closed_loop(M[np.ix_(order, order)])
            M = np.empty_like(Ma)
            M[np.ix_(order, order)] = Ma
            J += dJ
            pen, mean, cov, con = _knot_terms(problem, k, M, n)
            J += pen
            means.append(mean); covs.append(cov); cons.append(con)
            continue
        rhs = _moment_rhs(problem, st, stage, d)
        t_eval = (np.linspace(st.t_start, st.t_end, points_per_stage)
                  if points_per_stage else None)
        from scipy.integrate import solve_ivp
        res = solve_ivp(rhs, (st.t_start, st.t_end),
                        require_finite(np.concatenate([M.ravel(), [0.0]])),
                        method="DOP853", rtol=rtol, atol=atol, t_eval=t_eval)
        if res.status != 0:
            raise RuntimeError(f"moment integration failed on stage {k}: {res.message}")
        M = res.y[:-1, -1].reshape(d, d)
        M = 0.5 * (M + M.T)
        J += res.y[-1, -1]
        if points_per_stage:
            pts_t.append(res.t)
            pts_m.append(res.y[:-1].reshape(d, d, -1)[:n, -1, :].T)
        pen, mean, cov, con = _knot_terms(problem, k, M, n)
        J += pen
        means.append(mean); covs.append(cov); cons.append(con)
    path_t = np.concatenate(pts_t) if pts_t else np.zeros(0)
    path_mean = np.concatenate(pts_m) if pts_m else np.zeros((0, n))
    return Moments(float(J), means, covs, cons, path_t, path_mean)


def _moment_rhs(problem: Problem, st, stage, d: int):
    """Right-hand side of ``[vec M; J]`` on one stage of a continuous design: the second moment
    of ``y = [x; v; 1]`` under ``u = F y`` and the expected running cost. With constant data
    everything but the gains is built once; the integrator calls this thousands of times."""
    n, m = problem.n, problem.m
    constant = stage.varying is None
    parts = _closed_loop_parts(stage, n, m, d) if constant else None

    def rhs(t, y):
        sd, (Abar0, Geff0, Lb, Tw) = (stage, parts) if constant else \
            (stage.at(t), _closed_loop_parts(stage.at(t), n, m, d))
        Mt = y[:-1].reshape(d, d)
        K, k0, L = st.gains_at(t)
        F = np.concatenate([-K, -L, -k0[:, None]], axis=1)   # u = F y
        Abar = Abar0.copy()
        Abar[:n] += sd.B @ F
        AM = Abar @ Mt
        # The diffusion sum_i x_i G_i + sum_j u_j H_j with u = F y is sum_i y_i Geff_i dZ:
        # sum_ij M_ij Geff_i Geff_j' over the live multipliers only (none: no product).
        Geff = Geff0
        if sd.H is not None and sd.H.any():
            Geff = Geff0 + np.einsum("ji,jak->iak", F, sd.H)
        dM = AM + AM.T
        live = np.flatnonzero(Geff.any(axis=(1, 2)))
        if live.size:
            Gk = np.moveaxis(Geff[live], 2, 0)          # (mz, na, n)
            dM[:n, :n] += (np.swapaxes(Gk, 1, 2) @ Mt[np.ix_(live, live)] @ Gk).sum(axis=0)
        Tw[n:n + m] = F
        dJ = np.sum((Tw.T @ Lb @ Tw) * Mt)
        return np.concatenate([dM.ravel(), [dJ]])

    return rhs


def _closed_loop_parts(sd, n: int, m: int, d: int):
    """What the moment equations take from the plant's data, before the gains: the drift of
    ``y`` without the input (the drift f multiplies the constant 1), the state's diffusion
    multipliers, the running cost matrix of ``[x; u; 1]`` and the map ``y -> [x; u; 1]`` with
    its input rows left to fill."""
    Abar0 = np.zeros((d, d))
    Abar0[:n, :n] = sd.A
    if sd.f is not None:
        Abar0[:n, -1] += sd.f
    Geff0 = np.zeros((d,) + sd.G.shape[1:])
    Geff0[:n] = sd.G
    Lb = running_cost_matrix(sd, n, m, n + m + 1, n)
    return Abar0, Geff0, Lb, _w_map(n, m, d, slice(0, n))


def state_range(problem: Problem, table: GainTable, *, sigmas: float = DEFAULT_SIGMAS
                ) -> np.ndarray:
    """``max_t |E x_j(t)| + sigmas * std x_j(t)`` over every tick of the plan (exact moments of
    the table's law, `evaluate_table`): the state scales of a Q15/Q31 table."""
    from stospline.table.qformat import scalable_ranges   # fixed point only
    mom = evaluate_table(problem, table, path=True)
    # max(., 0): a zero variance may come out as -1e-18 on another machine (NaN from sqrt).
    r = np.max(np.abs(mom.path_mean) + sigmas * np.sqrt(np.maximum(mom.path_var, 0.0)), axis=0)
    return scalable_ranges(r)
