"""Hostile inputs against the command line's contract.

For any problem file and any command line, `stospline` either

* exits 2 with exactly one line on stderr (``stospline: ...``), nothing on stdout, and the
  file system exactly as it was (no output directory, no temporary file), or
* exits 0; for ``design`` the output directory then holds exactly ``<name>.{c,h,json}``, the
  JSON is strict (no NaN/Infinity), the C has no non-finite literal, compiles with the
  firmware's warning flags, and ``stsp_init_problem`` accepts the table.

Exit 1, a traceback, a warning, a crash, more than 60 s or more than 8 GiB of address space is
a failure (mutated problem files run with ``--max-time 10``: the tool must refuse up front
what it estimates beyond that, and finish what it accepts within 60 s). Problem files come from `hostile.problem_cases` (valid problems with mutations from
named classes); file kinds and command-line values are listed below. The number of generated
problem cases is ``STOSPLINE_HOSTILE_EXAMPLES`` (default 120, derandomized, so CI always runs
the same cases); a longer run: ``STOSPLINE_HOSTILE_EXAMPLES=3000 .venv/bin/python -m pytest
tests/python/cli/test_hostile_inputs.py``.
"""
from __future__ import annotations

import contextlib
import io
import json
import os
import re
import resource
import shutil
import signal
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, settings

from hostile import BASES, NOISY, problem_cases, to_toml
from stospline.cli import main

REPO = Path(__file__).resolve().parents[3]
FIRMWARE = REPO / "firmware"
EXAMPLES_N = int(os.environ.get("STOSPLINE_HOSTILE_EXAMPLES", "120"))
TIME_LIMIT_S = int(os.environ.get("STOSPLINE_HOSTILE_SECONDS", "60"))
ADDRESS_SPACE = 8 << 30
# The tool refuses up front what it estimates beyond --max-time; its estimates hold within a
# factor of ~3 (docs/guide/problem-file.md, Limits), so a case it accepts must end within
# TIME_LIMIT_S = 6 x MAX_TIME_S.
MAX_TIME_S = 10
WARNINGS = ["-std=c99", "-Wall", "-Wextra", "-Wpedantic", "-Wconversion", "-Wshadow", "-Werror"]
ARITH_DEFS = {"float32": [], "q15": ["-DSTSP_ARITH_Q15"], "q31": ["-DSTSP_ARITH_Q31"]}
NONFINITE_C = re.compile(r"\b(inff?|nanf?|INFINITY|NAN|HUGE_VALF?)\b", re.IGNORECASE)


class _TimeLimit(BaseException):
    """Raised by the alarm; a BaseException so that no `except Exception` in the tool hides it."""


def _on_alarm(signum, frame):
    raise _TimeLimit(f"took longer than {TIME_LIMIT_S} s")


@pytest.fixture(scope="module", autouse=True)
def bounded_process():
    """Cap the address space (a runaway allocation fails fast, not by swapping) and arm a
    per-case alarm handler; both restored afterwards."""
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_SPACE, hard))
    old = signal.signal(signal.SIGALRM, _on_alarm)
    yield
    signal.signal(signal.SIGALRM, old)
    resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


@pytest.fixture(scope="module")
def firmware_libs(tmp_path_factory):
    """The firmware compiled once per arithmetic, as an archive the checks link against."""
    root = tmp_path_factory.mktemp("fw")
    libs = {}
    for arith, defs in ARITH_DEFS.items():
        objs = []
        for src in sorted((FIRMWARE / "src").glob("*.c")):
            obj = root / f"{arith}_{src.stem}.o"
            subprocess.run(["gcc", *WARNINGS, "-O1", *defs, f"-I{FIRMWARE / 'include'}",
                            "-c", str(src), "-o", str(obj)], check=True)
            objs.append(str(obj))
        libs[arith] = root / f"libstsp_{arith}.a"
        subprocess.run(["ar", "rcs", str(libs[arith]), *objs], check=True)
    return libs


def _tree(root: Path) -> dict:
    """Every path below root with its size and mtime (what 'nothing on disk' compares)."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in dirnames + filenames:
            p = Path(dirpath, name)
            st = p.lstat()
            out[str(p.relative_to(root))] = (st.st_size, st.st_mtime_ns)
    return out


def run_cli(argv: list[str], cwd: Path) -> tuple[int, str, str]:
    """`stospline argv` in this process, in `cwd`: (exit status, stdout, stderr).

    Warnings are captured as stderr lines (a leaked RuntimeWarning breaks the one-line rule)."""
    out, err = io.StringIO(), io.StringIO()
    here = os.getcwd()
    os.chdir(cwd)
    signal.alarm(TIME_LIMIT_S)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), \
                warnings.catch_warnings():
            warnings.simplefilter("always")
            warnings.showwarning = lambda m, c, f, ln, file=None, line=None: err.write(
                f"{c.__name__}: {m}\n")
            try:
                rc = main(argv)
            except SystemExit as exc:   # argparse
                rc = exc.code if isinstance(exc.code, int) else 1
    finally:
        signal.alarm(0)
        os.chdir(here)
    return rc, out.getvalue(), err.getvalue()


def _limit_child():
    resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_SPACE, ADDRESS_SPACE))


def run_cli_isolated(argv: list[str], cwd: Path) -> tuple[int, str, str]:
    """`stospline argv` in a child process: for commands that run the compiled C controller,
    whose memory fault must fail this test, not kill the test runner. A signal death is
    reported as exit 128 + signal."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTHONWARN")}
    env["PYTHONWARNINGS"] = "always"
    try:
        p = subprocess.run([sys.executable, "-m", "stospline.cli", *argv], cwd=cwd, env=env,
                           capture_output=True, text=True, timeout=TIME_LIMIT_S,
                           preexec_fn=_limit_child)
    except subprocess.TimeoutExpired:
        raise _TimeLimit(f"took longer than {TIME_LIMIT_S} s") from None
    rc = p.returncode if p.returncode >= 0 else 128 - p.returncode
    return rc, p.stdout, p.stderr


def _strict_json(text: str):
    def refuse(name):
        raise ValueError(f"non-standard JSON constant {name}")
    return json.loads(text, parse_constant=refuse)


def check_refusal(rc, out, err, before, after, what):
    lines = err.splitlines()
    assert rc == 2, f"{what}: exit {rc}, stderr:\n{err[-3000:]}"
    assert len(lines) == 1 and lines[0].startswith("stospline: "), \
        f"{what}: stderr is not one 'stospline: ...' line:\n{err[-3000:]}"
    assert out == "", f"{what}: refused but printed on stdout: {out[:500]!r}"
    assert after == before, f"{what}: refused but changed the disk: " \
                            f"{sorted(set(after) ^ set(before))[:10]}"


def check_design_outputs(out_dir: Path, libs: dict, what: str):
    files = sorted(p.name for p in out_dir.iterdir())
    stems = {Path(f).stem for f in files}
    assert len(stems) == 1 and sorted(Path(f).suffix for f in files) == [".c", ".h", ".json"], \
        f"{what}: output directory holds {files}"
    stem = stems.pop()
    summary = _strict_json((out_dir / f"{stem}.json").read_text())
    arith = summary.get("fixed", {}).get("arith", "float32") if isinstance(
        summary.get("fixed"), dict) else "float32"
    if stem.endswith("_q15"):
        arith = "q15"
    elif stem.endswith("_q31"):
        arith = "q31"
    for suffix in (".c", ".h"):
        bad = NONFINITE_C.search((out_dir / f"{stem}{suffix}").read_text())
        assert bad is None, f"{what}: non-finite literal {bad.group(0)!r} in {stem}{suffix}"
    upper = stem.upper()
    driver = out_dir.parent / "driver.c"
    driver.write_text(
        "#include <stdio.h>\n"
        f'#include "{stem}.h"\n'
        "int main(void) {\n"
        "    stsp_ctrl_t ctrl;\n"
        f"    const uint8_t sha[32] = {upper}_PROBLEM_SHA256;\n"
        f"    stsp_status_t s = stsp_init_problem(&ctrl, &{stem}_table, {upper}_NX, {upper}_NU,"
        " sha);\n"
        '    printf("%d\\n", (int)s);\n'
        "    return s == STSP_OK ? 0 : 1;\n"
        "}\n")
    exe = out_dir.parent / "driver"
    cc = subprocess.run(["gcc", *WARNINGS, *ARITH_DEFS[arith], f"-I{FIRMWARE / 'include'}",
                         f"-I{out_dir}", str(driver), str(out_dir / f"{stem}.c"),
                         str(libs[arith]), "-lm", "-o", str(exe)],
                        capture_output=True, text=True)
    assert cc.returncode == 0, f"{what}: generated C does not compile:\n{cc.stderr[-3000:]}"
    run = subprocess.run([str(exe)], capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, f"{what}: stsp_init_problem refuses the table: {run.stdout}"
    driver.unlink()
    exe.unlink()


def check_contract(argv, cwd: Path, libs, what: str, *, out_dir: Path | None = None,
                   isolated: bool = False):
    """Run argv in cwd and assert the contract; returns the exit status."""
    before = _tree(cwd)
    rc, out, err = (run_cli_isolated if isolated else run_cli)(argv, cwd)
    after = _tree(cwd)
    if rc != 0:
        check_refusal(rc, out, err, before, after, what)
        return rc
    # A success may add one summary line of floating-point warnings (every number written
    # was checked finite); nothing else, no raw numpy warning.
    extra = [ln for ln in err.splitlines() if not ln.startswith("stospline: warning: ")]
    assert not extra or argv[0] != "design", f"{what}: exit 0 with stderr:\n{err}"
    if argv[0] == "design" and out_dir is not None:
        check_design_outputs(out_dir, libs, what)
    if "--json" in argv:
        _strict_json(out)
    return rc


# ---------------------------------------------------------------------------------------
# Generated problem files.

CLASS_COUNTS: dict[str, list[int]] = {}   # class -> [accepted, refused, broke the contract]
FAILURES: list[str] = []


@settings(max_examples=EXAMPLES_N, derandomize=True, deadline=None, database=None,
          phases=[Phase.explicit, Phase.generate], suppress_health_check=list(HealthCheck))
@given(case=problem_cases())
def test_mutated_problem_files_keep_the_contract(case, tmp_path_factory, firmware_libs):
    """Every generated case is run; a broken contract is recorded (with the file) rather than
    raised, so one run reports every failing class; the next test asserts there was none."""
    classes, base, text = case
    cwd = tmp_path_factory.mktemp("case")
    (cwd / "p.toml").write_text(text)
    what = f"classes {classes} on base {base!r}"
    try:
        rc = check_contract(["design", "p.toml", "--out", "out", "--json", "--max-time",
                             str(MAX_TIME_S)], cwd,
                            firmware_libs, what, out_dir=cwd / "out")
        slot = 0 if rc == 0 else 1
    except (AssertionError, _TimeLimit, Exception) as exc:  # noqa: BLE001 - recorded below
        slot = 2
        FAILURES.append(f"{what}: {type(exc).__name__}: {str(exc)[:600]}\n--- file ---\n"
                        f"{text[:1500]}")
    for cls in classes:
        CLASS_COUNTS.setdefault(cls, [0, 0, 0])[slot] += 1
    shutil.rmtree(cwd, ignore_errors=True)


def test_mutated_problem_files_broke_no_contract():
    """Summary of the run above: counts per class ([accepted, refused, broken]), every class
    generated, and no broken case (each is listed with its file)."""
    from hostile import MUTATIONS
    total = sum(sum(v) // 1 for v in CLASS_COUNTS.values())
    print(f"hostile problem files: {EXAMPLES_N} cases, {len(CLASS_COUNTS)} classes "
          f"[accepted, refused, broken]: {dict(sorted(CLASS_COUNTS.items()))} ({total} "
          f"class applications)")
    assert not FAILURES, f"{len(FAILURES)} of {EXAMPLES_N} cases broke the contract:\n\n" + \
        "\n\n".join(FAILURES)
    if EXAMPLES_N >= 100:
        assert set(CLASS_COUNTS) == set(MUTATIONS), "a mutation class was never generated"


@pytest.mark.parametrize("base", sorted(BASES))
def test_scaled_rows_give_the_same_design_or_a_refusal(base, tmp_path, firmware_libs):
    """The `row_scale` class with its verdict checked: every constraint, region and wall row
    of a base scaled by its own 10^k (seeded) designs the same J0 to 1e-9, or, beyond
    |k| = 12, is refused cleanly (the contract) when a scaled number leaves the normal
    doubles."""
    from hostile import ROW_SCALES, scale_rows
    rng = np.random.default_rng(2024)
    runs = []
    for trial, pool in enumerate([[1.0], [10.0 ** k for k in range(-12, 13)], ROW_SCALES]):
        doc = json.loads(json.dumps(BASES[base]))
        scale_rows(doc, lambda: float(rng.choice(pool)))
        cwd = tmp_path / str(trial)
        cwd.mkdir()
        (cwd / "p.toml").write_text(to_toml(doc))
        rc = check_contract(["design", "p.toml", "--out", "out"], cwd, firmware_libs,
                            f"{base} row scale {trial}", out_dir=cwd / "out")
        assert rc == 0 or trial == 2, f"{base}: rows scaled by 10^k, |k| <= 12, refused"
        runs.append(json.loads(next((cwd / "out").glob("*.json")).read_text())
                    if rc == 0 else None)
    for got in runs[1:]:
        if got is not None:
            assert abs(got["J0"] - runs[0]["J0"]) <= 1e-9 * max(1.0, abs(runs[0]["J0"]))


@pytest.mark.parametrize("base", sorted(BASES))
@pytest.mark.parametrize("arith", ["float32", "q15", "q31"])
def test_valid_bases_design_in_every_arithmetic(base, arith, tmp_path, firmware_libs):
    (tmp_path / "p.toml").write_text(to_toml(BASES[base]))
    rc = check_contract(["design", "p.toml", "--out", "out", "--arith", arith], tmp_path,
                        firmware_libs, f"{base} {arith}", out_dir=tmp_path / "out")
    if not (base == "bands" and arith != "float32"):
        assert rc == 0


# ---------------------------------------------------------------------------------------
# File kinds.

def _make_file(kind: str, cwd: Path) -> str:
    p = cwd / "p.toml"
    if kind == "missing":
        return "nope.toml"
    if kind == "directory":
        p.mkdir()
    elif kind == "symlink_loop":
        os.symlink("q.toml", p)
        os.symlink("p.toml", cwd / "q.toml")
    elif kind == "dangling_symlink":
        os.symlink("nowhere.toml", p)
    elif kind == "dev_zero":
        return "/dev/zero"
    elif kind == "dev_null":
        return "/dev/null"
    elif kind == "fifo":
        os.mkfifo(p)
    elif kind == "empty":
        p.write_bytes(b"")
    elif kind == "binary":
        p.write_bytes(bytes(range(256)) * 64)
    elif kind == "bad_utf8":
        p.write_bytes(to_toml(NOISY).encode() + b'\n# \xff\xfe\n')
    elif kind == "utf16":
        p.write_bytes(to_toml(NOISY).encode("utf-16"))
    elif kind == "huge":
        with open(p, "wb") as fh:
            fh.write(to_toml(NOISY).encode())
            line = b"# " + b"x" * 1022 + b"\n"
            for _ in range(20 * 1024):
                fh.write(line)
    elif kind == "nul_bytes":
        p.write_bytes(to_toml(NOISY).encode().replace(b"\n", b"\n\0", 1))
    elif kind == "deep_toml_tables":
        p.write_text("a = " + "{b = " * 3000 + "1" + "}" * 3000 + "\n")
    elif kind == "deep_toml_arrays":
        p.write_text("x0 = " + "[" * 100000 + "]" * 100000 + "\n")
    return str(p) if kind not in ("missing",) else kind


FILE_KINDS = ["missing", "directory", "symlink_loop", "dangling_symlink", "dev_zero",
              "dev_null", "fifo", "empty", "binary", "bad_utf8", "utf16", "huge", "nul_bytes",
              "deep_toml_tables", "deep_toml_arrays"]


@pytest.mark.parametrize("command", ["design", "simulate", "plot"])
@pytest.mark.parametrize("kind", FILE_KINDS)
def test_file_kinds_are_refused_in_one_line(kind, command, tmp_path, firmware_libs):
    path = _make_file(kind, tmp_path)
    argv = [command, path] + (["--out", "x.png"] if command == "plot" else [])
    rc = check_contract(argv, tmp_path, firmware_libs, f"{command} on a {kind} file")
    assert rc == 2


# ---------------------------------------------------------------------------------------
# Command-line values (on a valid problem).

CLI_CASES = [
    ("design", ["--out", "FILE"]), ("design", ["--out", "/proc/forbidden/x"]),
    ("design", ["--out", "RO/sub"]), ("design", ["--arith", "q7"]),
    ("design", ["--mode", "both"]), ("design", ["--discretization", "euler"]),
    ("design", ["--out", ""]), ("design", ["--out", "a" * 300]),
    ("simulate", ["--paths", "0"]), ("simulate", ["--paths", "-5"]),
    ("simulate", ["--paths", "1e3"]), ("simulate", ["--paths", str(10**15)]),
    ("simulate", ["--seed", "-1"]), ("simulate", ["--seed", str(2**70)]),
    ("simulate", ["--seed", "x"]), ("simulate", ["--substeps", "0"]),
    ("simulate", ["--substeps", "-3"]), ("simulate", ["--substeps", str(10**9)]),
    ("simulate", ["--x0=1e30,0"]), ("simulate", ["--x0=nan,0"]), ("simulate", ["--x0=1,2,3"]),
    ("simulate", ["--x0="]), ("simulate", ["--x0=1e400,0"]),
    ("plot", ["--out", "p.txt"]), ("plot", ["--out", "FILE/p.png"]),
    ("plot", ["--out", "p.png", "--paths", "0"]), ("plot", ["--out", "p.png", "--paths", "-1"]),
    ("plot", ["--out", "/proc/forbidden.png"]),
    ("report", ["--out", "p.png"]), ("report", ["--out", "FILE/p.html"]),
    ("report", ["--out", "p.html", "--paths", "0"]),
    ("report", ["--out", "p.html", "--workers", "0"]),
    ("simulate", ["--workers", "-2"]), ("simulate", ["--substeps", "autox"]),
    ("simulate", ["--scheduler", ""]), ("simulate", ["--scheduler", "tcp://host"]),
    ("report", ["--out", "p.html", "--scheduler", "a b:1"]),
]


@pytest.mark.parametrize("command,extra", CLI_CASES, ids=lambda v: "_".join(v)
                         if isinstance(v, list) else v)
def test_command_line_values_keep_the_contract(command, extra, tmp_path, firmware_libs):
    (tmp_path / "p.toml").write_text(to_toml(NOISY))
    (tmp_path / "FILE").write_text("not a directory")
    ro = tmp_path / "RO"
    ro.mkdir()
    ro.chmod(0o500)
    extra = [e.replace("RO/sub", str(ro / "sub")) for e in extra]
    argv = [command, "p.toml", *extra]
    if command == "simulate":
        argv += ["--paths", "20"] if "--paths" not in extra else []
    if command in ("plot", "report") and "--paths" not in extra:
        argv += ["--paths", "5"]
    try:
        rc = check_contract(argv, tmp_path, firmware_libs, " ".join(argv),
                            isolated=command != "design")
    finally:
        ro.chmod(0o700)
    if command == "simulate" and extra[0].startswith("--x0=1e30"):
        assert rc in (0, 2)
    elif os.geteuid() == 0 and "RO/sub" in " ".join(extra):
        assert rc in (0, 2)   # root writes into a read-only directory
    else:
        assert rc == 2, f"{argv} was accepted"


# ---------------------------------------------------------------------------------------
# `hil` and `board` values, refused before any design, QEMU or serial line.

BOARD_CLI_CASES = [
    ("hil", ["--board", "netduinoplus2", "--elf", "FILE", "--batch", "0"]),
    ("hil", ["--board", "netduinoplus2", "--elf", "FILE", "--batch", "256"]),
    ("hil", ["--board", "netduinoplus2", "--elf", "FILE", "--batch", "x"]),
    ("hil", ["--board", "netduinoplus2", "--elf", "FILE", "--paths", "1"]),
    ("hil", ["--board", "nosuch", "--elf", "FILE"]),
    ("hil", ["--board", "microbit", "--elf", "missing.elf"]),
    ("hil", ["--board", "microbit", "--elf", "FILE", "--arith", "q7"]),
    ("board", ["--board", "microbit", "--out", "FILE"]),
    ("board", ["--board", "microbit", "--out", "o", "--timeout-ticks", "0"]),
]


@pytest.mark.parametrize("command,extra", BOARD_CLI_CASES, ids=lambda v: "_".join(v)
                         if isinstance(v, list) else v)
def test_board_command_values_keep_the_contract(command, extra, tmp_path, firmware_libs):
    (tmp_path / "p.toml").write_text(to_toml(NOISY))
    (tmp_path / "FILE").write_text("not an image, not a directory")
    argv = [command, "p.toml", *extra]
    rc = check_contract(argv, tmp_path, firmware_libs, " ".join(argv))
    assert rc == 2, f"{argv} was accepted"


# ---------------------------------------------------------------------------------------
# Outputs and blame (hostile.OUTPUT_CASES, hostile.BLAME_CASES): output paths refused before
# any work, and overflows that name the extreme input or fault.

def _unwritable_dir() -> str | None:
    """A directory where even root cannot create a file (a pseudo file system), or None."""
    for d in ("/sys", "/proc/sys"):
        probe = os.path.join(d, ".stospline-hostile-probe")
        try:
            os.close(os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
        except OSError:
            if os.path.isdir(d):
                return d
            continue
        os.unlink(probe)
    return None


@pytest.mark.parametrize("case", sorted(__import__("hostile").OUTPUT_CASES))
def test_hostile_output_paths_are_refused_first(case, tmp_path, monkeypatch):
    from hostile import OUTPUT_CASES
    from stospline import pipeline
    command, out, words = OUTPUT_CASES[case]
    unwritable = _unwritable_dir()
    if "{unwritable}" in out and unwritable is None:
        pytest.skip("no pseudo file system here")
    name = {"design": f"{NOISY['name']}.json", "plot": "p.png", "report": "p.html"}[command]
    (tmp_path / name).write_text(to_toml(NOISY))     # a problem file named like an output
    out = out.format(input=name, here=".", unwritable=unwritable)

    def no_work(*a, **k):
        raise AssertionError("design or Monte Carlo started before the refusal")
    monkeypatch.setattr(pipeline, "design_problem", no_work)
    before = _tree(tmp_path)
    rc, stdout, err = run_cli([command, name, "--out", out], tmp_path)
    check_refusal(rc, stdout, err, before, _tree(tmp_path), case)
    assert words in err and "--out" in err, err


@pytest.mark.parametrize("case", sorted(__import__("hostile").BLAME_CASES))
def test_hostile_overflows_name_their_cause(case, tmp_path):
    import copy
    from hostile import BLAME_CASES, ROBOT_EDITS, UNSTABLE, _blame_edit
    base, how, extra, field = BLAME_CASES[case]
    if base == "robot":
        text = (REPO / "examples" / "robot_corridor.toml").read_text()
        if how is not None:
            text = text.replace(*ROBOT_EDITS[how])
    else:
        doc = copy.deepcopy(NOISY if base == "noisy" else UNSTABLE)
        _blame_edit(doc, how)
        text = to_toml(doc)
    (tmp_path / "p.toml").write_text(text)
    argv = ["simulate", "p.toml", "--paths", "20", "--json", *extra]
    before = _tree(tmp_path)
    rc, stdout, err = run_cli_isolated(argv, tmp_path)
    if field is None:
        assert rc == 0, err
        _strict_json(stdout)
    else:
        check_refusal(rc, stdout, err, before, _tree(tmp_path), case)
        assert f": {field}:" in err and "no single input is extreme" not in err, err


# ---------------------------------------------------------------------------------------
# Board and HIL (hostile.BOARD_CASES): `stospline board` and `stospline hil` options, files
# and serial peers, each refused in one line naming its option, nothing on disk.

@contextlib.contextmanager
def _fake_board(data):
    """A local TCP server playing a board: accepts one connection, sends `data` (None: hangs
    up at once), then waits until the client hangs up. Yields its port."""
    import socket
    import threading
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)
    srv.settimeout(TIME_LIMIT_S)

    def serve():
        try:
            conn, _ = srv.accept()
        except OSError:
            return
        with conn:
            if data is None:
                return
            conn.sendall(data)
            conn.settimeout(TIME_LIMIT_S)
            try:
                while conn.recv(4096):
                    pass
            except OSError:
                pass
    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    port = srv.getsockname()[1]
    try:
        yield port
    finally:
        if thread.is_alive():   # no client came (refused before the line): wake accept()
            with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port)):
                pass
        thread.join(timeout=5)
        srv.close()


def _closed_port() -> int:
    import socket
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize("case", sorted(__import__("hostile").BOARD_CASES))
def test_board_and_hil_inputs_are_refused_naming_the_option(case, tmp_path):
    import copy
    from hostile import BOARD_CASES, BOARD_PEERS, arm_stub_elf
    argv, words = BOARD_CASES[case]
    reaches_line = argv[0] == "hil" and "--paths" in argv and "2" in argv
    if "{arm_stub}" in argv and reaches_line and shutil.which("qemu-system-arm") is None:
        pytest.skip("needs qemu-system-arm (tools/setup.sh installs it)")
    (tmp_path / "p.toml").write_text(to_toml(NOISY))
    delayed = copy.deepcopy(NOISY)
    delayed["design"] = {"delay_ticks": 1}
    (tmp_path / "delayed.toml").write_text(to_toml(delayed))
    faulty = copy.deepcopy(NOISY)
    faulty["faults"] = {"sensor_noise": [0.01, 0.01]}
    (tmp_path / "faulty.toml").write_text(to_toml(faulty))
    (tmp_path / "FILE").write_text("not a directory, not a serial line")
    (tmp_path / "dir").mkdir()
    os.mkfifo(tmp_path / "fifo")
    (tmp_path / "text.elf").write_text("not an image\n")
    (tmp_path / "x86.elf").write_bytes(b"\x7fELF\x02\x01\x01" + bytes(9) + b"\x02\x00\x3e\x00"
                                       + bytes(44))
    (tmp_path / "stub.elf").write_bytes(arm_stub_elf())
    peer = next((a[len("{peer:"):-1] for a in argv if a.startswith("{peer:")), None)
    names = {"{problem}": "p.toml", "{delayed}": "delayed.toml", "{faulty}": "faulty.toml",
             "{file}": "FILE", "{dir}": "dir", "{fifo}": "fifo", "{text}": "text.elf",
             "{elf64}": "x86.elf", "{arm_stub}": "stub.elf",
             "{closed}": f"tcp:127.0.0.1:{_closed_port()}"}
    data = BOARD_PEERS.get(peer)
    if callable(data):
        from stospline.pipeline import design_problem
        from stospline.problem.reader import load_problem
        from stospline.table.format import table_crc32
        data = data(table_crc32(design_problem(load_problem(tmp_path / "p.toml")).table))
    with (_fake_board(data) if peer else contextlib.nullcontext()) as port:
        names[f"{{peer:{peer}}}"] = f"tcp:127.0.0.1:{port}"
        args = [names.get(a, a.replace("{file}", "FILE")) for a in argv] + ["--quiet"]
        before = _tree(tmp_path)
        rc, stdout, err = (run_cli_isolated if reaches_line else run_cli)(args, tmp_path)
    if words is None:
        assert rc == 0, err
        assert (tmp_path / "o" / "CMakeLists.txt").is_file()
        return
    check_refusal(rc, stdout, err, before, _tree(tmp_path), f"{case}: {args}")
    assert words in err, f"{case}: the refusal does not name {words!r}: {err}"
