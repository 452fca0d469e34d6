"""Exact moments of the controller as implemented in a loop with linear faults: sensor noise,
a one-tick computation delay, actuator noise and model mismatch (`problem.faults.Faults`).

The same Ito moment propagation as `oracle.evaluate_table`, on a larger augmented state. Between
ticks the state is ``z = [x; p; v; 1]``: the plant state, the command waiting to be applied
(``p``, with a delay only) and the latched multipliers. At tick j the independent zero-mean
noises of that tick are appended, ``z_e = [z; nu; eta]`` (sensor ``nu``, actuator ``eta``, their
covariances known), and everything the loop does is a linear map of ``z_e``:

    measured  x_m = x + nu
    latch     v   = Lambda x_m + lambda0             (a stage's first tick)
    command   c   = -K x_m - L v - k0
    applied   u   = (p if delayed else c) + eta      held over the tick

so ``w = [x; u; 1]`` moves by the exact one-tick map of the plant (the faulty plant: model
mismatch is just another plant), and the passengers ``a = [c (delayed); v]``, which the plant
does not touch, follow the mean map ``E x+ a' = [Ad, Bd, fd] E [x; u; 1] a'``. Quantization
and missed ticks are not linear: `FaultsNotExact`.

A table designed for a one-tick delay (``GainTable.delay_ticks = 1``, `design.zoh`) is the
delayed loop whose controller also measures the command being applied: its state is
``[x_m; p]``. `evaluate_table` evaluates such tables here (without faults); a delay fault on
top of it (two ticks) is not evaluated.
"""
from __future__ import annotations

import numpy as np

from stospline.errors import StosplineError
from stospline.problem.faults import Faults
from stospline.problem.model import Problem
from stospline.oracle.tick_moments import (Moments, _knot_terms, _PathRecord, _StagePlant,
                                        _w_map)
from stospline.table.format import GainTable

__all__ = ["evaluate_with_faults", "FaultsNotExact", "has_exact_oracle"]


class FaultsNotExact(StosplineError, ValueError):
    """The faults make the loop nonlinear (quantization, missed ticks, a band latch from a
    noisy measurement): no exact moments; Monte Carlo only."""


def has_exact_oracle(table: GainTable, faults: Faults) -> bool:
    """Whether `evaluate_with_faults` can evaluate `table` in a loop with `faults`."""
    try:
        _check_exact(table, faults)
    except FaultsNotExact:
        return False
    return True


def _check_exact(table: GainTable, faults: Faults) -> None:
    if not faults.exact:
        raise FaultsNotExact("quantization and missed ticks make the loop nonlinear")
    if getattr(table, "delay_ticks", 0) and faults.delay_ticks:
        raise FaultsNotExact("the table is designed for a one-tick delay: a delay fault on "
                             "top of it is not evaluated")
    if table.band_qp is not None and np.any(faults.sensor_noise):
        raise FaultsNotExact("the firmware's band latch solves a QP from the noisy measurement")


def evaluate_with_faults(problem: Problem, table: GainTable, faults: Faults | None = None, *,
                         propagator: str = "exact", substeps: int = 4,
                         path: bool = False) -> Moments:
    """Exact moments and cost of `table`'s law in a loop with `faults` (default
    ``problem.faults``) around the plant of `problem` (to which the faults' model mismatch
    is applied). Without faults this is `oracle.evaluate_table`, computed another way.

    `propagator`/`substeps` as in `oracle.evaluate_table` ("euler": the Monte Carlo plant
    scheme). `path` keeps the mean and variance at every tick. Raises `FaultsNotExact` for
    faults without an exact oracle."""
    faults = problem.faults if faults is None else faults
    _check_exact(table, faults)
    plant = faults.plant_of(problem)
    n_c, m, nl = table.dims                  # the controller's state: n_c = n (+ m, fed)
    n = problem.n
    fed = int(getattr(table, "delay_ticks", 0))
    if n_c != n + m * fed:
        raise ValueError(f"the table's law has {n_c} states, the problem {n} "
                         f"(delay_ticks {fed})")
    h = 1.0 / table.tick_hz
    delayed = faults.delay_ticks == 1 or fed == 1
    sig_x = faults.sensor_noise if np.any(faults.sensor_noise) else np.zeros(0)
    sig_u = faults.actuator_noise if np.any(faults.actuator_noise) else np.zeros(0)
    mp = m if delayed else 0
    # Between ticks: z = [x; p; v; 1]. During a tick: z_e = [x; p; v; nu; eta; 1].
    xs, ps, vs = slice(0, n), slice(n, n + mp), slice(n + mp, n + mp + nl)
    d_z = n + mp + nl + 1
    nus = slice(d_z - 1, d_z - 1 + len(sig_x))
    etas = slice(nus.stop, nus.stop + len(sig_u))
    D = etas.stop + 1
    # The actuator starts on the safe command (the firmware's u_hold, 0 unless set).
    hold0 = np.asarray(table.u_hold, dtype=float)[:mp]
    z0 = np.concatenate([problem.x0, hold0, np.zeros(nl), [1.0]])
    M = np.outer(z0, z0)
    noise_cov = np.diag(np.concatenate([sig_x ** 2, sig_u ** 2]))
    J = 0.0
    means, covs, cons = [], [], []
    rec = _PathRecord(problem.x0, path)

    # What does not change from tick to tick, as rows over z_e: what the controller measures
    # (the state; with a table designed for the delay also the command p being applied); z inside
    # z_e; the applied command without the law's part (the held one, the actuator noise);
    # w = [x; u; 1] around its command rows; the latched multipliers.
    Sx = np.zeros((n_c, D))
    Sx[:n, xs] = np.eye(n)
    if len(sig_x):
        Sx[:n, nus] = np.eye(n)
    if fed:
        Sx[n:, ps] = np.eye(m)
    keep = np.r_[0:d_z - 1, D - 1]
    Fu_fixed = np.zeros((m, D))
    if delayed:
        Fu_fixed[:, ps] = np.eye(m)
    if len(sig_u):
        Fu_fixed[:, etas] += np.eye(m)
    Tw = _w_map(n, m, D, xs)
    Sv = np.eye(D)[vs]
    for k in range(table.n_stages):
        plant_k = _StagePlant(plant.stages[k], n, m, table.t0, h, propagator, substeps)
        relatch = k == 0 or table.stage_n_latch[k] > 0
        for j in range(int(table.stage_start[k]), int(table.stage_start[k + 1])):
            # Append this tick's noises (independent of everything so far).
            Me = np.zeros((D, D))
            Me[np.ix_(keep, keep)] = M
            Me[d_z - 1:D - 1, d_z - 1:D - 1] = noise_cov
            if relatch and j == table.stage_start[k]:
                T = np.eye(D)
                T[vs] = 0.0
                if k == 0 and table.band_qp is not None:
                    from stospline.oracle.band_latch import target_latch
                    T[vs.start:vs.start + table.band_qp.q, -1] = target_latch(
                        table.band_qp, problem.x0, float32=table.K.dtype == np.float32)
                else:
                    T[vs] = table.Lambda[k].astype(float) @ Sx
                    T[vs, -1] += table.lambda0[k].astype(float)
                Me = T @ Me @ T.T
            Fc = -table.K[j].astype(float) @ Sx          # c = Fc z_e
            Fc[:, vs] -= table.L[j].astype(float)
            Fc[:, -1] -= table.k0[j].astype(float)
            Tw[n:n + m] = Fu_fixed if delayed else Fu_fixed + Fc      # the applied command
            Ta = np.vstack([Fc, Sv]) if delayed else Sv              # passengers [c; v]
            TM = Tw @ Me
            Mw = TM @ Tw.T
            Mwa = TM @ Ta.T                                   # E [x; u; 1] a'
            rec.command(Mw, n, m)
            Mw, dJ, Fmean = plant_k.tick(Mw, j)
            J += dJ
            Ma = Ta @ Me
            M = np.empty((d_z, d_z))
            a = slice(n, d_z - 1)
            M[xs, xs] = Mw[:n, :n]
            M[xs, -1] = M[-1, xs] = Mw[:n, -1]
            M[-1, -1] = 1.0
            M[xs, a] = Fmean @ Mwa
            M[a, xs] = M[xs, a].T
            M[a, a] = Ma @ Ta.T
            M[a, -1] = M[-1, a] = Ma[:, -1]
            rec.state(M, n)
        # The knot terms read the state block and the constant only.
        sub = np.r_[0:n, d_z - 1]
        pen, mean, cov, con = _knot_terms(problem, k, M[np.ix_(sub, sub)], n)
        J += pen
        means.append(mean); covs.append(cov); cons.append(con)
    return rec.moments(J, means, covs, cons, problem.t0, h, table.n_ticks)


def evaluate_delayed_table(problem: Problem, table: GainTable, *, propagator: str = "exact",
                           substeps: int = 4, path: bool = True) -> Moments:
    """`oracle.evaluate_table` of a table designed for a one-tick delay: the delayed loop
    without faults."""
    return evaluate_with_faults(problem, table, Faults(), propagator=propagator,
                                substeps=substeps, path=path)

