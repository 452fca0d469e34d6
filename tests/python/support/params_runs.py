"""The two Monte Carlo runs of a parametric controller the sim tests compare with oracles:
theta fixed from tick 0, and theta set at tick 0 then theta2 at tick 150 (inside stage 0),
each with the oracle that holds and the one with the parameters not in force."""
from stospline.harness.params_loop import simulate_params
from stospline.oracle.parametric import evaluate_at, evaluate_switched

CHANGE_TICK = 150


def fixed_and_changed_runs(p, ctl, theta, theta2, *, paths: int, seed: int,
                           substeps: int) -> dict:
    """``{name: (run, right, wrong)}``: each run of `simulate_params` and two oracle makers
    ``(table, **kw) -> Moments``, the right one and the one with theta and theta2 swapped."""
    return {
        "fixed": (simulate_params(p, ctl, theta, paths=paths, seed=seed, substeps=substeps),
                  lambda t, **kw: evaluate_at(p, t, theta, **kw),
                  lambda t, **kw: evaluate_at(p, t, theta2, **kw)),
        f"changed at tick {CHANGE_TICK}": (
            simulate_params(p, ctl, theta, paths=paths, seed=seed + 1, substeps=substeps,
                            change=(0, theta2, CHANGE_TICK)),
            lambda t, **kw: evaluate_switched(p, t, theta, 0, theta2, tick=CHANGE_TICK, **kw),
            lambda t, **kw: evaluate_switched(p, t, theta2, 0, theta, tick=CHANGE_TICK, **kw)),
    }
