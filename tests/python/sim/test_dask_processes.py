"""A run spread over a Dask cluster started as a user starts one: `dask scheduler` and two
`dask worker` processes, each its own process. The blocks of paths carry their own random
streams (`montecarlo.block_seed`: block i draws from child i - 1 of the seed's
SeedSequence, whichever process runs it) and their statistics merge in block order, so the
numbers are those of the run in this process, bit for bit."""
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from stospline.harness.controller import build_controller
from stospline.harness.montecarlo import BLOCK_PATHS, simulate

DASK = Path(sys.executable).with_name("dask")
SEED = 20261128


def _wait_for(path: Path, seconds: float = 120.0) -> dict:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if path.exists() and path.stat().st_size:
            return json.loads(path.read_text())
        time.sleep(0.2)
    raise TimeoutError(f"no {path} after {seconds} s")


@pytest.fixture
def cluster(tmp_path):
    """A scheduler and two single-threaded workers, separate processes; its address."""
    if not DASK.exists():
        pytest.skip("the dask command is not installed beside this Python")
    file = tmp_path / "scheduler.json"
    common = {"env": {**os.environ}, "stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    procs = [subprocess.Popen([str(DASK), "scheduler", "--port", "0", "--no-dashboard",
                               "--scheduler-file", str(file)], **common)]
    try:
        address = _wait_for(file)["address"]
        procs += [subprocess.Popen([str(DASK), "worker", "--scheduler-file", str(file),
                                    "--nthreads", "1", "--no-dashboard"], **common)
                  for _ in range(2)]
        from distributed import Client
        with Client(address, timeout="60s") as client:
            client.wait_for_workers(2, timeout=120)
        yield address
    finally:
        for p in procs[::-1]:
            p.terminate()
        for p in procs:
            p.wait(timeout=60)


def test_separate_process_cluster_gives_the_numbers_of_this_process(cluster, robot_problem,
                                                                    robot_zoh):
    ctl = build_controller(robot_zoh.table)
    paths = 3 * BLOCK_PATHS + 100
    here = simulate(robot_problem, ctl, paths=paths, seed=SEED, substeps=1, workers=1)
    there = simulate(robot_problem, ctl, paths=paths, seed=SEED, substeps=1,
                     scheduler=cluster)
    for a, b in zip([here.cost_moments, *here.knot_moments],
                    [there.cost_moments, *there.knot_moments]):
        for name in ("mean", "comoment", "m3", "m4", "low", "high"):
            assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert np.array_equal(here.mean_x, there.mean_x)
    assert np.array_equal(here.sample_x, there.sample_x)
    assert here.exits.by_tick[0].tolist() == there.exits.by_tick[0].tolist()
    assert here.exits.examples == there.exits.examples
    assert (here.worst_status, here.saturated_tick_count) == (there.worst_status,
                                                              there.saturated_tick_count)
