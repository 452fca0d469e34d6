"""Monte Carlo through the compiled C (stsp_set_params, stsp_param_step) of the drone through
gates at the vertex of the parameter box where its altitude band is tightest: the sample mean
altitude at that tick agrees with the oracle at that vertex (99 % two-sided, the sample's own
standard error, fixed seed), the oracle's value there is inside the band, and the same run
disagrees with the nominal's (the test can fail)."""
import numpy as np

from conftest import EXAMPLES
from stospline import design_problem, load_problem
from stospline.harness.params_loop import build_params_controller, simulate_params
from stospline.oracle.parametric import (check_parametric_options, design_parametric,
                                         evaluate_at)

PATHS, SEED = 2000, 20261129
Z99 = 2.5758293035489


def test_altitude_at_the_worst_vertex_agrees_with_the_oracle(tmp_path_factory):
    p = load_problem(EXAMPLES / "drone_gates.toml")
    opts = check_parametric_options(p)
    pd = design_parametric(p, mode=opts.mode)
    table = design_problem(p, options=opts).table
    ctl = build_params_controller(pd.table, table, build_dir=tmp_path_factory.mktemp("box"))
    (m,) = pd.margins
    reg = p.tick_regions[0]
    j = int(round((m.t - p.t0) * p.tick_hz))
    s = reg.C[0] @ pd.box.S[j]                          # the row's sensitivity there
    lo = np.array([q.lower for q in p.parameters])
    hi = np.array([q.upper for q in p.parameters])
    theta = np.where(s > 0, hi, lo) if m.side == "upper" else np.where(s > 0, lo, hi)
    seen = {}

    def observe(tick, X):
        if tick == j:
            seen["z"] = X @ reg.C[0]

    run = simulate_params(p, ctl, theta, paths=PATHS, seed=SEED, observe=observe)
    assert run.worst_status >= 0
    z = seen["z"]
    se = z.std(ddof=1) / np.sqrt(z.size)
    exact = evaluate_at(p, pd.table, theta, quantize=True, path=True).path_mean[j] @ reg.C[0]
    assert exact <= reg.upper[0] + 1e-6
    assert abs(z.mean() - exact) <= Z99 * se, (z.mean(), exact, se)
    nominal = evaluate_at(p, pd.table, pd.table.nominal, quantize=True, path=True).path_mean[j] @ reg.C[0]
    assert abs(z.mean() - nominal) > Z99 * se
