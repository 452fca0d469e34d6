"""All-or-nothing output sets: the files of one ``stospline design`` appear together or not at all.

POSIX renames one name at a time, so several files at fixed names (``gains/<name>.c``, ``.h``,
``.json``, which builds include directly) cannot switch in one system call. `write_set` makes
the switch a transaction with a redo journal instead:

1. Lock the output directory (``flock`` on the directory itself: concurrent writers queue,
   and the lock dies with its process, even on SIGKILL) and `recover` what an earlier,
   killed writer left (below).
2. Stage: write every file into a fresh ``.stospline-staging-*`` directory inside the output
   directory (the same file system, so a rename moves it), fsync each file and the staging
   directory.
3. Commit point: write the journal ``COMMIT`` (the list of names) into the staging directory
   under a temporary name, fsync it, rename it to ``COMMIT``, fsync the staging directory.
   Before this point the old set is the outcome; after it, the new set.
4. Publish: rename the staged files over their targets one after the other, fsync the output
   directory, delete the journal and the staging directory, fsync again.

Signals: from the start, SIGINT, SIGTERM and SIGHUP (those not ignored) abort the write, the
staging directory is removed, and the signal is then re-delivered with the disposition it had
(so a SIGTERM still terminates the process, a SIGINT raises KeyboardInterrupt). From the commit
point to the end of the clean-up they are deferred: the publication completes, then the signal
is delivered. Only in the main thread (Python runs signal handlers there); elsewhere signals
keep their dispositions. An exception during staging removes the staging directory; one
during publication is retried once, from the journal.

Guarantee, precisely:

* Every file at its final name is always complete: either the old file or the new one (it
  is only ever replaced by rename(2) of a complete, fsynced file).
* When `write_set` returns, raises, or the process ends by a signal it can catch (at any
  instant), the directory holds the complete old set or the complete new set, and no
  staging directory (with one exception: a rename(2) that keeps failing after the commit
  point; the error then says so and the next write completes the set).
* SIGKILL, a crash or a power loss: before the commit point the directory keeps the old set
  (plus an uncommitted staging directory); after it, it may hold a mixture of old and new
  files plus the committed staging directory. The next `write_set` into the directory, or
  `recover`, completes the committed set and deletes uncommitted staging directories, before
  anything else. So once recovered, a reader finds the old or the new set, never a mixture.
* A reader running *while* a writer publishes (a window of a few renames) can still open an
  old ``.h`` and a new ``.c``: a reader that must be sure calls `read_set`, which holds the
  same lock (and recovers first). Each generated file also names its design (the problem
  file's SHA-256; the table CRC in ``.c``/``.h``), so a mixture can be detected.

Directories created for the output (``--out a/b/c`` with none of them existing) are removed
again when the write fails. Pre-existing targets that are directories, an output path that is
a file, or an unwritable directory are refused before anything is created.
"""
from __future__ import annotations

import errno
import fcntl
import json
import os
import secrets
import shutil
import signal
import stat
import threading
from contextlib import contextmanager
from pathlib import Path

__all__ = ["OutputError", "Interrupted", "STAGING_PREFIX", "JOURNAL", "write_set",
           "recover", "read_set", "check_target", "check_file_target", "write_file"]

STAGING_PREFIX = ".stospline-staging-"
JOURNAL = "COMMIT"
_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP")
                 if hasattr(signal, name))


class OutputError(OSError):
    """An output cannot be written (the CLI reports it on ``--out``). ``reason`` says why;
    nothing was created or changed unless the message says otherwise."""

    def __init__(self, reason: str):
        super().__init__(reason)
        self.reason = reason

    def __str__(self) -> str:
        return self.reason


class Interrupted(BaseException):
    """A signal aborted a write before its commit point (nothing was changed). The signal is
    re-delivered after the clean-up; this is raised only if its handler returns."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum

    def __str__(self) -> str:
        return f"interrupted by {signal.Signals(self.signum).name}"


# --------------------------------------------------------------------------------------------
# Checks that create nothing.

def _why(exc: OSError) -> str:
    return exc.strerror or str(exc)


def check_target(out_dir: str | Path, names=()) -> None:
    """Refuse, without creating anything, an output directory that cannot receive `names`.

    Raises `OutputError` when `out_dir` exists but is not a directory, is not writable, or
    already holds one of `names` as a directory; or when it does not exist and the nearest
    existing ancestor is not a writable directory."""
    out = Path(out_dir)
    try:
        st = os.stat(out)
    except (FileNotFoundError, NotADirectoryError):    # missing, or below a file
        st = None
    except OSError as exc:
        raise OutputError(f"{out}: {_why(exc)}") from None
    if st is None:
        parent = out.absolute().parent
        while True:
            try:
                pst = os.stat(parent)
                break
            except (FileNotFoundError, NotADirectoryError):
                parent = parent.parent
            except OSError as exc:
                raise OutputError(f"{parent}: {_why(exc)}") from None
        if not stat.S_ISDIR(pst.st_mode):
            raise OutputError(f"{parent} is not a directory, so {out} cannot be created")
        if not os.access(parent, os.W_OK | os.X_OK):
            raise OutputError(f"cannot create {out}: {parent} is not writable")
        return
    if not stat.S_ISDIR(st.st_mode):
        raise OutputError(f"{out} exists and is not a directory")
    if not os.access(out, os.W_OK | os.X_OK):
        raise OutputError(f"{out} is not writable")
    for name in names:
        _check_name(name)
        if (out / name).is_dir():
            raise OutputError(f"{out / name} is a directory; it would be replaced by a file "
                              f"(remove or rename it)")


def check_file_target(path: str | Path) -> None:
    """Refuse, creating nothing, a single output file (`write_file`) that cannot be written:
    its directory missing or unwritable, or the path itself a directory."""
    path = Path(path)
    parent = path.absolute().parent
    try:
        pst = os.stat(parent)
    except OSError as exc:
        raise OutputError(f"{path}: its directory {parent} cannot be used: {_why(exc)}") from None
    if not stat.S_ISDIR(pst.st_mode):
        raise OutputError(f"{path}: {parent} is not a directory")
    if path.is_dir():
        raise OutputError(f"{path} is a directory")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputError(f"{path}: its directory {parent} is not writable")


def _check_name(name: str) -> None:
    if (not name or name in (".", "..") or "/" in name or "\0" in name
            or name.startswith(STAGING_PREFIX)):
        raise OutputError(f"{name!r} is not a plain file name")


# --------------------------------------------------------------------------------------------
# Signals: abort before the commit point, defer after it.

class _SignalGuard:
    def __init__(self):
        self.deferring = False
        self.pending: int | None = None
        self._saved: dict[int, object] = {}

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            for sig in _SIGNALS:
                old = signal.getsignal(sig)
                if old is signal.SIG_IGN or old is None:
                    continue     # ignored (e.g. nohup) or not installed from Python: keep it
                self._saved[sig] = old
                signal.signal(sig, self._handle)
        return self

    def _handle(self, signum, frame):
        if self.pending is None:
            self.pending = signum
        if not self.deferring:
            self.deferring = True        # one abort; later signals wait for the clean-up
            raise Interrupted(signum)

    def defer(self) -> None:
        self.deferring = True

    def __exit__(self, exc_type, exc, tb):
        for sig, old in self._saved.items():
            signal.signal(sig, old)
        if self.pending is not None:
            signal.raise_signal(self.pending)   # its own disposition, now the work is done
        return False


# --------------------------------------------------------------------------------------------
# File-system steps.

def _fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _write_synced(path: Path, data: bytes, mode: int = 0o644) -> None:
    """Create `path` (it must not exist), write all of `data`, fsync, close."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, mode)
    try:
        os.fchmod(fd, mode)          # not narrowed by the umask: the files are for everyone
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view):]
        os.fsync(fd)
    finally:
        os.close(fd)


def _make_dirs(out: Path) -> list[Path]:
    """``mkdir -p out``; the directories it created, outermost first."""
    missing = []
    p = out.absolute()
    while not p.exists():
        missing.append(p)
        p = p.parent
    created = []
    for d in reversed(missing):
        try:
            os.mkdir(d)
        except FileExistsError:
            if not d.is_dir():
                raise
            continue
        created.append(d)
        _fsync_dir(d.parent)
    return created


def _remove_created(created: list[Path]) -> None:
    for d in reversed(created):
        try:
            os.rmdir(d)              # only if still empty: never removes anyone's files
            _fsync_dir(d.parent)
        except OSError:
            break


@contextmanager
def _locked(out: Path):
    fd = os.open(out, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)                 # releases the lock


def _journal(stage: Path) -> list[str] | None:
    """The names a committed staging directory publishes; None if it is not committed."""
    try:
        names = json.loads((stage / JOURNAL).read_text())
    except (FileNotFoundError, ValueError):
        return None
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        return None
    return names


def _publish(out: Path, stage: Path, names: list[str]) -> None:
    """Roll a committed staging directory forward: rename what is still staged, then remove
    the journal and the directory. Idempotent (what was renamed already is skipped)."""
    for name in names:
        _check_name(name)
        src = stage / name
        if os.path.lexists(src):
            os.replace(src, out / name)
    _fsync_dir(out)
    (stage / JOURNAL).unlink(missing_ok=True)  # after every rename: the set is complete
    if stage.exists():
        shutil.rmtree(stage)
    _fsync_dir(out)


def _recover_locked(out: Path) -> None:
    for stage in sorted(out.glob(STAGING_PREFIX + "*")):
        if not stage.is_dir() or stage.is_symlink():
            continue
        names = _journal(stage)
        if names is not None:
            _publish(out, stage, names)
        else:
            shutil.rmtree(stage)
            _fsync_dir(out)


def recover(out_dir: str | Path) -> None:
    """Finish or undo what a killed writer left in `out_dir` (nothing if it does not exist):
    a committed staging directory is published, an uncommitted one deleted."""
    out = Path(out_dir)
    if not out.is_dir():
        return
    with _locked(out):
        _recover_locked(out)


def read_set(out_dir: str | Path, names) -> dict[str, bytes]:
    """Read `names` from `out_dir` as one consistent set: under the writers' lock, after
    `recover`. Missing files raise FileNotFoundError."""
    out = Path(out_dir)
    with _locked(out):
        _recover_locked(out)
        return {name: (out / name).read_bytes() for name in names}


def write_set(out_dir: str | Path, files: dict[str, str | bytes]) -> list[Path]:
    """Write `files` (name -> text or bytes) into `out_dir` as one set: all or none (see the
    module docstring for the exact guarantee). Creates `out_dir` and its parents if needed.

    Returns
    -------
    list of Path
        The written files, in the order of `files`.

    Raises
    ------
    OutputError
        The directory cannot take the files (checked before anything is created), or a write
        failed (the old set is then unchanged and every created directory removed).
    Interrupted
        SIGINT/SIGTERM/SIGHUP arrived before the commit point and its re-delivered handler
        returned (the default handlers terminate the process or raise KeyboardInterrupt).
    """
    out = Path(out_dir)
    names = list(files)
    for name in names:
        _check_name(name)
    check_target(out, names)
    blobs = {n: t.encode() if isinstance(t, str) else bytes(t) for n, t in files.items()}
    with _SignalGuard() as guard:
        created: list[Path] = []
        state = {"committed": False}
        try:
            created = _make_dirs(out)
            with _locked(out):
                _recover_locked(out)
                check_target(out, names)        # again, under the lock
                _transaction(out, blobs, guard, state)
        except BaseException as exc:
            guard.defer()                       # the clean-up must not be interrupted
            if not state["committed"]:
                _remove_created(created)
            if isinstance(exc, OSError) and not isinstance(exc, OutputError):
                if state["committed"]:
                    raise OutputError(f"the new files are committed but not all in place "
                                      f"({_why(exc)}); the next write into {out} or "
                                      f"stospline.atomic.recover completes them") from None
                raise OutputError(f"cannot write into {out}: {_why(exc)}; nothing was "
                                  f"changed") from None
            raise
    return [out / name for name in names]


def _transaction(out: Path, blobs: dict[str, bytes], guard: _SignalGuard, state: dict) -> None:
    """Stage, commit and publish `blobs` in `out` (locked by the caller)."""
    # The name is chosen before the directory exists, so a signal just after the mkdir (the
    # handler raises there) still finds the directory to remove; mkdtemp would lose it.
    stage = _staging_name(out)
    try:
        os.mkdir(stage, 0o700)
        for name, blob in blobs.items():
            _write_synced(stage / name, blob)
        _fsync_dir(stage)
        _write_synced(stage / (JOURNAL + ".tmp"), json.dumps(list(blobs)).encode())
        guard.defer()                           # the commit point and everything after it
        os.rename(stage / (JOURNAL + ".tmp"), stage / JOURNAL)
        state["committed"] = True
    except BaseException:
        guard.defer()
        shutil.rmtree(stage, ignore_errors=True)
        raise
    try:
        _fsync_dir(stage)
        _publish(out, stage, list(blobs))
    except OSError:
        _publish(out, stage, list(blobs))       # once more, from the journal


def _staging_name(out: Path) -> Path:
    """A fresh staging directory's path (not created). The lock serialises writers of `out`
    and recovery removes every earlier staging directory, so a random suffix cannot clash."""
    return out / f"{STAGING_PREFIX}{os.getpid()}-{secrets.token_hex(6)}"


def write_file(path: str | Path, writer) -> Path:
    """Write one file atomically: ``writer(tmp_path)`` creates a temporary file next to
    `path` (same suffix, so a format guessed from it is right); it is fsynced and renamed
    over `path`, or removed on any error or signal (temporary files of a killed earlier write
    of the same `path` are removed first). The parent directory must exist."""
    path = Path(path)
    parent = path.absolute().parent
    check_file_target(path)
    prefix = f"{STAGING_PREFIX}{path.name}."
    with _SignalGuard() as guard, _locked(parent):
        for stale in parent.glob(glob_escape(prefix) + "*"):
            stale.unlink(missing_ok=True)
        tmp = parent / f"{prefix}{os.getpid()}{path.suffix}"
        try:
            writer(tmp)
            fd = os.open(tmp, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
            guard.defer()
            os.replace(tmp, path)
            _fsync_dir(parent)
        except BaseException as exc:
            guard.defer()
            try:
                os.unlink(tmp)
            except OSError:
                pass
            if isinstance(exc, OSError) and not isinstance(exc, OutputError):
                raise OutputError(f"cannot write {path}: {_why(exc)}") from None
            raise
    return path


def glob_escape(text: str) -> str:
    """`text` with glob metacharacters escaped (a file name used as a glob prefix)."""
    import glob
    return glob.escape(text)
