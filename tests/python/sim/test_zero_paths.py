"""Zero Monte Carlo paths must not corrupt memory.

A ``harness_init_batch`` that initialised ``ctrls[0]`` whatever the count would write a whole
controller instance into a zero-length cffi array (``free(): invalid next size``,
SIGSEGV/SIGABRT), and ``harness_step_batch`` would read ``ctrls[0].table``. The C helpers touch
nothing for count 0, the Python wrappers refuse it, and the CLI refuses ``--paths`` below 2
with the one-line error.
"""
import subprocess
import sys

import pytest

from support.problems import cart as cart_problem


@pytest.fixture(scope="module")
def cart(tmp_path_factory):
    path = tmp_path_factory.mktemp("cart") / "cart0.toml"
    path.write_text(cart_problem(name="cart0"))
    return path


@pytest.fixture(scope="module")
def controller(cart):
    from stospline.harness.controller import build_controller
    from stospline.pipeline import design_problem
    from stospline.problem import load_problem
    return build_controller(design_problem(load_problem(cart)).table)


def test_init_batch_writes_nothing_for_count_zero(controller):
    """A one-instance buffer stands for the memory after a zero-length array: count 0 must
    leave every byte of it as it was (no stsp_init of instance 0 there)."""
    ffi, lib = controller.ffi, controller.lib
    guard = ffi.new("stsp_ctrl_t[]", 1)
    raw = ffi.buffer(guard)
    raw[:] = b"\xa5" * len(raw)
    status = lib.harness_init_batch(guard, 0, controller.c_table)
    assert bytes(raw) == b"\xa5" * len(raw)
    assert status == -1                 # STSP_ERR_NULL: there is no instance to initialise


def test_batch_helpers_with_no_instances_do_not_dereference(cart):
    """Count 0 and NULL arrays: before the fix step_batch read ctrls[0].table and pair_batch
    proto->table (SIGSEGV). Run in a child process so that a crash fails only this test."""
    script = (
        "import sys\n"
        "from stospline.harness.controller import build_controller\n"
        "from stospline.pipeline import design_problem\n"
        "from stospline.problem import load_problem\n"
        "c = build_controller(design_problem(load_problem(sys.argv[1])).table)\n"
        "ffi, lib, N = c.ffi, c.lib, c.ffi.NULL\n"
        "print(lib.harness_init_batch(N, 0, c.c_table), lib.harness_init_batch(N, 5, c.c_table),"
        " lib.harness_step_batch(N, 0, 0, N, N, N),"
        " lib.harness_pair_batch(N, 0, N, N, N, N, N, N))\n")
    r = subprocess.run([sys.executable, "-c", script, str(cart)], capture_output=True,
                       text=True, timeout=600)
    assert r.returncode == 0, (r.returncode, r.stderr[-2000:])
    assert r.stdout.split() == ["-1", "-1", "-1", "-1"]


@pytest.mark.parametrize("count", [0, -1, 1.5, True])
def test_python_wrappers_refuse_no_instances(controller, count):
    with pytest.raises(ValueError, match="instances must be an integer >= 1"):
        controller.new_instances(count)
    with pytest.raises(ValueError, match="instances must be an integer >= 1"):
        controller.stepper(count)


def test_simulate_refuses_zero_paths_before_allocating(controller, cart):
    from stospline.harness.montecarlo import simulate
    from stospline.problem import load_problem
    p = load_problem(cart)
    for kw in ({"paths": 0}, {"paths": -3}, {"paths": 4, "substeps": 0}):
        with pytest.raises(ValueError, match=r"(paths|substeps) must be an integer >= 1"):
            simulate(p, controller, seed=1, **{"substeps": 2, **kw})


@pytest.mark.parametrize("command", ["simulate", "plot"])
@pytest.mark.parametrize("paths", ["0", "1", "-5"])
def test_cli_refuses_too_few_paths(tmp_path, cart, command, paths):
    extra = ["--out", str(tmp_path / "fig.png")] if command == "plot" else []
    r = subprocess.run([sys.executable, "-m", "stospline.cli", command, str(cart),
                        f"--paths={paths}", *extra], capture_output=True, text=True)
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and r.stdout == ""
    assert r.stderr.startswith("stospline: error: --paths: must be an integer in 2..")
    assert not (tmp_path / "fig.png").exists()
