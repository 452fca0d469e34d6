"""Where the firmware sources that `simulate` compiles come from.

In order: the directory named by ``STOSPLINE_FIRMWARE`` (a tree with ``src/*.c`` and
``include/stospline/*.h``, e.g. a modified copy); the copy an installed wheel carries as
package data (``stospline/_firmware``, found through `importlib.resources`); the repository's
``firmware/`` when the package runs from a source checkout (editable install), which keeps the
repository the single source of truth.
"""
from __future__ import annotations

import os
from importlib import resources
from pathlib import Path

from stospline.errors import StosplineError

__all__ = ["firmware_dir", "FirmwareNotFoundError", "ENV_VAR"]

ENV_VAR = "STOSPLINE_FIRMWARE"
_MARKER = Path("include") / "stospline" / "stsp_controller.h"


class FirmwareNotFoundError(StosplineError, FileNotFoundError):
    """No firmware source tree: the CLI reports it in one line, exit status 2."""


def _packaged() -> Path | None:
    root = resources.files("stospline") / "_firmware"
    # A wheel installs unzipped, so the Traversable is a real directory (cffi needs paths).
    if isinstance(root, Path) and (root / _MARKER).is_file():
        return root
    return None


def firmware_dir() -> Path:
    """The firmware tree to compile (see the module docstring for the order)."""
    env = os.environ.get(ENV_VAR)
    if env:
        path = Path(env)
        if not (path / _MARKER).is_file():
            raise FirmwareNotFoundError(f"{ENV_VAR}={env}: not a firmware tree (no {_MARKER})")
        return path
    packaged = _packaged()
    if packaged is not None:
        return packaged
    checkout = Path(__file__).resolve().parents[2] / "firmware"
    if (checkout / _MARKER).is_file():
        return checkout
    raise FirmwareNotFoundError(f"the firmware sources are missing from this installation "
                                f"(no stospline/_firmware); reinstall stospline, or set "
                                f"{ENV_VAR} to a firmware tree")
