"""The files of one design appear together or not at all.

Renaming the files one by one with no journal would let a SIGTERM/SIGINT between the renames
leave a new ``.h`` beside an old ``.c``/``.json`` and orphan ``.tmp`` files, and a target that
is a directory a half-replaced set; and without fsync nothing is durable.

Here every write, fsync, open, rename and unlink of a write is made to fail, or to raise
SIGTERM, SIGINT or SIGKILL, at each call in turn (`stospline.atomic`), and the directory
must then hold exactly the old set or exactly the new set (byte for byte, the three files
naming the same problem SHA-256), with no staging leftovers - for SIGKILL after the recovery
that the next write (or `atomic.recover`) performs. A real ``stospline design`` process is
also killed at random times.
"""
import errno
import json
import os
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from stospline import atomic
from stospline.pipeline import design_problem, generated_files, write_outputs
from stospline.problem import parse_problem

CART = """\
name = "cart"
x0 = [{x0}, 0.0]
tick_hz = 10
[dynamics]
A = [[0, 1], [0, 0]]
B = [[0], [1]]
noise = [{{ state = 1, G = [[0], [0.3]] }}]
[cost]
R = [[1]]
[[knots]]
t = 1.0
constraint = {{ C = [[1, 0]], value = [1.0] }}
[[knots]]
t = 2.0
constraint = {{ C = [[1, 0], [0, 1]], value = [0.0, 0.0] }}
"""
CALLS = ("open", "write", "fsync", "rename", "replace", "mkdir", "unlink", "rmdir")


def _files(x0: float) -> dict[str, str]:
    import hashlib
    import tomllib
    text = CART.format(x0=x0)
    p = parse_problem(tomllib.loads(text), source_sha256=hashlib.sha256(text.encode()).hexdigest())
    return generated_files(design_problem(p), "cart.toml")


@pytest.fixture(scope="module")
def sets():
    """(old, new): two complete sets of the same names from different problems."""
    old, new = _files(0.0), _files(0.5)
    assert old.keys() == new.keys() and all(old[k] != new[k] for k in old)
    return old, new


def _sha(name: str, text: str) -> str:
    if name.endswith(".json"):
        return json.loads(text)["problem_sha256"]
    return re.search(r"problem sha256 ([0-9a-f]{64})", text).group(1)


def state(out, sets) -> str:
    """'old' or 'new' when `out` holds exactly that set and nothing else; else fails."""
    old, new = sets
    names = sorted(os.listdir(out))
    assert names == sorted(old), f"leftovers or missing files: {names}"
    got = {n: (out / n).read_text() for n in names}
    assert len({_sha(n, b) for n, b in got.items()}) == 1, "files of different designs"
    if got == old:
        return "old"
    assert got == new, "a file is neither the old nor the new version"
    return "new"


def _each_file_whole(out, sets) -> None:
    """Between a SIGKILL and the recovery each target is still a whole old or new file."""
    old, new = sets
    for n in old:
        if (out / n).exists():
            assert (out / n).read_text() in (old[n], new[n]), n


class _Inject:
    """Wrap the os calls of a write; at call number `at` (1-based, over all of them) run
    `action`. With `only`, act on every call of that function from call `at` on instead."""

    def __init__(self, monkeypatch, at: int, action, only: str | None = None):
        self.count, self.at, self.action, self.only = 0, at, action, only
        self.hit_name = None
        for name in CALLS:
            monkeypatch.setattr(os, name, self._wrap(name, getattr(os, name)))

    def _wrap(self, name, real):
        def call(*args, **kwargs):
            self.count += 1
            hit = (self.count == self.at if self.only is None
                   else self.count >= self.at and name == self.only)
            if hit:
                self.hit_name = name
                self.action(name)
            return real(*args, **kwargs)
        return call


def _fail(name):
    raise OSError(errno.EIO, f"injected failure in os.{name}")


def test_every_single_failure_leaves_old_or_new(tmp_path, monkeypatch, sets):
    """One failure at call k, for every k: an error leaves the old set, and a failure after
    the commit point is retried from the journal, so the call then succeeds with the new set."""
    old, new = sets
    outcomes = {}
    k = 0
    while True:
        k += 1
        out = tmp_path / f"k{k}"
        atomic.write_set(out, old)
        with monkeypatch.context() as mp:
            inj = _Inject(mp, k, _fail)
            try:
                write_outputs(out, new)
                raised = None
            except OSError as exc:       # OutputError
                raised = str(exc)
        got = state(out, sets)
        assert (raised is None and got == "new") or (raised and got == "old"), (k, raised, got)
        outcomes[k] = (inj.hit_name, got)
        if inj.count < k:                 # no call k: every point has been covered
            break
    calls = [name for name, _ in outcomes.values() if name]
    assert {"write", "fsync", "rename", "replace", "unlink"} <= set(calls), calls
    assert {g for _, g in outcomes.values()} == {"old", "new"}
    assert len(outcomes) > 20


@pytest.mark.parametrize("target", ["replace", "fsync"])
def test_persistent_failure_is_completed_by_recovery(tmp_path, monkeypatch, sets, target):
    """A function that keeps failing from its first use after call k: the write reports it;
    the directory is the old set, or (past the commit point) becomes the new set on
    `recover` - never a mixture once recovered, and no leftovers."""
    old, new = sets
    seen = set()
    for k in range(1, 60):
        out = tmp_path / f"k{k}"
        atomic.write_set(out, old)
        with monkeypatch.context() as mp:
            _Inject(mp, k, _fail, only=target)
            try:
                write_outputs(out, new)
                raised = None
            except OSError as exc:       # OutputError
                raised = str(exc)
        atomic.recover(out)
        got = state(out, sets)
        if raised and "committed" not in raised:
            assert got == "old", (k, raised)
        elif raised:
            assert got == "new", (k, raised)
        seen.add((bool(raised), got))
    # os.replace is used only after the commit point; fsync before and after it.
    want = {"replace": {(True, "new"), (False, "new")},
            "fsync": {(True, "old"), (True, "new"), (False, "new")}}[target]
    assert seen == want, seen


def _run_child(out, files, k, sig, after=False):
    """Fork; the child writes `files` into `out` and sends itself `sig` at os call k (just
    before it, or with `after` just after it returns). Returns (wait status, calls made)."""
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:                                          # child
        os.close(r)
        try:
            # Python's own SIGINT handler, as in a terminal: a shell starts background jobs
            # with SIGINT ignored, which the writer rightly leaves alone.
            signal.signal(signal.SIGINT, signal.default_int_handler)
            count = [0]
            real = {n: getattr(os, n) for n in CALLS}
            real_kill, real_write = os.kill, os.write

            def wrap(name):
                def call(*a, **kw):
                    count[0] += 1
                    if count[0] == k and not after:
                        real_kill(os.getpid(), sig)
                    result = real[name](*a, **kw)
                    if count[0] == k and after:
                        real_kill(os.getpid(), sig)
                    return result
                return call
            for n in CALLS:
                setattr(os, n, wrap(n))
            code = 0
            try:
                write_outputs(out, files)
            except KeyboardInterrupt:
                code = 130
            for n in CALLS:
                setattr(os, n, real[n])
            real_write(w, str(count[0]).encode())
        except BaseException:                             # noqa: BLE001
            code = 3
        os._exit(code)
    os.close(w)
    _, status = os.waitpid(pid, 0)
    calls = os.read(r, 64)
    os.close(r)
    return status, int(calls) if calls else None


@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs fork")
@pytest.mark.parametrize("after", [False, True], ids=["before", "after"])
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT, signal.SIGKILL],
                         ids=["SIGTERM", "SIGINT", "SIGKILL"])
def test_signal_at_every_call(tmp_path, sets, sig, after):
    """SIGTERM/SIGINT just before or just after call k: the process dies by that signal (or
    KeyboardInterrupt) with the old set before the commit point and the new set after it, no
    leftovers, nothing to recover. (Just after the staging directory's mkdir is the window a
    timed kill of a real design once hit.) SIGKILL at call k: each file stays whole, and after
    `recover` the directory is one set with no leftovers."""
    old, new = sets
    seen = set()
    k = 0
    while True:
        k += 1
        out = tmp_path / f"k{k}"
        atomic.write_set(out, old)
        status, calls = _run_child(out, new, k, sig, after)
        if calls is not None and calls < k:               # finished before call k
            assert os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0
            assert state(out, sets) == "new"
            break
        if sig == signal.SIGKILL:
            assert os.WIFSIGNALED(status) and os.WTERMSIG(status) == sig
            _each_file_whole(out, sets)
            atomic.recover(out)
        elif sig == signal.SIGTERM:
            assert os.WIFSIGNALED(status) and os.WTERMSIG(status) == sig, (k, status)
        else:
            assert os.WIFEXITED(status) and os.WEXITSTATUS(status) == 130, (k, status)
        seen.add(state(out, sets))
        assert k < 200
    assert seen == {"old", "new"}, seen


def test_recovery_before_the_next_write(tmp_path, sets):
    """The next write completes a committed staging directory and drops an uncommitted one
    before it does its own work (what a SIGKILL leaves)."""
    old, new = sets
    out = tmp_path / "o"
    atomic.write_set(out, old)
    committed = out / (atomic.STAGING_PREFIX + "a")
    committed.mkdir()
    names = sorted(new)
    journal = atomic._journal_record(out, committed, {n: new[n].encode() for n in names})
    (committed / names[0]).write_text(new[names[0]])      # two of three already moved
    for n in names[1:]:
        (out / n).write_text(new[n])
    (committed / atomic.JOURNAL).write_bytes(journal)
    stale = out / (atomic.STAGING_PREFIX + "b")
    stale.mkdir()
    (stale / names[0]).write_bytes(b"half")
    got = atomic.read_set(out, names)
    assert got == {n: t.encode() for n, t in new.items()} and state(out, sets) == "new"


def test_write_outputs_uses_the_atomic_writer(tmp_path, monkeypatch, sets):
    old, new = sets
    seen = []
    monkeypatch.setattr(atomic, "write_set", lambda d, f, i=(): seen.append((d, f)) or [])
    write_outputs(tmp_path, new)
    assert seen == [(tmp_path, new)]


def test_target_that_is_a_directory_is_refused_before_writing(tmp_path, sets):
    old, new = sets
    out = tmp_path / "o"
    atomic.write_set(out, old)
    os.remove(out / "cart.json")
    (out / "cart.json").mkdir()
    with pytest.raises(atomic.OutputError, match="cart.json is a directory"):
        write_outputs(out, new)
    assert sorted(os.listdir(out)) == ["cart.c", "cart.h", "cart.json"]
    assert (out / "cart.h").read_text() == old["cart.h"]


def _cli(*args, **kw):
    return subprocess.Popen([sys.executable, "-m", "stospline.cli", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kw)


def test_cli_refuses_directory_target_with_one_line(tmp_path, sets):
    """One of the targets (``X/cart.json``) a directory: exit 2, one line, the old files
    untouched, no .tmp left."""
    old, _ = sets
    out = tmp_path / "X"
    atomic.write_set(out, old)
    os.remove(out / "cart.json")
    (out / "cart.json").mkdir()
    src = tmp_path / "cart.toml"
    src.write_text(CART.format(x0=0.5))
    p = _cli("design", str(src), "--out", str(out))
    stdout, stderr = p.communicate(timeout=300)
    assert p.returncode == 2 and stdout == ""
    assert stderr.count("\n") == 1 and stderr.startswith("stospline: error: --out: ")
    assert "cart.json is a directory" in stderr
    assert sorted(os.listdir(out)) == ["cart.c", "cart.h", "cart.json"]
    assert (out / "cart.h").read_text() == old["cart.h"]


def test_failed_write_removes_the_directories_it_created(tmp_path):
    """A name the file system refuses (253 characters and the suffix): one line, exit 2 and
    no output directory left behind (not created, or removed again)."""
    src = tmp_path / "long.toml"
    src.write_text(CART.format(x0=0.5).replace('name = "cart"', f'name = "{"n" * 253}"'))
    out = tmp_path / "new" / "sub"
    p = _cli("design", str(src), "--out", str(out))
    stdout, stderr = p.communicate(timeout=300)
    assert p.returncode == 2 and stdout == "" and stderr.count("\n") == 1, stderr
    assert "Traceback" not in stderr
    assert not (tmp_path / "new").exists()


@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs POSIX signals")
def test_random_kills_of_a_real_design(tmp_path, sets):
    """SIGTERM and SIGKILL at seeded random times over a real ``stospline design`` run
    (6 of each): after a SIGTERM the directory is one set with no leftovers; after a SIGKILL
    it is one set once recovered."""
    old, new = sets
    src = tmp_path / "cart.toml"
    src.write_text(CART.format(x0=0.5))
    out = tmp_path / "o"
    t = time.perf_counter()
    p = _cli("design", str(src), "--out", str(out))
    p.communicate(timeout=300)
    full = time.perf_counter() - t
    assert p.returncode == 0 and state(out, sets) == "new"
    rng = np.random.default_rng(20240610)
    seen = {signal.SIGTERM: [], signal.SIGKILL: []}
    for i, sig in enumerate([signal.SIGTERM, signal.SIGKILL] * 6):
        atomic.write_set(out, old)
        p = _cli("design", str(src), "--out", str(out))
        time.sleep(rng.uniform(0.6, 1.05) * full)
        p.send_signal(sig)
        p.communicate(timeout=300)
        if sig == signal.SIGKILL:
            _each_file_whole(out, sets)
            atomic.recover(out)
        seen[sig].append(state(out, sets))
    assert all(seen.values())
