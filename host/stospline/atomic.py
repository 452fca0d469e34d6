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
* Recovery only completes what a writer staged in this very directory: the journal records
  the output and staging directories' device and inode numbers, each staged file's size and
  SHA-256, and the file each one replaces (its inode, size and mtime, or that there was none).
  A committed staging directory that does not match all of it (copied from elsewhere, checked
  out of version control, edited, or a target changed since) is foreign: left alone, nothing
  published from it.
* A reader running *while* a writer publishes (a window of a few renames) can still open an
  old ``.h`` and a new ``.c``: a reader that must be sure calls `read_set`, which holds the
  same lock (and recovers first). Each generated file also names its design (the problem
  file's SHA-256; the table CRC in ``.c``/``.h``), so a mixture can be detected.

Directories created for the output (``--out a/b/c`` with none of them existing) are removed
again when the write fails. Pre-existing targets that are directories, an output path that is
a file, an unwritable directory (tried with an unnamed ``O_TMPFILE`` file, so root on a
read-only or pseudo file system is refused too), a name or path longer than the file system
takes, and a target that is one of the run's input files are refused before anything is
created.
"""
from __future__ import annotations

import errno
import fcntl
import hashlib
import json
import os
import shutil
import signal
import stat
import threading
from contextlib import contextmanager
from pathlib import Path

from stospline.errors import StosplineError

__all__ = ["OutputError", "Interrupted", "STAGING_PREFIX", "JOURNAL", "write_set",
           "recover", "read_set", "check_target", "check_file_target", "write_file"]

STAGING_PREFIX = ".stospline-staging-"
JOURNAL = "COMMIT"
JOURNAL_FORMAT = "stospline-commit-2"
# The longest staging directory name (`_staging_name`), for the length checks.
_STAGING_SAMPLE = f"{STAGING_PREFIX}{2 ** 22}-{'0' * 12}"
_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP")
                 if hasattr(signal, name))


class OutputError(StosplineError, OSError):
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


def check_target(out_dir: str | Path, names=(), inputs=()) -> None:
    """Refuse, without creating anything, an output directory that cannot receive `names`.

    Raises `OutputError` when `out_dir` exists but is not a directory, is not writable, or
    already holds one of `names` as a directory or as one of the `inputs` (files the run
    reads); when it does not exist and the nearest existing ancestor is not a writable
    directory; or when a name or the path is longer than the file system takes."""
    out = Path(out_dir)
    try:
        st = os.stat(out)
    except (FileNotFoundError, NotADirectoryError):    # missing, or below a file
        st = None
    except OSError as exc:
        if exc.errno != errno.ENAMETOOLONG:            # that one: the length check says which
            raise OutputError(f"{_short(out)}: {_why(exc)}") from None
        st = None
    for name in names:
        _check_name(name)
    if st is None:
        parent = _existing_ancestor(out)
        _check_lengths(out, parent, [*names, _STAGING_SAMPLE])
        if not stat.S_ISDIR(os.stat(parent).st_mode):
            raise OutputError(f"{parent} is not a directory, so {out} cannot be created")
        _check_writable(parent, f"cannot create {out}: {parent} is not writable")
        return
    if not stat.S_ISDIR(st.st_mode):
        raise OutputError(f"{out} exists and is not a directory")
    _check_lengths(out, out, [*names, _STAGING_SAMPLE])
    _check_writable(out, f"{out} is not writable")
    for name in names:
        if (out / name).is_dir():
            raise OutputError(f"{out / name} is a directory; it would be replaced by a file "
                              f"(remove or rename it)")
        _check_not_input(out / name, inputs)


def check_file_target(path: str | Path, inputs=()) -> None:
    """Refuse, creating nothing, a single output file (`write_file`) that cannot be written:
    its directory missing or unwritable, the path itself a directory or one of the `inputs`,
    or its name or path too long for the file system."""
    path = Path(path)
    parent = path.absolute().parent
    _check_lengths(path, _existing_ancestor(path), [])
    try:
        pst = os.stat(parent)
    except OSError as exc:
        raise OutputError(f"{_short(path)}: its directory {_short(parent)} cannot be used: "
                          f"{_why(exc)}") from None
    if not stat.S_ISDIR(pst.st_mode):
        raise OutputError(f"{_short(path)}: {_short(parent)} is not a directory")
    try:
        is_dir = stat.S_ISDIR(os.stat(path).st_mode)
    except OSError:
        is_dir = False
    if is_dir:
        raise OutputError(f"{path} is a directory")
    _check_writable(parent, f"{path}: its directory {parent} is not writable")
    _check_not_input(path, inputs)


def _short(path) -> str:
    """A path for a one-line message: an over-long one is cut in the middle."""
    text = str(path)
    return text if len(text) <= 120 else f"{text[:60]}...{text[-50:]}"


def _existing_ancestor(path: Path) -> Path:
    parent = path.absolute().parent
    while True:
        try:
            os.stat(parent)
            return parent
        except (FileNotFoundError, NotADirectoryError):
            parent = parent.parent
        except OSError as exc:
            if exc.errno != errno.ENAMETOOLONG:
                raise OutputError(f"{_short(parent)}: {_why(exc)}") from None
            parent = parent.parent


def _limit(directory: Path, name: str, default: int) -> int:
    try:
        return os.pathconf(directory, name)
    except (OSError, ValueError):
        return default


def _check_lengths(path: Path, existing: Path, names) -> None:
    """Every component of `path` (and of `path`/name for `names`) within the file system's
    NAME_MAX, and the whole within PATH_MAX (both asked of the existing directory)."""
    name_max = _limit(existing, "PC_NAME_MAX", 255)
    path_max = _limit(existing, "PC_PATH_MAX", 4096)
    full = path.absolute()
    for part in [*full.parts[1:], *names]:
        size = len(os.fsencode(part))
        if size > name_max:
            raise OutputError(f"the name {_short(part)!r} is {size} bytes, longer than the "
                              f"{name_max} the file system takes")
    longest = max((len(os.fsencode(n)) + 1 for n in names), default=0)
    size = len(os.fsencode(str(full))) + longest
    if size >= path_max:
        raise OutputError(f"the path {_short(full)} is {size} bytes, longer than the "
                          f"{path_max - 1} the system takes")


def _check_writable(directory: Path, message: str) -> None:
    """Refuse a directory where no file can be created. os.access answers yes for root even
    on a read-only or pseudo file system (/sys, /proc), so a file is tried: an unnamed one
    (O_TMPFILE, never visible), else, where the file system lacks O_TMPFILE, a hidden one that
    is removed at once."""
    if not os.access(directory, os.W_OK | os.X_OK):
        raise OutputError(message)
    try:
        try:
            fd = os.open(directory, os.O_TMPFILE | os.O_WRONLY | os.O_CLOEXEC, 0o600)
        except AttributeError:              # no O_TMPFILE on this platform
            raise OSError(errno.EOPNOTSUPP, "no O_TMPFILE") from None
        except OSError as exc:
            if exc.errno not in (errno.EOPNOTSUPP, errno.EISDIR, errno.EINVAL):
                raise
            probe = directory / f"{STAGING_PREFIX}probe-{os.getpid()}-{os.urandom(4).hex()}"
            fd = os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o600)
            os.unlink(probe)
        os.close(fd)
    except OSError as exc:
        raise OutputError(f"{message} ({_why(exc)})") from None


def _check_not_input(target: Path, inputs) -> None:
    """Refuse a target that is one of the run's input files (the same inode: the same name,
    a hard link, or a name an input symlink resolves to)."""
    try:
        tst = os.lstat(target)
    except OSError:
        return
    for source in inputs:
        try:
            ist = os.stat(source)
        except OSError:
            continue
        if (tst.st_dev, tst.st_ino) == (ist.st_dev, ist.st_ino):
            raise OutputError(f"{_short(target)} is the input file {_short(source)}; writing "
                              f"would replace it (choose another output)")


def _check_name(name: str) -> None:
    if not _plain(name):
        raise OutputError(f"{name!r} is not a plain file name")


def _plain(name) -> bool:
    return (isinstance(name, str) and bool(name) and name not in (".", "..") and "/" not in name
            and "\0" not in name and not name.startswith(STAGING_PREFIX))


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


def _identity(st: os.stat_result) -> list[int]:
    return [st.st_dev, st.st_ino]


def _file_state(path: Path) -> list[int] | None:
    """What the journal records of a target a staged file replaces (None: it did not exist)."""
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return None
    return [st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns]


def _journal_record(out: Path, stage: Path, blobs: dict[str, bytes]) -> bytes:
    """The journal of a staging directory: what recovery checks before publishing from it
    (`_verified_names`)."""
    files = [{"name": name, "size": len(blob), "sha256": hashlib.sha256(blob).hexdigest(),
              "replaces": _file_state(out / name)} for name, blob in blobs.items()]
    return json.dumps({"format": JOURNAL_FORMAT, "out": _identity(os.stat(out)),
                       "stage": _identity(os.lstat(stage)), "files": files}).encode()


def _journal(stage: Path):
    """The parsed journal of a staging directory; None if it is not committed."""
    try:
        return json.loads((stage / JOURNAL).read_text())
    except FileNotFoundError:
        return None
    except (OSError, ValueError):
        return {}                    # committed but unreadable: not verifiable, so foreign


def _sha256_of(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


def _verified_names(out: Path, stage: Path, record, protect=()) -> list[str] | None:
    """The names to publish from a committed staging directory, or None when it is not one
    this module staged in `out` (module docstring): recovery then leaves it alone."""
    if not isinstance(record, dict) or record.get("format") != JOURNAL_FORMAT:
        return None
    files = record.get("files")
    if (record.get("out") != _identity(os.stat(out))
            or record.get("stage") != _identity(os.lstat(stage))
            or not isinstance(files, list)
            or not all(isinstance(f, dict) and _plain(f.get("name")) for f in files)):
        return None
    names = [f["name"] for f in files]
    if set(os.listdir(stage)) - set(names) - {JOURNAL} or len(set(names)) != len(names):
        return None                  # something this writer did not stage
    protected = {(st.st_dev, st.st_ino) for st in map(_stat_or_none, protect) if st}
    for f in files:
        staged, target = stage / f["name"], out / f["name"]
        if not os.path.lexists(staged):
            continue                 # published before the writer died
        st = os.lstat(staged)
        if (not stat.S_ISREG(st.st_mode) or st.st_size != f.get("size")
                or _sha256_of(staged) != f.get("sha256")
                or _file_state(target) != f.get("replaces")):
            return None              # not what was staged, or the target changed since
        tst = _stat_or_none(target)
        if tst is not None and (tst.st_dev, tst.st_ino) in protected:
            return None              # it would replace an input of this run
    return names


def _stat_or_none(path) -> os.stat_result | None:
    try:
        return os.stat(path)
    except OSError:
        return None


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


def _recover_locked(out: Path, protect=()) -> None:
    for stage in sorted(out.glob(STAGING_PREFIX + "*")):
        if not stage.is_dir() or stage.is_symlink():
            continue
        record = _journal(stage)
        if record is None:
            shutil.rmtree(stage)
            _fsync_dir(out)
            continue
        names = _verified_names(out, stage, record, protect)
        if names is not None:
            _publish(out, stage, names)


def recover(out_dir: str | Path) -> None:
    """Finish or undo what a killed writer left in `out_dir` (nothing if it does not exist):
    a committed staging directory is published, an uncommitted one deleted; a committed one
    that this module did not stage there (module docstring) is left alone."""
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


def write_set(out_dir: str | Path, files: dict[str, str | bytes], inputs=()) -> list[Path]:
    """Write `files` (name -> text or bytes) into `out_dir` as one set: all or none (see the
    module docstring for the exact guarantee). Creates `out_dir` and its parents if needed.
    A target that is one of `inputs` (the files the run read) is refused, and recovery never
    publishes over one.

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
    check_target(out, names, inputs)
    blobs = {n: t.encode() if isinstance(t, str) else bytes(t) for n, t in files.items()}
    with _SignalGuard() as guard:
        created: list[Path] = []
        state = {"committed": False}
        try:
            created = _make_dirs(out)
            with _locked(out):
                _recover_locked(out, inputs)
                check_target(out, names, inputs)        # again, under the lock
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
        _write_synced(stage / (JOURNAL + ".tmp"), _journal_record(out, stage, blobs))
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
    return out / f"{STAGING_PREFIX}{os.getpid()}-{os.urandom(6).hex()}"


def write_file(path: str | Path, writer, inputs=()) -> Path:
    """Write one file atomically: ``writer(tmp_path)`` creates a temporary file next to
    `path` (same suffix, so a format guessed from it is right); it is fsynced and renamed
    over `path`, or removed on any error or signal (temporary files of a killed earlier write
    of the same `path` are removed first). The parent directory must exist; `path` must not be
    one of `inputs`."""
    path = Path(path)
    parent = path.absolute().parent
    check_file_target(path, inputs)
    # Named by a hash of the name, so a name near NAME_MAX still has a temporary name.
    tag = hashlib.sha256(os.fsencode(path.name)).hexdigest()[:12]
    prefix = f"{STAGING_PREFIX}{tag}."
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
