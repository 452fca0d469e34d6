"""One-line exit-2 errors instead of tracebacks, for every command-line value
and every kind of problem FILE.

Before: ``--paths -5``, ``--seed -1``, ``--substeps 0``, ``plot --out p.txt``, ``--out`` an
existing file, a directory or a symlink loop as FILE, ``/dev/zero`` (7.7 GB read, then
MemoryError), arrays nested 1000 deep (RecursionError) and a knot at ``t = 1e308``
(OverflowError) all ended in a traceback; a missing FILE printed ``[Errno 2] ...``.
Now each gives exactly one line on stderr, ``stospline: error: OPTION: REASON`` for a
command-line value, ``stospline: error in FILE: FIELD: REASON`` for the file, exit status 2,
nothing on stdout and nothing created.
"""
import os
import subprocess
import sys

import pytest

from conftest import EXAMPLES
from stospline.cli import main
from stospline.problem.inputfile import MAX_BYTES, MAX_DEPTH
from support.problems import cart

ROBOT = str(EXAMPLES / "robot_corridor.toml")


def run_main(capsys, argv):
    """`main(argv)` as the console script runs it: (exit status, stdout, stderr)."""
    try:
        code = main(argv)
    except SystemExit as exc:          # argparse exits by itself
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def assert_one_line(code, out, err, prefix):
    assert code == 2, err
    assert out == "" and "Traceback" not in err
    assert err.count("\n") == 1 and err.endswith("\n"), err
    assert err.startswith(prefix), err


OPTION_CASES = [  # (command line after FILE, option named, reason substring)
    (["simulate", "--paths", "0"], "--paths", "integer in 2.."),
    (["simulate", "--paths=-5"], "--paths", "integer in 2.."),
    (["simulate", "--paths", "1e3"], "--paths", "got '1e3'"),
    (["simulate", "--seed=-1"], "--seed", "integer in 0..9223372036854775807"),
    (["simulate", "--seed", str(2 ** 63)], "--seed", "integer in 0.."),
    (["simulate", "--substeps", "0"], "--substeps", "integer in 1..10000"),
    (["simulate", "--substeps", "100001"], "--substeps", "integer in 1..10000"),
    (["simulate", "--x0=a,b"], "--x0", "comma-separated numbers"),
    (["simulate", "--x0="], "--x0", "comma-separated numbers"),
    (["simulate", "--x0", "-5,0"], "--x0", "expected one argument"),
    (["plot", "--out", "p.txt"], "--out", "must name a .png, .pdf, .svg file"),
    (["plot", "--out", "p"], "--out", "must name a .png"),
    (["plot", "--out", "p.png", "--paths", "0"], "--paths", "integer in 2.."),
    (["plot", "--out", "p.png", "--seed", "x"], "--seed", "integer in 0.."),
    (["design", "--max-time", "0"], "--max-time", "number of seconds"),
    (["design", "--max-time", "nan"], "--max-time", "number of seconds"),
    (["simulate", "--max-memory", "-1"], "--max-memory", "number of GiB"),
    (["design", "--arith", "q7"], "--arith", "must be one of"),
    (["design", "--mode", "both"], "--mode", "invalid choice"),
    (["simulate", "--fault", "sensor_noise"], "--fault", "must be KEY=VALUE"),
    (["simulate", "--fault", "wobble=1"], "--fault wobble", "unknown fault"),
    (["simulate", "--fault", "sensor_noise=1,2"], "--fault sensor_noise", "length 2, expected 4"),
    (["simulate", "--fault", "delay_ticks=2"], "--fault delay_ticks", "must be 0 or 1"),
    (["simulate", "--fault", "actuator_noise=nan"], "--fault actuator_noise", "finite"),
    (["simulate", "--fault", "plant_B_scale=x"], "--fault plant_B_scale", "must be a number"),
    (["report", "--out", "r.html", "--fault", "miss_probability=1"],
     "--fault miss_probability", "below 1"),
    (["report", "--out", "r.html", "--fault-paths", "-1"], "--fault-paths", "integer in 0.."),
]


@pytest.mark.parametrize("argv,option,reason", OPTION_CASES,
                         ids=[" ".join(c[0]) for c in OPTION_CASES])
def test_bad_option_value_is_one_line(capsys, tmp_path, monkeypatch, argv, option, reason):
    monkeypatch.chdir(tmp_path)        # plot --out p.* would land here (restored afterwards)
    code, out, err = run_main(capsys, [argv[0], ROBOT, *argv[1:]])
    prefix = f"stospline: error: {option}" + ("" if option == "--arith" else ": ")
    assert_one_line(code, out, err, prefix)
    assert reason in err
    assert os.listdir(tmp_path) == []


def test_out_is_an_existing_file(capsys, tmp_path):
    f = tmp_path / "afile"
    f.write_text("keep")
    code, out, err = run_main(capsys, ["design", ROBOT, "--out", str(f)])
    assert_one_line(code, out, err, "stospline: error: --out: ")
    assert "exists and is not a directory" in err and f.read_text() == "keep"


def test_out_below_a_file(capsys, tmp_path):
    f = tmp_path / "afile"
    f.write_text("keep")
    code, out, err = run_main(capsys, ["design", ROBOT, "--out", str(f / "sub" / "dir")])
    assert_one_line(code, out, err, "stospline: error: --out: ")
    assert "is not a directory" in err and sorted(os.listdir(tmp_path)) == ["afile"]


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write anywhere")
def test_out_unwritable(capsys, tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        code, out, err = run_main(capsys, ["design", ROBOT, "--out", str(ro / "o")])
    finally:
        ro.chmod(0o755)
    assert_one_line(code, out, err, "stospline: error: --out: ")
    assert "not writable" in err and os.listdir(ro) == []


def test_out_unwritable_location(capsys):
    """Under /proc nothing can be created, even by root: one line, no traceback."""
    code, out, err = run_main(capsys, ["design", str(EXAMPLES / "robot_corridor.toml"),
                                       "--out", "/proc/stospline-cannot-exist/o"])
    assert_one_line(code, out, err, "stospline: error: --out: ")


@pytest.mark.parametrize("out", ["missing/fig.png", "dir.png"])
def test_plot_out_unusable(capsys, tmp_path, out):
    (tmp_path / "dir.png").mkdir()
    code, o, err = run_main(capsys, ["plot", ROBOT, "--out", str(tmp_path / out)])
    assert_one_line(code, o, err, "stospline: error: --out: ")
    assert sorted(os.listdir(tmp_path)) == ["dir.png"]


def _file_cases(tmp):
    """(FILE, field, reason substring) for every kind of bad problem file."""
    loop = tmp / "loop.toml"
    os.symlink(tmp / "loop2.toml", loop)
    os.symlink(loop, tmp / "loop2.toml")
    big = tmp / "big.toml"
    with open(big, "wb") as fh:
        fh.truncate(MAX_BYTES + 1)                      # sparse: no 16 MiB written
    deep = tmp / "deep.toml"
    deep.write_text('name = "a"\nx0 = ' + "[" * 1000 + "]" * 1000 + "\n")
    deep40 = tmp / "deep40.toml"
    deep40.write_text('name = "a"\nx0 = ' + "[" * 40 + "1" + "]" * 40 + "\n")
    latin = tmp / "latin1.toml"
    latin.write_bytes('name = "caf\u00e9"\n'.encode("latin-1"))
    huge_t = tmp / "t1e308.toml"
    huge_t.write_text(cart(t="1e308", noise=False))
    return [
        (tmp / "missing.toml", "<file>", "cannot read: no such file"),
        (tmp, "<file>", "is a directory"),
        (loop, "<file>", "symbolic link loop"),
        (big, "<file>", f"at most {MAX_BYTES} bytes"),
        (deep, "<file>", "nested too deeply"),
        (deep40, "x0", f"nested more than {MAX_DEPTH} levels"),
        (latin, "<file>", "not UTF-8"),
        (huge_t, "knots[0].t", "ticks"),
    ]


def test_bad_problem_files(capsys, tmp_path):
    for path, field, reason in _file_cases(tmp_path):
        out = tmp_path / "o"
        code, o, err = run_main(capsys, ["design", str(path), "--out", str(out)])
        assert_one_line(code, o, err, f"stospline: error in {path}: {field}: ")
        assert reason in err, err
        assert not out.exists()


@pytest.mark.parametrize("kind", ["/dev/zero", "fifo"])
def test_device_and_fifo_are_refused_without_reading(tmp_path, kind):
    """In a child with a timeout: /dev/zero, read, would fill memory, and a FIFO without a
    writer blocks an ordinary open."""
    path = "/dev/zero"
    if kind == "fifo":
        path = str(tmp_path / "fifo.toml")
        os.mkfifo(path)
    r = subprocess.run([sys.executable, "-m", "stospline.cli", "design", path],
                       capture_output=True, text=True, timeout=60)
    assert_one_line(r.returncode, r.stdout, r.stderr, f"stospline: error in {path}: <file>: ")
    assert ("character device" if kind == "/dev/zero" else "FIFO") in r.stderr


def test_load_problem_keeps_file_not_found(tmp_path):
    """The library's missing-file error is a ProblemError on <file> and still the
    FileNotFoundError that `load_problem` documented."""
    from stospline.problem import ProblemError, load_problem
    with pytest.raises(FileNotFoundError) as info:
        load_problem(tmp_path / "nope.toml")
    assert isinstance(info.value, ProblemError) and info.value.field == "<file>"
