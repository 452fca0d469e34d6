"""The problem `name` as a C prefix: refuse names whose generated identifiers, macros or files
would collide with the firmware's, the harness's, the C library's or each other.

`codegen.generate_c` writes ``<name>.h``/``<name>.c`` defining ``<name>_table``,
``<name>_K``, ``<name>_stage_start``, ... and the macros ``<NAME>_NX``, ``<NAME>_GAINS_H``,
``<NAME>_PROBLEM_SHA256``, ...; fixed-point tables use the prefix ``<name>_q15``/``<name>_q31``.
Every generated identifier is the prefix, an underscore and one of a fixed set of suffixes, none
of which the C library uses; so the collisions to refuse are the namespaces that prefix-wise
contain the generated names, and the file names.
"""
from __future__ import annotations

import re

from stospline.firmware_interface import FIXED_POINT

__all__ = ["MAX_NAME_LENGTH", "RESERVED_PREFIXES", "check_name"]

# The longest generated macro, <NAME>_Q31_PROBLEM_SHA256, then has 60 characters: within the
# 63 significant characters C99 guarantees for macros and internal identifiers, and the file
# names (<name>_q31.json) and the harness's module name stay far below 255 bytes.
MAX_NAME_LENGTH = 40

# Prefix (case-insensitive; the macros are upper-cased) -> who owns the namespace.
RESERVED_PREFIXES = {
    "stsp": "the firmware's identifiers and macros (stsp_*, STSP_MAX_NX, STSP_FIXED_NX, ...)",
    "harness": "the Monte Carlo harness's C functions (harness_table, harness_step_batch, ...)",
}

_VARIANT_SUFFIX = re.compile(rf"_({'|'.join(FIXED_POINT)})$", re.IGNORECASE)

# <name>.h would shadow <name.h> for every build that puts the output directory on the include
# path (this repository's CMake does, and so does the harness): the C11/C23 headers, the POSIX
# and glibc headers they pull in, and Python.h of the cffi harness.
_HEADERS = frozenset(
    "assert complex ctype errno fenv float inttypes iso646 limits locale math setjmp signal "
    "stdalign stdarg stdatomic stdbit stdbool stdckdint stddef stdint stdio stdlib stdnoreturn "
    "string tgmath threads time uchar wchar wctype "
    "alloca endian features fcntl malloc memory pthread sched strings unistd "
    "python pyconfig".split())
# File names Windows refuses whatever the extension.
_DEVICES = frozenset(["con", "prn", "aux", "nul"] + [f"com{i}" for i in range(1, 10)]
                     + [f"lpt{i}" for i in range(1, 10)])


def check_name(name: str) -> None:
    """Raise ProblemError (field ``name``) unless `name` (already a C identifier that is not a
    keyword) is a safe prefix for the generated code and file names."""
    from stospline.errors import ProblemError

    def refuse(reason: str):
        raise ProblemError("name", f"{name[:48]!r}{'...' if len(name) > 48 else ''}: {reason}")

    if len(name) > MAX_NAME_LENGTH:
        refuse(f"has {len(name)} characters, at most {MAX_NAME_LENGTH} are allowed (it prefixes "
               f"every generated C identifier and file name)")
    if name.startswith("_") or "__" in name or name.endswith("_"):
        refuse("must not start or end with an underscore nor contain two in a row: C reserves "
               "file-scope identifiers starting with _, C++ those containing __, and the "
               "generated <name>_table would contain one")
    low = name.lower()
    for prefix, owner in RESERVED_PREFIXES.items():
        if low == prefix or low.startswith(prefix + "_"):
            refuse(f"the generated {name}_table and {name.upper()}_NX would fall in the "
                   f"{prefix}_ / {prefix.upper()}_ namespace of {owner}; choose another name")
    m = _VARIANT_SUFFIX.search(name)
    if m:
        refuse(f"ends in {m.group(0)}, the suffix of the fixed-point tables of a design named "
               f"{name[:m.start()]!r}: their identifiers would collide")
    if low in _HEADERS:
        refuse(f"the generated {name}.h would shadow the system header <{name}.h> wherever the "
               f"output directory is on the include path; choose another name")
    if low in _DEVICES:
        refuse(f"{name}.c and {name}.h are reserved device names on Windows; choose another name")
