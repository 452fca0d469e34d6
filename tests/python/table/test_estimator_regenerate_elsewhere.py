"""The estimator's tables are the same bytes under other BLAS kernels.

The filter's gains come from the loop's second moments, and its error covariance is a
difference of moments up to ~1e10 times larger: computed with numpy, the BLAS kernel's last
bits moved small gains by up to 6e-9 relative, and with a 3 cm sensor at 100 Hz, or V = 1e-3,
a float32 or Q31 entry landed on a rounding boundary (`tools/check_estimator_blas.py`, which
runs every setting under every kernel). The compiled recursion (`estimator.filter_kernel`)
sums in a fixed order without BLAS. Here: it agrees with the numpy loop, and the 3 cm
setting's float32 and Q31 filter tables (both differed before) come out byte for byte the same
under OpenBLAS's Nehalem kernel (SSE only, two threads) as under this machine's own.
"""
import dataclasses
import hashlib
import json
import os
import pickle
import subprocess
import sys

import numpy as np
import pytest

from stospline import pipeline
from stospline.estimator.ctable import estimator_c, estimator_table
from stospline.estimator.oracle import evaluate_estimator
from stospline.estimator.qformat import estimator_q_c
from stospline.problem import load_problem
from stospline.report.json_numbers import rounded

from conftest import EXAMPLES

import test_gains_regenerate_elsewhere as elsewhere


def _with_sensor(d, V: float, every: int, x0_var: float):
    """`d` (robot_position_sensor's design: the law does not depend on the sensor) with the
    sensor reading each position with variance `V` every `every` ticks, from a start known to
    `x0_var`."""
    meas = d.problem.measurement
    x0_cov = np.diag([x0_var, 0.0, x0_var, 0.0])
    meas = dataclasses.replace(meas, V=V * np.eye(2), every=every, x0_cov=x0_cov)
    return dataclasses.replace(d, problem=dataclasses.replace(d.problem, measurement=meas))


# The setting of tools/check_estimator_blas.py whose float32 and Q31 filters both gave other
# bytes under Nehalem's kernel (v1e-3's Q31 did under Haswell's and Zen's: the script runs it).
SETTINGS = {"3cm_100hz": (9e-4, 10, 9e-4)}
# Its sensor and start spread of 0.5 m: the error covariance not a small difference.
WIDE = ("wide_0.5m", (0.25, 20, 0.25))


@pytest.fixture(scope="module")
def robot_sensor():
    problem = load_problem(EXAMPLES / "robot_position_sensor.toml")
    return pipeline.design_problem(problem)


def test_settings_are_the_check_scripts():
    """The settings here are those the check script writes into the problem file."""
    check = elsewhere.tool_module("check_estimator_blas")
    for name, (V, every, x0_var) in [*SETTINGS.items(), WIDE]:
        v, e, x0 = check.SETTINGS[name]
        assert (float(v), e, float(x0)) == (V, every, x0_var)
        assert f"every = {every}" in check.setting_toml(name)


def _digests(d) -> dict:
    """What gains/ would hold of the filter: the float32 filter's C text, the Q31 filter's
    and the Q31 law's arrays (scaled from the loop's moments), the Q31 summary's numbers."""
    sha = lambda b: hashlib.sha256(b).hexdigest()  # noqa: E731
    et = estimator_table(d.problem, d.table)
    ft, (qt, summary) = pipeline.fixed_point_estimator(d, "q31")
    law = b"".join(np.ascontiguousarray(getattr(ft, a)).tobytes()
                   for a in ("K", "L", "k0", "Lambda", "lambda0", "x_exp", "u_exp"))
    return {"float32 filter": sha(estimator_c(et, "t")[1].encode()),
            "q31 filter": sha(estimator_q_c(qt, "t")[1].encode()), "q31 law": sha(law),
            "q31 summary": json.dumps(rounded(summary), sort_keys=True)}


def _child_digests(path) -> dict:
    """`_digests` of each pickled design in `path` (run in the subprocess)."""
    with open(path, "rb") as f:
        designs = pickle.load(f)
    return {name: _digests(d) for name, d in designs.items()}


def test_filter_tables_are_the_same_under_another_blas_kernel(tmp_path, robot_sensor):
    coretype, corename, flag, threads = next(k for k in elsewhere.BLAS_KERNELS
                                             if k[0] == "Nehalem")
    if flag not in elsewhere._cpu_flags():
        pytest.skip(f"this CPU lacks {flag}: it cannot run OpenBLAS's {coretype} kernels")
    designs = {name: _with_sensor(robot_sensor, *s) for name, s in SETTINGS.items()}
    path = tmp_path / "designs.pickle"
    path.write_bytes(pickle.dumps(designs))
    here = os.path.dirname(os.path.abspath(__file__))
    code = ("import sys, json; sys.path[:0] = sys.argv[1:3]; "
            "import test_estimator_regenerate_elsewhere as t, test_gains_regenerate_elsewhere as e; "
            "print(json.dumps(t._child_digests(sys.argv[3]))); exec(e._CORENAMES)")
    env = {**os.environ, "OPENBLAS_CORETYPE": coretype, "OPENBLAS_NUM_THREADS": str(threads),
           "OMP_NUM_THREADS": str(threads)}
    proc = subprocess.run([sys.executable, "-c", code, here, os.path.dirname(here), str(path)],
                          env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    ran = [line.split()[1] for line in lines if line.startswith("corename ")]
    assert ran and set(ran) == {corename}, f"OpenBLAS ran {ran}, not {corename}"
    theirs = json.loads(lines[0])
    for name, d in designs.items():
        ours = _digests(d)
        differ = [k for k in ours if ours[k] != theirs[name][k]]
        assert not differ, f"{name}: under {coretype} these differ: {differ}"


def _numpy_loop(problem, table, monkeypatch):
    monkeypatch.setenv("STOSPLINE_FILTER_KERNEL", "numpy")
    loop = evaluate_estimator(problem, table)
    monkeypatch.delenv("STOSPLINE_FILTER_KERNEL")
    return loop


def test_compiled_filter_agrees_with_the_numpy_loop(robot_sensor, monkeypatch):
    """The compiled gains agree with the numpy loop's as closely as numpy's own agree between
    BLAS kernels (`tools/check_estimator_blas.py`: the largest difference over the plan
    relative to the largest gain, numpy's own kernel against Nehalem's, and compiled against
    numpy): with a sensor and start spread of 0.5 m per axis (P ~ 0.1 against E xx' ~ 25)
    5.4e-13 and 4.5e-13, to 1e-12 (with the shipped 2 cm sensor, P down to 1e-9 of E xx',
    7.2e-11 and 7.6e-11: the script's figures). The mean maps agree to 1e-15, the loop's cost
    to 1e-12 relative."""
    d = _with_sensor(robot_sensor, *WIDE[1])
    c = evaluate_estimator(d.problem, d.table)
    ref = _numpy_loop(d.problem, d.table, monkeypatch)
    assert c.gain.shape == ref.gain.shape and np.any(c.gain)
    sampled = np.any(ref.gain != 0, axis=(1, 2))
    assert np.array_equal(sampled, np.arange(len(sampled)) % d.problem.measurement.every == 0)
    assert not np.any(c.gain[~sampled])
    err = np.abs(c.gain - ref.gain).max() / np.abs(ref.gain).max()
    assert err <= 1e-12, f"gains differ by {err:.2e} of the largest"
    np.testing.assert_allclose(c.predict, ref.predict, rtol=0, atol=1e-15)
    assert abs(c.moments.J - ref.moments.J) <= 1e-12 * abs(ref.moments.J)
