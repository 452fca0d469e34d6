"""Bounded reading of a problem file: what `problem.load_problem` decodes, and nothing larger.

A hostile or mistaken FILE (a directory, ``/dev/zero``, a FIFO, a symlink loop, gigabytes,
arrays nested a thousand deep) gets one `ProblemError` on field ``<file>`` (or on the key
holding the too-deep value), never a traceback, a hang or a huge allocation:

* only regular files (symlinks to them are followed), checked on the open descriptor, so a
  FIFO is never waited on and a device never read;
* at most `MAX_BYTES` are read (one byte more tells that the file is too large);
* UTF-8 text, valid TOML;
* arrays and tables nested at most `MAX_DEPTH` deep, checked on the decoded document without
  recursion (tomllib itself recurses: its RecursionError is caught as a last resort).
"""
from __future__ import annotations

import errno
import os
import stat
import tomllib
from pathlib import Path

from stospline.errors import ProblemError

__all__ = ["MAX_BYTES", "MAX_DEPTH", "ProblemFileNotFound", "read_problem_file",
           "decode_problem", "check_depth"]

MAX_BYTES = 16 * 1024 * 1024   # 16 MiB: the robot example is 2 KiB
MAX_DEPTH = 32                 # the deepest valid value (time-varying noise G) is 6 deep


class ProblemFileNotFound(ProblemError, FileNotFoundError):
    """The problem file does not exist (a `ProblemError` on ``<file>`` and a
    FileNotFoundError, so callers catching either see it)."""


_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
          (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
          (stat.S_ISSOCK, "a socket"))


def _kind(mode: int) -> str:
    return next((name for test, name in _KINDS if test(mode)), "not a regular file")


def _open_error(exc: OSError) -> ProblemError:
    if exc.errno == errno.ENOENT:
        return ProblemFileNotFound("<file>", "cannot read: no such file")
    reasons = {errno.ELOOP: "a symbolic link loop (too many levels of symbolic links)",
               errno.EACCES: "permission denied", errno.ENOTDIR: "a path component is not "
               "a directory", errno.ENAMETOOLONG: "the file name is too long",
               errno.EISDIR: "a directory, not a problem file"}
    return ProblemError("<file>", f"cannot read: {reasons.get(exc.errno, exc.strerror)}")


def read_problem_file(path: str | Path) -> bytes:
    """The bytes of the problem file at `path`, read with the bounds of this module.

    Raises
    ------
    ProblemError
        On ``<file>``: missing (`ProblemFileNotFound`), unreadable, not a regular file, or
        larger than `MAX_BYTES`.
    """
    try:
        # O_NONBLOCK: opening a FIFO must not wait for a writer (it is refused just below);
        # it has no effect on the regular file we then read.
        fd = os.open(os.fspath(path), os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        raise _open_error(exc) from None
    except ValueError as exc:                       # an embedded NUL byte
        raise ProblemError("<file>", f"cannot read: {exc}") from None
    try:
        st = os.fstat(fd)        # of what was opened: no race between a check and the read
        if not stat.S_ISREG(st.st_mode):
            raise ProblemError("<file>", f"is {_kind(st.st_mode)}, not a problem file "
                                         f"(a regular TOML file)")
        if st.st_size > MAX_BYTES:
            raise ProblemError("<file>", f"is {st.st_size} bytes; a problem file may have at "
                                         f"most {MAX_BYTES} bytes (16 MiB)")
        chunks, size = [], 0
        while size <= MAX_BYTES:                    # the file may grow while we read it
            chunk = os.read(fd, min(1 << 20, MAX_BYTES + 1 - size))
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
        if size > MAX_BYTES:
            raise ProblemError("<file>", f"has more than {MAX_BYTES} bytes; a problem file "
                                         f"may have at most {MAX_BYTES} bytes (16 MiB)")
        return b"".join(chunks)
    except OSError as exc:
        raise ProblemError("<file>", f"cannot read: {exc.strerror}") from None
    finally:
        os.close(fd)


def decode_problem(data: bytes) -> dict:
    """Decode UTF-8 TOML into a document whose values are nested at most `MAX_DEPTH` deep.

    Raises
    ------
    ProblemError
        ``<file>`` for bad UTF-8 or TOML, or nesting too deep for tomllib; the top-level key
        of a value nested deeper than `MAX_DEPTH`.
    """
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ProblemError("<file>", f"not valid TOML: not UTF-8 text ({exc})") from None
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ProblemError("<file>", f"not valid TOML: {exc}") from None
    except RecursionError:
        raise ProblemError("<file>", f"arrays or tables are nested too deeply to decode "
                                     f"(at most {MAX_DEPTH} levels)") from None
    except (OverflowError, MemoryError) as exc:
        raise ProblemError("<file>", f"not valid TOML: a value is too large "
                                     f"({type(exc).__name__})") from None
    check_depth(doc)
    return doc


def check_depth(doc: dict, limit: int = MAX_DEPTH) -> None:
    """Raise `ProblemError` (field: the top-level key) if some array or table inside `doc`
    is nested more than `limit` levels deep. Iterative: depth costs no stack."""
    stack = [(value, 1, key) for key, value in doc.items()]
    while stack:
        value, depth, top = stack.pop()
        if isinstance(value, dict):
            children = value.values()
        elif isinstance(value, list):
            children = value
        else:
            continue
        if depth > limit:
            raise ProblemError(top, f"arrays or tables are nested more than {limit} levels "
                                    f"deep (at most {limit})")
        stack.extend((child, depth + 1, top) for child in children)
