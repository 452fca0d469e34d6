"""Progress bars on stderr for long designs and simulations (tqdm), off unless `enable`d.

The CLI enables them when stderr is a terminal and ``--quiet`` is not given; the library is
silent by default. A loop announces its size with `start` and reports with `advance`; a bar
appears only after `DELAY` seconds, so short runs print nothing. When disabled, `advance`
costs one function call.
"""
from __future__ import annotations

import sys
import threading
from contextlib import contextmanager

__all__ = ["enable", "enabled", "start", "advance", "finish", "close_all", "note", "shared",
           "DELAY"]

DELAY = 1.0           # seconds before a bar appears
_enabled = False
_bars: list = []      # open bars, innermost last
_shared: list = []    # [bar or None] while loops run concurrently under `shared`
_lock = threading.Lock()


def enable(on: bool = True) -> None:
    global _enabled
    _enabled = bool(on)


def enabled() -> bool:
    return _enabled


def start(label: str, total: int, unit: str = "tick"):
    """Open a bar of `total` units (a token for `finish`; None when disabled)."""
    if not _enabled or _shared:
        return None
    try:
        from tqdm import tqdm
    except ImportError:          # a declared dependency; without it, no bars (not an error)
        return None
    bar = tqdm(total=int(total), desc=label, unit=unit, file=sys.stderr, delay=DELAY,
               leave=False, mininterval=0.5, dynamic_ncols=True, unit_scale=True)
    _bars.append(bar)
    return bar


def advance(n: int = 1) -> None:
    """Count `n` units of the innermost open bar."""
    if _shared:
        with _lock:
            if _shared[0] is not None:
                _shared[0].update(n)
    elif _bars:
        _bars[-1].update(n)


def finish(bar) -> None:
    """Close `bar` (and any bar opened inside it and left open by an exception)."""
    if bar is None or bar not in _bars:
        return
    while _bars:
        top = _bars.pop()
        top.close()
        if top is bar:
            break


def close_all() -> None:
    while _bars:
        _bars.pop().close()


@contextmanager
def shared(label: str, total: int, unit: str = "tick"):
    """One bar for loops that run concurrently (in threads): inside, `start` opens no bar
    and every `advance` counts on this one."""
    bar = start(label, total, unit)
    _shared.append(bar)
    try:
        yield
    finally:
        _shared.clear()
        finish(bar)


def note(message: str) -> None:
    """One line on stderr when enabled (e.g. the run's estimate)."""
    if _enabled:
        print(f"stospline: {message}", file=sys.stderr, flush=True)
