"""How far a compiled fixed-point (Q15/Q31) controller is from the double-precision law:
random in-range samples for the per-tick error bound, and a noise-free closed loop with the
compiled controller in it (the test of the bound and ``tools/reports/fixed_error.py`` share
these, so the report prints what the test asserts)."""
from __future__ import annotations

import numpy as np

from stospline.design.discretize import zoh


def random_q_samples(ft, count: int, rng: np.random.Generator):
    """`count` random ticks of fixed-point table `ft`, with latch states and tick states drawn
    over the whole Q range (both ends included).

    Returns ``(tick, latch_stage, t_latch, X, XL)``: the tick, the stage whose latch it uses
    (-1 if none), that stage's first tick, the state at the tick and the state at the latch,
    both as Q integers of shape ``(count, n)``.
    """
    F = ft.frac_bits
    n = ft.dims[0]
    tick = rng.integers(0, ft.n_ticks, count)
    ls = ft.latch_stage(ft.stage_of_tick(tick))
    t_latch = ft.stage_start[np.maximum(ls, 0)].astype(np.int64)
    X = rng.integers(-(1 << F), (1 << F) - 1, (count, n), endpoint=True)
    XL = rng.integers(-(1 << F), (1 << F) - 1, (count, n), endpoint=True)
    return tick, ls, t_latch, X, XL


def noise_free_closed_loop(problem, controller, to_input, to_command):
    """The noise-free plant (exact zero-order hold) of `problem` with the compiled `controller`
    in the loop over the whole horizon.

    `to_input` turns the real state into what ``stsp_step`` is given (float32, or Q integers);
    `to_command` turns its output into the real command. Returns the states (ticks + 1, n), the
    commands (ticks, m) and the values handed to ``stsp_step`` (ticks, n). Raises
    RuntimeError if a step does not return status 0.
    """
    step = controller.stepper(1)
    tab = controller.table
    x = np.array(problem.x0, dtype=float)
    xs, us, given = [x.copy()], [], []
    for k in range(tab.n_stages):
        Ad, Bd = zoh(problem.stages[k].A, problem.stages[k].B, 1.0 / tab.tick_hz)
        for j in range(int(tab.stage_start[k]), int(tab.stage_start[k + 1])):
            xin = to_input(x)
            U, st = step(j, xin[None, :])
            if st[0] != 0:
                raise RuntimeError(f"stsp_step returned status {int(st[0])} at tick {j}")
            given.append(xin.copy())
            u = to_command(U[0])
            x = Ad @ x + Bd @ u
            xs.append(x.copy())
            us.append(u)
    return np.array(xs), np.array(us), np.array(given)
