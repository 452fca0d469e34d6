"""The memory estimate of `stospline.budget` is never below what a run really takes.

Each case of `tools/bench/calibrate_budget.py`'s spread (`PEAK_CASES`: a design, a simulation
with a hundred corridors, a Monte Carlo run on one and on two worker processes, regions at
every tick with the tick-grid QP and rows between ticks, a report) runs as the CLI runs it, in
a fresh process whose peak memory is measured (``ru_maxrss``, and the total proportional set
size of it and its workers); the estimate must be at least that, and not absurdly more.
About 45 s of CPU in all.
"""
import importlib.util
import os

import pytest

from conftest import REPO as ROOT


_spec = importlib.util.spec_from_file_location("calibrate_budget",
                                               ROOT / "tools" / "bench" / "calibrate_budget.py")
calibrate = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(calibrate)

# Far above this the limits would refuse runs that fit: the estimate must stay of the
# order of the measurement (the calibration aims at a factor of about 3).
MAX_OVER = 4.0


@pytest.fixture(scope="module")
def build_dir(tmp_path_factory):
    """One fresh cache of compiled kernels and controllers for the cases, as on a user's
    first run: the first case compiles the design's kernels, which the estimate covers."""
    return tmp_path_factory.mktemp("build")


@pytest.mark.parametrize("label, text, cmd", calibrate.PEAK_CASES,
                         ids=[c[0] for c in calibrate.PEAK_CASES])
def test_estimate_is_not_below_the_measured_peak(label, text, cmd, tmp_path, build_dir):
    est = calibrate.case_estimate(text, cmd)
    env = {**os.environ, "STOSPLINE_CACHE_DIR": str(build_dir)}
    _, peak, code, err = calibrate.measure(calibrate.cli_argv(text, cmd, tmp_path), env)
    assert code == 0, err
    assert est.bytes >= peak, (f"{label}: estimated {est.bytes / 2**20:.0f} MiB, measured "
                               f"{peak / 2**20:.0f} MiB")
    assert est.bytes <= MAX_OVER * peak, (label, est.bytes, peak)


def test_the_measurement_sees_worker_processes():
    """The sampled peak counts a child's children: a process that forks one holding ~200 MB
    is measured above that (else a run's workers would go unmeasured)."""
    code = ("import os, time, numpy as np\n"
            "pid = os.fork()\n"
            "if pid == 0:\n"
            "    a = np.ones(25_000_000); time.sleep(1.0); os._exit(0)\n"
            "os.waitpid(pid, 0)\n")
    _, peak, status, err = calibrate.measure([calibrate.sys.executable, "-c", code])
    assert status == 0, err
    assert peak > 200e6, peak
