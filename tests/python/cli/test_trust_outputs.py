"""Outputs that never touch what is not theirs, and errors that name the right thing, early.

* An output that would replace an input file, an over-long name or path, an unwritable or
  missing directory: refused in one line, exit 2, before any design or Monte Carlo work.
* Recovery of an earlier writer's staging directory publishes only what this module staged in
  that very directory (a copied, edited or out-of-date one is left alone).
* Overflows name the extreme input (a corridor's A, the drift f, a time-varying sample, a
  fault), a loop whose ticks are all missed is not an overflow, tiny inputs are echoed as
  given, an unreachable corridor epsilon or an empty polygon is refused before screening, and
  a failed corridor search prints nothing on stdout (test_corridor_design_command.py).
* No C compiler: one line naming what to install (simulate), a fallback with one note (design).
* SIGINT at any moment of a run: exit 130 with one line, no traceback.
"""
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from stospline import atomic, pipeline
from stospline.cli import main

REPO = Path(__file__).resolve().parents[3]
EXAMPLES = REPO / "examples"

CART = textwrap.dedent("""\
    name = "cart"
    x0 = [0.0, 0.0]
    tick_hz = 10
    [dynamics]
    A = [[0, 1], [0, 0]]
    B = [[0], [1]]
    noise = [{ state = 1, G = [[0], [0.3]] }]
    [cost]
    R = [[1]]
    [[knots]]
    t = 1.0
    constraint = { C = [[1, 0]], value = [1.0] }
    [[knots]]
    t = 2.0
    constraint = { C = [[1, 0], [0, 1]], value = [0.0, 0.0] }
    """)


def _run(capsys, argv):
    rc = main(argv)
    out, err = capsys.readouterr()
    return rc, out, err


def _one_line_refusal(rc, out, err, *words):
    lines = err.strip().splitlines()
    assert rc == 2 and out == "" and len(lines) == 1, (rc, out, err)
    for w in words:
        assert w in lines[0], (w, lines[0])
    return lines[0]


@pytest.fixture
def no_work(monkeypatch):
    """Any design or Monte Carlo run fails the test: a refusal must come before them."""
    # Imported before the patch: it binds pipeline.design_problem when first imported, and
    # would keep the patched one for the tests that run after this one.
    from stospline import corridor_search

    def boom(*a, **k):
        raise AssertionError("work started before the refusal")
    monkeypatch.setattr(pipeline, "design_problem", boom)
    monkeypatch.setattr(pipeline, "simulate_problem", boom)
    monkeypatch.setattr(corridor_search, "evaluate_grid", boom)


def _tree(root: Path) -> dict:
    return {str(p.relative_to(root)): (p.lstat().st_size, p.lstat().st_mtime_ns)
            for p in root.rglob("*")}


# ---------------------------------------------------------------------------------------
# Outputs equal to an input.

def test_corridor_design_never_replaces_its_input(capsys, tmp_path, no_work):
    src = (EXAMPLES / "robot_corridor.toml").read_text().replace(
        "[[corridors]]\n", "[[corridors]]\nepsilon = 0.1\n", 1)
    f = tmp_path / "robot_corridor.toml"       # the name corridor-design writes
    f.write_text(src)
    before = _tree(tmp_path)
    line = _one_line_refusal(*_run(capsys, ["corridor-design", str(f), "--out", str(tmp_path)]),
                             "--out", "input file")
    assert "robot_corridor.toml" in line and _tree(tmp_path) == before


def test_design_never_replaces_its_input(capsys, tmp_path, no_work):
    f = tmp_path / "cart.json"                  # design writes cart.{c,h,json}
    f.write_text(CART)
    before = _tree(tmp_path)
    _one_line_refusal(*_run(capsys, ["design", str(f), "--out", str(tmp_path)]), "--out",
                      "input file")
    assert _tree(tmp_path) == before


def test_design_refuses_a_hard_link_to_its_input(capsys, tmp_path, no_work):
    f = tmp_path / "p.toml"
    f.write_text(CART)
    (tmp_path / "out").mkdir()
    os.link(f, tmp_path / "out" / "cart.h")
    _one_line_refusal(*_run(capsys, ["design", str(f), "--out", str(tmp_path / "out")]),
                      "input file")


@pytest.mark.parametrize("command,suffix", [("plot", ".png"), ("report", ".html")])
def test_plot_and_report_never_replace_their_input(capsys, tmp_path, no_work, command, suffix):
    f = tmp_path / f"p{suffix}"                 # a problem file with the output's suffix
    f.write_text(CART)
    _one_line_refusal(*_run(capsys, [command, str(f), "--out", str(f)]), "input file")
    assert f.read_text() == CART


# ---------------------------------------------------------------------------------------
# Output paths refused before any work.

def _unwritable_dir() -> str | None:
    """A directory where no file can be created even by root (a pseudo file system)."""
    for d in ("/sys", "/proc/sys"):
        try:
            fd = os.open(d, os.O_RDONLY | os.O_DIRECTORY)
            os.close(fd)
        except OSError:
            continue
        try:
            probe = os.open(os.path.join(d, ".stospline-test-probe"),
                            os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        except OSError:
            return d
        os.close(probe)
        os.unlink(os.path.join(d, ".stospline-test-probe"))
    return None


OUT_CASES = {
    "long_name": ("a" * 300, "longer than"),
    "long_name_near_limit": ("a" * 250, None),          # fits, so must not fail late either
    "long_path": ("/".join(["d" * 200] * 22), "longer than"),
    "missing_parent": ("missing/dir/", "cannot be used"),
    "parent_is_file": ("FILE/", "not a directory"),
}


@pytest.mark.parametrize("command", ["design", "plot", "report"])
@pytest.mark.parametrize("case", sorted(OUT_CASES))
def test_output_paths_refused_before_any_work(capsys, tmp_path, monkeypatch, no_work, command,
                                              case):
    (tmp_path / "p.toml").write_text(CART)
    (tmp_path / "FILE").write_text("a file")
    monkeypatch.chdir(tmp_path)
    path, words = OUT_CASES[case]
    if command == "design":
        if case == "missing_parent":
            return                  # design creates its directory
        out = path.rstrip("/") + ("/x" if case == "parent_is_file" else "")
    else:
        out = path + ("p" if path.endswith("/") else "") + (".png" if command == "plot"
                                                            else ".html")
    before = _tree(tmp_path)
    if words is None:               # accepted by the checks: the work (stubbed) starts
        with pytest.raises(AssertionError, match="work started"):
            main([command, "p.toml", "--out", out])
        return
    _one_line_refusal(*_run(capsys, [command, "p.toml", "--out", out]), "--out", words)
    assert _tree(tmp_path) == before


@pytest.mark.parametrize("command", ["design", "plot", "report", "corridor-design"])
def test_unwritable_out_refused_before_any_work(capsys, tmp_path, no_work, command):
    d = _unwritable_dir()
    if d is None:
        pytest.skip("no pseudo file system to write into")
    f = tmp_path / "p.toml"
    f.write_text(CART if command != "corridor-design" else
                 (EXAMPLES / "robot_corridor.toml").read_text().replace(
                     "[[corridors]]\n", "[[corridors]]\nepsilon = 0.1\n", 1))
    out = {"design": f"{d}/out", "corridor-design": f"{d}/out", "plot": f"{d}/p.png",
           "report": f"{d}/p.html"}[command]
    _one_line_refusal(*_run(capsys, [command, str(f), "--out", out]), "--out", "not writable")


def test_long_report_name_is_written(tmp_path):
    """A name that NAME_MAX allows is written (its temporary name is short)."""
    target = tmp_path / ("r" * 250 + ".html")
    atomic.write_file(target, lambda tmp: Path(tmp).write_text("page"))
    assert target.read_text() == "page" and sorted(os.listdir(tmp_path)) == [target.name]


# ---------------------------------------------------------------------------------------
# Recovery touches only what it staged itself.

def _committed_stage(out: Path, files: dict[str, bytes], tag="x") -> Path:
    """What a writer killed between commit and publication leaves: a committed staging
    directory of `files` in `out`."""
    stage = out / f"{atomic.STAGING_PREFIX}{tag}"
    stage.mkdir()
    for name, blob in files.items():
        (stage / name).write_bytes(blob)
    (stage / atomic.JOURNAL).write_bytes(atomic._journal_record(out, stage, files))
    return stage


def test_own_committed_staging_is_published(tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    (out / "a.c").write_text("old")
    _committed_stage(out, {"a.c": b"new"})
    atomic.recover(out)
    assert (out / "a.c").read_text() == "new" and os.listdir(out) == ["a.c"]


@pytest.mark.parametrize("present", [True, False], ids=["replacing", "creating"])
def test_copied_staging_directory_is_left_alone(tmp_path, present):
    """A committed staging directory that came from elsewhere (copied, checked out of version
    control) lists a file: the next write must neither replace that file of this directory nor
    create it."""
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    stage = _committed_stage(elsewhere, {"notes.txt": b"theirs"})
    out = tmp_path / "o"
    out.mkdir()
    if present:
        (out / "notes.txt").write_text("mine")
    shutil.copytree(stage, out / stage.name)
    atomic.write_set(out, {"cart.c": "c"})
    assert (out / "notes.txt").read_text() == "mine" if present else \
        not (out / "notes.txt").exists()
    assert (out / stage.name / "notes.txt").read_bytes() == b"theirs"   # left as it was


@pytest.mark.parametrize("tamper", ["list_journal", "edited_file", "target_changed",
                                    "extra_file", "bad_name"])
def test_unverifiable_staging_is_left_alone(tmp_path, tamper):
    out = tmp_path / "o"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    stage = _committed_stage(out, {"notes.txt": b"staged"})
    if tamper == "list_journal":            # the journal of an older or foreign writer
        (stage / atomic.JOURNAL).write_text(json.dumps(["notes.txt"]))
    elif tamper == "edited_file":
        (stage / "notes.txt").write_bytes(b"Staged")
    elif tamper == "target_changed":        # the user edited the target since the commit
        os.utime(out / "notes.txt", ns=(1, 1))
    elif tamper == "extra_file":
        (stage / "other.txt").write_text("x")
    else:
        rec = json.loads((stage / atomic.JOURNAL).read_text())
        rec["files"][0]["name"] = "../notes.txt"
        (stage / atomic.JOURNAL).write_text(json.dumps(rec))
    atomic.recover(out)
    assert (out / "notes.txt").read_text() == "mine" and stage.is_dir()


def test_recovery_never_publishes_over_an_input(tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    (out / "cart.toml").write_text("the problem")
    _committed_stage(out, {"cart.toml": b"designed"})
    atomic.write_set(out, {"cart.c": "c"}, inputs=[out / "cart.toml"])
    assert (out / "cart.toml").read_text() == "the problem"


# ---------------------------------------------------------------------------------------
# The right key in every error.

def _corridor_example(tmp_path, edit) -> Path:
    f = tmp_path / "robot.toml"
    f.write_text(edit((EXAMPLES / "robot_corridor.toml").read_text()))
    return f


UNSTABLE = CART.replace("A = [[0, 1], [0, 0]]", "A = [[0, 1], [0, 0.5]]")

# A corridor wall of 1e308 does not overflow: walls are scaled as read
# (`stospline.problem.rows`; tests/python/design/test_row_scale.py).
OVERFLOW_CASES = {
    "drift_f": (lambda t: t.replace("[cost]", "f = [0, 1e308, 0, 0]\n\n[cost]", 1),
                ["design"], "dynamics.f"),
    "plant_noise_scale": (lambda t: t, ["simulate", "--paths", "50", "--fault",
                                        "plant_noise_scale=1000"], "--fault plant_noise_scale"),
}


@pytest.mark.parametrize("case", sorted(OVERFLOW_CASES))
def test_overflow_names_the_extreme_input(capsys, tmp_path, case):
    edit, argv, field = OVERFLOW_CASES[case]
    f = _corridor_example(tmp_path, edit)
    rc, out, err = _run(capsys, [argv[0], str(f), *argv[1:], "--quiet"])
    line = _one_line_refusal(rc, out, err, field)
    assert "no single input is extreme" not in line and "knots[0].t" not in line


def test_plant_A_scale_overflow_names_the_fault(capsys, tmp_path):
    f = tmp_path / "p.toml"
    f.write_text(UNSTABLE.replace("t = 2.0", "t = 20.0").replace("tick_hz = 10",
                                                                    "tick_hz = 10\n[faults]\n"
                                                                    "plant_A_scale = 1000"))
    rc, out, err = _run(capsys, ["simulate", str(f), "--paths", "20", "--substeps", "1"])
    _one_line_refusal(rc, out, err, "faults.plant_A_scale", "1000")


def test_time_varying_sample_is_named_with_its_size(capsys, tmp_path):
    f = tmp_path / "p.toml"
    f.write_text(CART.replace("B = [[0], [1]]",
                              "B = { t = [0.0, 0.55, 2.0], values = [[[0], [1]], [[0], [1e308]],"
                              " [[0], [1]]] }"))
    rc, out, err = _run(capsys, ["design", str(f)])
    line = _one_line_refusal(rc, out, err, "dynamics.B")
    assert "1e+308" in line or "1e308" in line, line


def test_all_ticks_missed_is_not_an_overflow(capsys):
    # One plant step per tick: the commands (none issued) do not depend on the plant's steps,
    # and "auto" picks the 10000-step ceiling for this open loop.
    rc, out, err = _run(capsys, ["simulate", str(EXAMPLES / "robot_corridor.toml"), "--paths",
                                 "50", "--substeps", "1", "--fault",
                                 "miss_probability=0.999999999", "--json"])
    assert rc == 0, err
    sat = json.loads(out)["saturation"]
    assert sat["u_low"] == [None, None] and sat["u_high"] == [None, None]
    assert "no command was issued" in sat["u_range_undefined"]


@pytest.mark.parametrize("eps", ["1e-300", "5e-324", "0.1234567890123"])
def test_tiny_inputs_are_echoed_exactly(capsys, tmp_path, eps):
    f = _corridor_example(tmp_path, lambda t: t.replace("[[corridors]]\n",
                                                        f"[[corridors]]\nepsilon = {eps}\n", 1))
    rc, out, err = _run(capsys, ["simulate", str(f), "--json", "--paths", "20"])
    assert rc == 0, err
    (c,) = json.loads(out)["corridors"]
    assert c["epsilon"] == float(eps) and f'"epsilon": {float(eps)!r}' in out


def test_spline_tolerance_bound_is_float32s():
    from stospline.table.spline.fit import MIN_TOLERANCE
    from stospline.table_options import check_spline_tolerance
    assert MIN_TOLERANCE == 4 * float(__import__("numpy").finfo("float32").eps)
    assert check_spline_tolerance(MIN_TOLERANCE, "x") == MIN_TOLERANCE
    with pytest.raises(ValueError, match=r"4\.77e-07"):
        check_spline_tolerance(math.nextafter(MIN_TOLERANCE, 0), "x")


def test_guide_lists_stage_drift():
    text = (REPO / "docs/guide/problem-file.md").read_text()
    assert "| `dynamics` | `A`, `B`, `f`, `noise`" in text
    assert "[1e-9, 0.1]" not in text


# ---------------------------------------------------------------------------------------
# Refusals before work: faults, corridor searches that cannot succeed.

def test_faults_on_time_varying_data_refused_before_design(capsys, tmp_path, no_work):
    f = tmp_path / "p.toml"
    f.write_text(CART.replace("A = [[0, 1], [0, 0]]",
                              "A = { t = [0.0, 2.0], values = [[[0, 1], [0, 0]], "
                              "[[0, 1], [0, -0.5]]] }"))
    for argv in (["simulate", str(f)], ["plot", str(f), "--out", str(tmp_path / "p.png")]):
        _one_line_refusal(*_run(capsys, [*argv, "--fault", "sensor_noise=0.1,0.1"]),
                          "--fault", "time-invariant")


@pytest.mark.parametrize("edit,field", [
    (lambda t: t.replace("[[corridors]]\n", "[[corridors]]\nepsilon = 1e-9\n", 1),
     "corridors[0].epsilon"),
    (lambda t: t.replace("[[corridors]]\n", "[[corridors]]\nepsilon = 0.1\n", 1).replace(
        "b = [2, 0, 0] }", "b = [-2, 0, 0] }"), "corridors[0].polygons[1]"),
])
def test_corridor_search_that_cannot_succeed_is_refused_first(capsys, tmp_path, no_work, edit,
                                                              field):
    f = _corridor_example(tmp_path, edit)
    _one_line_refusal(*_run(capsys, ["corridor-design", str(f)]), field)


# ---------------------------------------------------------------------------------------
# No C compiler; SIGINT from the first instruction.

def _child(argv, env_extra=None, **kw):
    env = {**os.environ, "PYTHONPATH": str(REPO / "host"), **(env_extra or {})}
    return subprocess.run([sys.executable, "-m", "stospline", *argv], env=env,
                          capture_output=True, text=True, timeout=600, **kw)


def test_no_compiler(tmp_path):
    (tmp_path / "p.toml").write_text(CART)
    env = {"CC": str(tmp_path / "no-such-cc"), "STOSPLINE_CACHE_DIR": str(tmp_path / "cache")}
    sim = _child(["simulate", "p.toml", "--paths", "20"], env, cwd=tmp_path)
    assert sim.returncode == 2 and sim.stdout == "", sim.stderr
    (line,) = sim.stderr.splitlines()
    assert "simulate needs a C compiler" in line and "apt-get install gcc" in line
    des = _child(["design", "p.toml"], env, cwd=tmp_path)
    assert des.returncode == 0, des.stderr
    (note,) = des.stderr.splitlines()
    assert note.startswith("stospline: note: no C compiler") and "floating-point" not in note


SIGINT_AFTER = [0.005, 0.02, 0.05, 0.1, 0.2, 0.4]


@pytest.mark.parametrize("delay", SIGINT_AFTER)
def test_sigint_at_any_moment_ends_in_one_line(tmp_path, delay):
    """From main's first instruction on (its imports included) a SIGINT ends the run with
    exit 130 and one line. The child arms the timer as main installs its handler (main's
    first step), so a loaded machine cannot deliver the signal before main has begun; as from
    an interactive shell, SIGINT starts at its default (a pytest-xdist worker, whose
    disposition a child inherits, ignores it)."""
    (tmp_path / "p.toml").write_text(CART)
    code = ("import os, signal, sys, threading\n"
            "signal.signal(signal.SIGINT, signal.default_int_handler)\n"
            "from stospline import cli\n"
            "catch = cli._catch_interrupts\n"
            "def armed():\n"
            "    restore = catch()\n"
            f"    threading.Timer({delay}, os.kill, (os.getpid(), signal.SIGINT)).start()\n"
            "    return restore\n"
            "cli._catch_interrupts = armed\n"
            "rc = cli.main(['simulate', 'p.toml', '--paths', '200000', '--substeps', '50',"
            " '--workers', '1'])\n"
            "sys.exit(rc)\n")
    env = {**os.environ, "PYTHONPATH": str(REPO / "host")}
    p = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True,
                       text=True, timeout=600)
    assert p.returncode == 130, (p.returncode, p.stderr[-2000:])
    assert p.stderr.splitlines() == ["stospline: interrupted"] and p.stdout == "", p.stderr
    assert sorted(os.listdir(tmp_path)) == ["p.toml"]


def test_cli_module_loads_nothing_heavy():
    """The console entry point's module imports neither numpy nor importlib.metadata, so the
    interpreter reaches `main` (and its SIGINT handling) at once."""
    code = ("import sys, stospline.cli\n"
            "print(sorted(m for m in ('numpy', 'scipy', 'importlib.metadata', 'cffi') "
            "if m in sys.modules))")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       env={**os.environ, "PYTHONPATH": str(REPO / "host")}, timeout=60)
    assert p.returncode == 0 and p.stdout.strip() == "[]", p.stdout + p.stderr


@pytest.fixture
def sigint_default():
    """SIGINT at Python's default handler for the test, as in an interactive shell (a
    pytest-xdist worker ignores it); restored after."""
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, old)


def test_interrupt_turned_into_another_error_still_ends_in_one_line(capsys, monkeypatch,
                                                                    sigint_default):
    """numpy turns a SIGINT during its import into an ImportError: after a SIGINT, whatever
    ends the run is reported as the interrupt."""
    import time

    from stospline import cli

    def interrupted_import():
        try:
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(5)
        except KeyboardInterrupt:
            raise ImportError("could not import module 'datetime'") from None
    monkeypatch.setattr(cli, "build_parser", interrupted_import)
    assert main(["design", "p.toml"]) == 130
    assert capsys.readouterr().err == "stospline: interrupted\n"
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler   # restored
