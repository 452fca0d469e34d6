"""What Python shares with the firmware's public header, in one place: the arithmetics, the
table's magic, format version and scalar kinds, and the status codes. `check_header` compares
them with the header the firmware is compiled from, every time the harness compiles it
(`stospline.harness.controller.build_controller`), so a header change that Python does not follow
stops the build naming the difference instead of running with stale numbers. (Struct layouts
need no copy: the harness compiles against the header itself, in cffi's API mode.)"""
from __future__ import annotations

import re
from pathlib import Path

from stospline.errors import StosplineError

__all__ = ["ARITHS", "FIXED_POINT", "FRAC_BITS", "SCALAR_KIND", "ELEMENT_BYTES", "MAGIC",
           "FORMAT_VERSION", "STATUS", "header_facts", "check_header", "InterfaceMismatch"]

ARITHS = ("float32", "q15", "q31")             # STSP_ARITH: the firmware's variants
FIXED_POINT = ("q15", "q31")
FRAC_BITS = {"q15": 15, "q31": 31}             # STSP_Q_FRAC_BITS
SCALAR_KIND = {"float32": 1, "q15": 2, "q31": 3}   # STSP_SCALAR_FLOAT32/_Q15/_Q31
ELEMENT_BYTES = {"float32": 4, "q15": 2, "q31": 4}  # bytes of one table entry
MAGIC = 0x53545350                             # STSP_TABLE_MAGIC, "STSP"
FORMAT_VERSION = 5                             # STSP_FORMAT_VERSION

STATUS = {                                     # stsp_status_t, without the STSP_ prefix
    "OK": 0, "WARN_TICK_SKIPPED": 1, "WARN_TICK_REPEATED": 2, "ERR_NULL": -1,
    "ERR_NOT_INITIALIZED": -2, "ERR_BAD_MAGIC": -3, "ERR_BAD_VERSION": -4, "ERR_BAD_DIMS": -5,
    "ERR_BAD_CRC": -6, "ERR_TICK_RANGE": -7, "ERR_TICK_ORDER": -8,
    "WARN_SATURATED": 3, "ERR_NONFINITE_STATE": -9, "ERR_NONFINITE_OUTPUT": -10,
    "ERR_BAD_VALUES": -11, "WARN_STATE_CLAMPED": 4, "WARN_BAND_FALLBACK": 5,
    "ERR_BAD_PROBLEM": -12, "ERR_TABLE_CHANGED": -13, "WARN_NO_MEASUREMENT": 6,
    "ERR_NONFINITE_MEASUREMENT": -14, "ERR_PARAM_RANGE": -15,
}

_DEFINE = re.compile(r"^\s*#\s*define\s+(STSP_\w+)\s+(0x[0-9A-Fa-f]+|\d+)u?\b", re.MULTILINE)
_ENUM = re.compile(r"typedef enum\s*{(.*?)}\s*stsp_status_t;", re.S)


class InterfaceMismatch(StosplineError, RuntimeError):
    """The firmware header and the package disagree on a shared constant."""


def header_facts(include_dir: str | Path) -> dict:
    """``{"macros": {name: value}, "status": {name: value}}`` from the public headers in
    `include_dir` (first definition of each macro wins: the default variant's)."""
    macros: dict[str, int] = {}
    status: dict[str, int] = {}
    for header in sorted(Path(include_dir).glob("stospline/*.h")):
        text = header.read_text()
        for name, value in _DEFINE.findall(text):
            macros.setdefault(name, int(value, 0))
        enum = _ENUM.search(text)
        if enum:
            body = re.sub(r"/\*.*?\*/", "", enum.group(1), flags=re.S)
            status.update((n, int(v)) for n, v in re.findall(r"STSP_(\w+)\s*=\s*(-?\d+)", body))
    return {"macros": macros, "status": status}


def check_header(include_dir: str | Path) -> None:
    """Raise InterfaceMismatch unless the header in `include_dir` has this module's values."""
    facts = header_facts(include_dir)
    m = facts["macros"]
    expected = {"STSP_TABLE_MAGIC": MAGIC, "STSP_FORMAT_VERSION": FORMAT_VERSION,
                **{f"STSP_SCALAR_{a.upper()}": k for a, k in SCALAR_KIND.items()}}
    diffs = [f"{name}: header {m.get(name)}, package {value}"
             for name, value in expected.items() if m.get(name) != value]
    if facts["status"] != STATUS:
        diffs.append(f"stsp_status_t: header {facts['status']}, package {STATUS}")
    if diffs:
        raise InterfaceMismatch(f"the firmware header in {include_dir} does not match the "
                                f"package: " + "; ".join(diffs))
