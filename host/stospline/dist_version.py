"""The installed distribution's version, read without importing `importlib.metadata`.

Importing `importlib.metadata` (it loads email, zipfile, csv, ...) is a tenth of a design's
start-up. `installed_version` looks the metadata up as its path finder does for the common
case, a ``stospline-*.dist-info`` directory in a directory of ``sys.path`` (the first such
entry wins), and reads its ``Version:`` header. Anything else (eggs, zip entries, another
distribution finder on ``sys.meta_path``, two candidates in one directory, no ``Version:``
header) is left to `importlib.metadata` itself, so the answer is always the one it gives.
"""
from __future__ import annotations

import os
import re
import sys

__all__ = ["installed_version"]

_NAME = "stospline"


def installed_version() -> str | None:
    """``importlib.metadata.version("stospline")``, or None where it is not installed."""
    fast = _fast_lookup()
    if fast is not None:
        return fast
    from importlib.metadata import PackageNotFoundError, version
    try:
        return version(_NAME)
    except PackageNotFoundError:
        return None


def _normalize(name: str) -> str:
    """`importlib.metadata.Prepared.normalize`."""
    return re.sub(r"[-_.]+", "-", name).lower().replace("-", "_")


def _fast_lookup() -> str | None:
    """The version from the first directory of ``sys.path`` holding stospline's metadata, or
    None where the lookup is not the plain case described in the module docstring."""
    from importlib.machinery import PathFinder
    if any(getattr(f, "find_distributions", None) is not None and f is not PathFinder
           for f in sys.meta_path):
        return None
    for entry in sys.path:
        root = entry or "."
        if os.path.basename(root).lower().endswith(".egg"):
            return None
        try:
            children = os.listdir(root)
        except OSError:
            if os.path.exists(root):      # a zip archive, say: not the plain case
                return None
            continue
        found = []
        for child in children:
            low = child.lower()
            if low.endswith((".dist-info", ".egg-info")) and \
                    _normalize(low.rpartition(".")[0].partition("-")[0]) == _NAME:
                found.append(child)
            elif low.endswith(".egg") and low.replace("-", "_").startswith(_NAME):
                return None
        if not found:
            continue
        if len(found) > 1 or not found[0].lower().endswith(".dist-info"):
            return None
        return _version_header(os.path.join(root, found[0], "METADATA"))
    return None


def _version_header(path: str) -> str | None:
    """The ``Version:`` header of the metadata file at `path`, or None."""
    try:
        with open(path, encoding="utf-8") as fh:
            for line in fh:
                if not line.strip():       # the headers end at the first blank line
                    break
                key, sep, value = line.partition(":")
                if sep and key.strip().lower() == "version":
                    return value.strip() or None
    except (OSError, UnicodeDecodeError):
        pass
    return None
