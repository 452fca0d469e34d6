"""The table benches (`tools/bench/spline_tables.py`, `tools/bench/table_kernel.py`), the
tick-grid QP's (`tools/bench/tick_qp_osqp.py`), the model loop's (`tools/bench/model_loop.py`)
and the harness build's (`tools/bench/harness_build.py`) refuse a bad argument with an error
line naming it (after argparse's usage line) and exit status 2, before any work: no
traceback, nothing on stdout."""
import os
import subprocess
import sys

import pytest

from conftest import REPO


@pytest.mark.parametrize("script,args,names", [
    ("spline_tables.py", ["--arith", "q16"], "--arith"),
    ("spline_tables.py", ["--repeat", "0"], "--repeat"),
    ("spline_tables.py", ["--rounding", "-1"], "--rounding"),
    ("spline_tables.py", ["--examples", "nope.toml"], "--examples"),
    ("spline_tables.py", ["--tolerances", "nan"], "--tolerances"),
    ("spline_tables.py", ["--tolerances", "0.5"], "--tolerances"),
    ("spline_tables.py", ["--tolerances", "1e-5,x"], "--tolerances"),
    ("table_kernel.py", ["--ticks", "0"], "--ticks"),
    ("table_kernel.py", ["--ticks", "999999999"], "--ticks"),
    ("tick_qp_osqp.py", ["--rates", "100,fast"], "--rates"),
    ("tick_qp_osqp.py", ["--rates", "0"], "--rates"),
    ("tick_qp_osqp.py", ["--eps", "nan"], "--eps"),
    ("tick_qp_osqp.py", ["--eps", "0"], "--eps"),
    ("tick_qp_osqp.py", ["--example", "nope.toml"], "--example"),
    ("harness_build.py", ["--runs", "0"], "--runs"),
    ("harness_build.py", ["nope.toml"], "PROBLEM"),
    ("model_loop.py", ["--paths", "0"], "--paths"),
    ("model_loop.py", ["--paths", "2000000"], "--paths"),
    ("model_loop.py", ["--hz", "0"], "--hz"),
    ("model_loop.py", ["--repeat", "0"], "--repeat"),
])
def test_a_bad_argument_is_named_and_refused(script, args, names):
    env = {**os.environ, "PYTHONPATH": str(REPO / "host")}
    run = subprocess.run([sys.executable, str(REPO / "tools" / "bench" / script), *args],
                         env=env, capture_output=True, text=True, timeout=120)
    assert run.returncode == 2, run.stderr
    last = run.stderr.strip().splitlines()[-1]
    assert names in last and "Traceback" not in run.stderr, run.stderr
    assert run.stdout == ""
