"""The firmware's limits on a gain table, checked by the designer before any work or output.

`stsp_init` refuses a table whose dimensions exceed the ``STSP_MAX_*`` limits of
``firmware/include/stospline/stsp_controller.h`` (and ``STSP_BANDQP_MAX`` of ``stsp_bandqp.h``)
or whose offsets would not fit 32 bits (``stsp_check_dims``). The designer refuses the same
problems when it reads the file (`check_problem`, naming the key that causes the excess) and
checks the finished table once more before anything is written or compiled (`check_table`),
because the latched width depends on the design mode.

The constants below are the header's defaults; ``read_header_limits`` parses the header, and
``tests/python/firmware/test_table_limits.py`` checks that the two agree, so a header change cannot
silently diverge from the designer.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

__all__ = ["MAX_NX", "MAX_NU", "MAX_LATCH", "MAX_STAGES", "BANDQP_MAX", "Q_EXP_MAX", "MAX_NY",
           "MAX_TICKS", "MAX_ARRAY_BYTES", "HEADER_MACROS", "read_header_limits",
           "check_state", "check_mode", "check_problem", "check_stage_count", "check_table",
           "latch_width"]

MAX_NX = 32           # STSP_MAX_NX: states
MAX_NU = 16           # STSP_MAX_NU: inputs
MAX_LATCH = 16        # STSP_MAX_LATCH: latched multipliers (the table's n_latch)
MAX_STAGES = 256      # STSP_MAX_STAGES: stages (knots, including the bands of [[regions]])
BANDQP_MAX = 8        # STSP_BANDQP_MAX: band rows the on-target dual solver takes
MAX_NY = 8            # STSP_MAX_NY (stsp_estimator.h): the sensor's outputs
Q_EXP_MAX = 60        # STSP_Q_EXP_MAX: fixed-point scale exponents within +-60
MAX_TICKS = 2**32 - 1  # n_ticks and every table offset are uint32_t
# The largest array a C compiler for a 32-bit target accepts is PTRDIFF_MAX = 2^31 - 1 bytes
# (GCC: "size of array is too large"); the tables are meant for such targets.
MAX_ARRAY_BYTES = 2**31 - 1
F32_MAX = float(np.finfo(np.float32).max)   # table entries and the measured state are float32

# Python name -> the macro it mirrors, for `read_header_limits` and the test.
HEADER_MACROS = {"MAX_NX": "STSP_MAX_NX", "MAX_NU": "STSP_MAX_NU", "MAX_LATCH": "STSP_MAX_LATCH",
                 "MAX_STAGES": "STSP_MAX_STAGES", "BANDQP_MAX": "STSP_BANDQP_MAX",
                 "Q_EXP_MAX": "STSP_Q_EXP_MAX", "MAX_NY": "STSP_MAX_NY"}

_DEFINE = re.compile(r"^\s*#\s*define\s+(STSP_\w+)\s+(\d+)u?\b", re.MULTILINE)


def read_header_limits(include_dir: str | Path) -> dict[str, int]:
    """The limit macros' default values in the firmware's public headers, keyed like
    `HEADER_MACROS` (``{"MAX_NX": 32, ...}``)."""
    found: dict[str, int] = {}
    for header in sorted(Path(include_dir).glob("stospline/*.h")):
        for macro, value in _DEFINE.findall(header.read_text()):
            found.setdefault(macro, int(value))
    return {name: found[macro] for name, macro in HEADER_MACROS.items() if macro in found}


def _error(field: str, reason: str):
    from stospline.errors import ProblemError
    return ProblemError(field, reason)


def check_stage_count(t_knots, band_times=()) -> None:
    """Refuse more than MAX_STAGES stages: the knots (times `t_knots`) plus the distinct times
    of the bands that ``[[regions]]`` add (checked before the bands are merged into knots)."""
    if len(t_knots) > MAX_STAGES:
        raise _error("knots", f"has {len(t_knots)} knots, i.e. {len(t_knots)} stages; the "
                              f"firmware takes at most {MAX_STAGES} stages (STSP_MAX_STAGES)")
    if len(band_times) == 0:
        return
    # A band within 1e-9 (relative) of a knot or another band joins it (parse_problem).
    t = np.sort(np.concatenate([np.asarray(t_knots, float), np.asarray(band_times, float)]))
    stages = 1 + int(np.count_nonzero(np.diff(t) > 1e-9 * np.maximum(1.0, np.abs(t[1:]))))
    if stages > MAX_STAGES:
        raise _error("regions", f"add bands at {stages - len(t_knots)} times between the "
                                f"knots, giving {stages} stages; the firmware takes at most "
                                f"{MAX_STAGES} stages (STSP_MAX_STAGES): use a larger every, "
                                f"or fewer regions")


def latch_width(problem, mode: str | None) -> int:
    """The table's n_latch for `mode` (None: the smallest over the modes, stage-wise): the
    multipliers latched at once, or n when more (the table then latches the state,
    `table.format.build_table`). A band design with at most BANDQP_MAX rows keeps all of them."""
    rows = [kn.n_constraints for kn in problem.knots]
    if mode == "joint":
        p = sum(rows)
        bands = any(kn.constraint is not None and kn.constraint.is_band for kn in problem.knots)
        if bands and p <= BANDQP_MAX:
            return p
    else:
        p = max(rows)
    return min(p, problem.n)


def check_state(x0: np.ndarray) -> None:
    """x0 (parsed, finite): at most MAX_NX states, each within the float32 range in which the
    firmware measures the state."""
    if x0.shape[0] > MAX_NX:
        raise _error("x0", f"has {x0.shape[0]} entries (n = {x0.shape[0]} states); the firmware "
                           f"takes at most {MAX_NX} states (STSP_MAX_NX)")
    big = np.flatnonzero(np.abs(x0) > F32_MAX)
    if big.size:
        i = int(big[0])
        raise _error(f"x0[{i}]", f"{x0[i]:g} is beyond the float32 range (|x| <= {F32_MAX:.8g}) "
                                 f"in which the controller measures the state")


def check_mode(problem, mode: str, *, field: str = "design.mode") -> None:
    """Refuse a design mode whose table would latch more than MAX_LATCH multipliers (joint
    mode latches the rows of every constraint at once); called before the design runs."""
    p = latch_width(problem, mode)
    if p > MAX_LATCH:
        raise _error(field, _latch_reason(mode, p))


def _latch_reason(mode: str, p: int) -> str:
    return (f"mode {mode} latches {p} multipliers at once (the rows of every constraint it "
            f"covers, or n when more); the firmware takes at most {MAX_LATCH} "
            f"(STSP_MAX_LATCH): use mode stagewise, or fewer constraint rows")


def check_problem(problem, *, B_path: str = "dynamics.B") -> None:
    """Refuse a parsed problem whose table the firmware would refuse (dimensions, stages,
    latched width in every mode, 32-bit offsets, array sizes); names the key that causes it."""
    n, m = problem.n, problem.m
    check_state(problem.x0)
    if m > MAX_NU:
        raise _error(B_path, f"has {m} columns (m = {m} inputs); the firmware takes at most "
                             f"{MAX_NU} inputs (STSP_MAX_NU)")
    check_stage_count([kn.t for kn in problem.knots])
    p = latch_width(problem, None)
    if p > MAX_LATCH:
        k = int(np.argmax([kn.n_constraints for kn in problem.knots]))
        raise _error(f"knots[{k}].constraint.C", f"has {p} rows: the controller would latch "
                                                  f"{p} multipliers at once, the firmware at "
                                                  f"most {MAX_LATCH} (STSP_MAX_LATCH)")
    _check_sizes(int(problem.ticks_per_stage.sum()), n, m, p, 4, "tick_hz")


def _check_sizes(ticks: int, n: int, m: int, p: int, scalar_bytes: int, field: str) -> None:
    """32-bit offsets (`stsp_check_dims`: n_ticks nu (nx + n_latch) <= 2^32 - 1) and the
    largest array, K or L (n_ticks x nu x nx or n_latch), within MAX_ARRAY_BYTES."""
    per_tick = m * (n + p)
    if ticks * per_tick > MAX_TICKS:
        raise _error(field, f"gives {ticks} ticks; the table's K and L arrays would hold "
                            f"{ticks} x {m} x ({n} + {p}) = {ticks * per_tick} entries, beyond "
                            f"the firmware's 32-bit offsets ({MAX_TICKS}); lower the tick "
                            f"rate or shorten the plan")
    largest = ticks * m * max(n, p) * scalar_bytes
    if largest > MAX_ARRAY_BYTES:
        raise _error(field, f"gives {ticks} ticks; the table's largest array would take "
                            f"{largest} bytes ({ticks} x {m} x {max(n, p)} x {scalar_bytes}), "
                            f"beyond the {MAX_ARRAY_BYTES} bytes a 32-bit target can hold in "
                            f"one array; lower the tick rate or shorten the plan")


def check_table(table, *, mode_field: str = "design.mode") -> None:
    """Refuse a finished table (float32 `GainTable` or `table.qformat.FixedPointTable`) that `stsp_init`
    would refuse for its dimensions; `mode_field` names where the design mode came from."""
    n, m, p = table.dims
    if n > MAX_NX or m > MAX_NU or n < 1 or m < 1:   # parse_problem refuses these first
        raise _error("x0" if not 1 <= n <= MAX_NX else "dynamics.B",
                     f"the table has nx = {n}, nu = {m}; the firmware takes 1..{MAX_NX} "
                     f"states and 1..{MAX_NU} inputs")
    if p > MAX_LATCH:
        raise _error(mode_field, _latch_reason(getattr(table, "mode", "joint"), p))
    if not 1 <= table.n_stages <= MAX_STAGES:
        raise _error("knots", f"the table has {table.n_stages} stages; the firmware takes "
                              f"1..{MAX_STAGES} (STSP_MAX_STAGES)")
    band = getattr(table, "band_qp", None)
    if band is not None and not 1 <= band.q <= BANDQP_MAX:
        raise _error("knots", f"the band dual has {band.q} rows; the firmware's solver takes "
                              f"1..{BANDQP_MAX} (STSP_BANDQP_MAX)")
    arith = getattr(table, "arith", "float32")
    _check_sizes(table.n_ticks, n, m, p, 2 if arith == "q15" else 4, "tick_hz")
