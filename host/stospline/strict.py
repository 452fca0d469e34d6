"""Strict output: every number the tool writes or prints is finite, or the run is refused.

* `dumps`: JSON with ``allow_nan=False``, so a NaN or an infinity can never reach a file or
  stdout (strict JSON parsers reject them); callers null undefined statistics first.
* `check_table_finite`: every entry of a generated table (float32 gains, feed-forwards, latch
  maps, limits, the band dual in double precision) is finite; a design whose numbers overflow
  float32 is refused naming the input that drives them (`culprit`) and the worst entry.
* `check_summary_finite`: the same for the numbers of a JSON summary.
* `quiet_numerics`: numpy's RuntimeWarnings (overflow, invalid value, division by zero) become
  at most one line on stderr, and only when the run succeeds: when it fails, the one-line
  error already says why.

Errors are `ProblemError`s (exit status 2 from the CLI) raised before anything is written.
"""
from __future__ import annotations

import functools
import json
import math
import sys
import warnings

import numpy as np

from stospline.limits import F32_MAX
from stospline.errors import ProblemError

__all__ = ["dumps", "first_nonfinite", "culprit", "check_table_finite", "check_summary_finite",
           "quiet_numerics", "ratio_or_null", "fixed_scale_error"]


def dumps(obj) -> str:
    """``json.dumps(obj, indent=2, sort_keys=True)`` that raises instead of writing NaN or
    Infinity (which ``json.dumps`` writes by default, and strict parsers reject), and writes
    every zero as ``0.0``: the sign of a computed zero depends on the machine's round-off
    (`stospline.table.format.positive_zeros`), and ``-0.0`` would make the bytes do too."""
    return json.dumps(_positive_zeros(obj), indent=2, sort_keys=True, allow_nan=False)


def _positive_zeros(obj):
    """`obj` (nested dicts, lists, tuples) with every float ``-0.0`` as ``0.0``."""
    if isinstance(obj, float):
        return obj + 0.0
    if isinstance(obj, dict):
        return {key: _positive_zeros(val) for key, val in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_positive_zeros(val) for val in obj]
    return obj


def first_nonfinite(obj, path: str = ""):
    """``(path, value)`` of the first non-finite number in nested dicts, lists and arrays
    (``"knots[0].cov[1][1]"``), or None."""
    if isinstance(obj, dict):
        for key, val in obj.items():
            hit = first_nonfinite(val, f"{path}.{key}" if path else str(key))
            if hit:
                return hit
    elif isinstance(obj, (list, tuple)):
        for i, val in enumerate(obj):
            hit = first_nonfinite(val, f"{path}[{i}]")
            if hit:
                return hit
    elif isinstance(obj, np.ndarray):
        if obj.dtype.kind in "fc" and not np.all(np.isfinite(obj)):
            idx = np.unravel_index(int(np.argmin(np.isfinite(obj).ravel())), obj.shape)
            return path + "".join(f"[{i}]" for i in idx), float(obj[idx])
    elif isinstance(obj, (float, np.floating)) and not math.isfinite(float(obj)):
        return path, float(obj)
    return None


def ratio_or_null(num, den, reason: str):
    """``num / den`` elementwise, with None where ``den == 0`` (the statistic is undefined),
    and the `reason` to report beside it, or None when every entry is defined."""
    num, den = np.asarray(num, dtype=float), np.asarray(den, dtype=float)
    defined = den != 0
    with np.errstate(divide="ignore", invalid="ignore"):
        val = np.where(defined, num / np.where(defined, den, 1.0), 0.0)
    out = [float(v) if ok else None for v, ok in zip(val.ravel(), defined.ravel())]
    value = out[0] if val.ndim == 0 else out
    return value, (None if defined.all() else reason)


# ---------------------------------------------------------------------------------------
# Which input of the problem file drives an overflow.

# Quantity -> the inputs that can make it large. Gains depend on the dynamics and weights
# (B, C, R also when small); feed-forwards and latch offsets also on targets and constraint
# values; predicted moments and costs also on x0 and rho.
_GAIN = ("dynamics.A", "dynamics.B", "dynamics.noise", "cost.Q", "cost.S", "cost.R",
         "penalty.weight", "penalty.C", "constraint.C")
_OFFSET = _GAIN + ("cost.q", "cost.r", "penalty.target", "constraint.value", "dynamics.f")
_MOMENTS = _OFFSET + ("x0", "cost.rho")
# The corridor statistics of a summary also depend on the corridors' own numbers.
_CORRIDOR = _MOMENTS + ("corridor.C", "corridor.A", "corridor.b")
# Time-varying data are scored at this many times per stage at most (tick midpoints and the
# stage's ends): a sample far from 1 between the ends is seen.
_VARYING_POINTS = 4097
_SMALL_MATTERS = ("dynamics.B", "cost.R", "constraint.C")  # gains scale with their inverse
_EXTREME = 8.0   # orders of magnitude from 1 that make an input the likely cause


def _orders(values, small: bool) -> float:
    """How many orders of magnitude the entries reach away from 1 (large, or small nonzero
    when `small`)."""
    a = np.abs(np.asarray(values, dtype=float)).ravel()
    a = a[np.isfinite(a) & (a > 0)]
    if not a.size:
        return 0.0
    out = math.log10(a.max())
    if small:
        out = max(out, -math.log10(a.min()))
    return out


def _candidates(problem):
    """``(field, kind, values)`` for every numeric input of the problem."""
    uniform = {key: all(_same(_value(problem.stages[0], key), _value(st, key))
                        for st in problem.stages) for key, _ in _STAGE_KEYS}
    for k, st in enumerate(problem.stages):
        for key, section in _STAGE_KEYS:
            yield from _stage_values(problem, k, st, key, section, uniform[key])
    for k, kn in enumerate(problem.knots):
        if kn.penalty is not None:
            p = kn.penalty
            yield f"knots[{k}].penalty.weight", "penalty.weight", [p.weight]
            yield f"knots[{k}].penalty.C", "penalty.C", p.C
            yield f"knots[{k}].penalty.target", "penalty.target", p.target
        if kn.constraint is not None:
            c = kn.constraint
            yield f"knots[{k}].constraint.C", "constraint.C", c.C
            lo, hi = c.bounds
            key = "value" if c.value is not None else "lower"
            yield f"knots[{k}].constraint.{key}", "constraint.value", np.concatenate([lo, hi])
    yield "x0", "x0", problem.x0
    for i, c in enumerate(getattr(problem, "corridors", ())):
        yield f"corridors[{i}].C", "corridor.C", c.C
        for j, (A, b) in enumerate(c.polygons):
            yield f"corridors[{i}].polygons[{j}].A", "corridor.A", A
            yield f"corridors[{i}].polygons[{j}].b", "corridor.b", b


_STAGE_KEYS = (("A", "dynamics"), ("B", "dynamics"), ("f", "dynamics"), ("noise", "dynamics"),
               ("Q", "cost"), ("S", "cost"), ("R", "cost"), ("q", "cost"), ("r", "cost"),
               ("rho", "cost"))


def _value(st, key: str):
    return st.noise_tensor if key == "noise" else getattr(st, key)


def _stage_values(problem, k: int, st, key: str, section: str, uniform: bool):
    """``(field, kind, values)`` of one key of stage k, named where the file writes it: each
    sample of time-varying data as ``<path>.values[i]``; a constant as ``section.key``, with
    ``stages[k].`` in front when the stages' values differ (`uniform`: they do not)."""
    kind = f"{section}.{key}"
    origin = getattr(st, "origin", None)
    raw = [] if origin is None else (
        [g for _, g, _ in origin.noise] if key == "noise" else [origin.fields.get(key)])
    series = [v for v in raw if hasattr(v, "path") and hasattr(v, "values")]
    for ser in series:
        for i, sample in enumerate(ser.values):
            yield f"{ser.path}.values[{i}]", kind, sample
    if series and key != "noise":
        return
    if st.varying is not None and origin is None:     # built in Python: sample it in time
        v = st.samples(_stage_times(problem, k))
        values = [v["G"], v["H"]] if key == "noise" else [v[key]]
    else:
        values = [st.noise_tensor] if key == "noise" else [getattr(st, key)]
    values = [np.atleast_1d(np.asarray(a, float)) for a in values if a is not None]
    if not values:
        return
    field = kind if uniform else f"stages[{k}].{kind}"
    for a in values:
        yield field, kind, a


def _same(a, b) -> bool:
    if a is None or b is None:
        return a is b
    return np.shape(a) == np.shape(b) and bool(np.all(np.asarray(a) == np.asarray(b)))


def _stage_times(problem, k: int) -> np.ndarray:
    """Times at which stage k's time-varying data are scored: its ends and tick midpoints
    (evenly thinned to `_VARYING_POINTS`)."""
    a, b = float(problem.times[k]), float(problem.times[k + 1])
    ticks = max(1, int(round((b - a) * problem.tick_hz)))
    inner = a + (np.arange(ticks) + 0.5) * (b - a) / ticks
    if inner.size > _VARYING_POINTS:
        inner = inner[np.linspace(0, inner.size - 1, _VARYING_POINTS).astype(int)]
    return np.concatenate([[a], inner, [b]])


def culprit(problem, kinds=_MOMENTS) -> str | None:
    """The field of the input (of `kinds`) whose entries lie furthest from 1 in orders of
    magnitude, if some lie at least 1e8 away (else None: no single extreme input)."""
    best, field = _EXTREME, None
    for name, kind, values in _candidates(problem):
        if kind in kinds:
            score = _orders(values, kind in _SMALL_MATTERS)
            if score >= best + 1e-12 or (field is None and score >= best):
                best, field = score, name
    return field


def _cause(problem, kinds, stage: int | None) -> tuple[str, str]:
    """(field, advice) for a refusal."""
    field = culprit(problem, kinds)
    if field is not None:
        return field, (f"{field} has entries {_extreme_text(problem, field)}; give the "
                       f"problem in units that keep its numbers moderate")
    where = "knots[0].t" if stage is None else f"knots[{stage}].t"
    return where, ("no single input is extreme, so the growth comes from the dynamics over "
                   "the plan (an unstable mode over a long stage): shorten the stage or "
                   "change the dynamics or weights")


def overflow_failure(problem) -> tuple[str, str]:
    """(field, reason) for a design whose intermediate numbers left the double range (a
    matrix exponential of non-finite data): the most extreme input when there is one."""
    field, advice = _cause(problem, _MOMENTS, None)
    return field, f"the design's numbers overflow the double range: {advice}"


def riccati_failure(problem, stage: int) -> tuple[str, str]:
    """(field, reason) for a Riccati recursion that broke down (lost positive definiteness,
    or its numbers left the double range) on `stage`: the most extreme input when there is one,
    else the knot that ends the stage."""
    field, advice = _cause(problem, _MOMENTS, stage)
    return field, (f"the design's numbers overflow (the tick Riccati recursion of stage {stage} "
                   f"lost positive definiteness): {advice}")


def _extreme_text(problem, field: str) -> str:
    for name, kind, values in _candidates(problem):
        if name == field:
            a = np.abs(np.asarray(values, float)).ravel()
            a = a[np.isfinite(a) & (a > 0)]
            if a.size:
                return f"up to {a.max():.3g}" if kind not in _SMALL_MATTERS or \
                    math.log10(a.max()) >= -math.log10(a.min()) else f"as small as {a.min():.3g}"
    return "of extreme size"


def _table_arrays(table):
    """``(name, per-tick?, array, kinds)`` of the arrays stored in a table."""
    yield "K", True, table.K, _GAIN
    yield "k0", True, table.k0, _OFFSET
    yield "L", True, table.L, _GAIN
    yield "Lambda", False, table.Lambda, _GAIN
    yield "lambda0", False, table.lambda0, _OFFSET
    b = getattr(table, "band_qp", None)
    if b is not None:
        yield "band Nt", False, b.Nt, _GAIN
        yield "band W", False, b.W, _GAIN
        yield "band mt", False, b.mt, _OFFSET
        yield "band lo/hi", False, np.concatenate([b.lo, b.hi]), _OFFSET


def check_table_finite(problem, table, exact=None) -> None:
    """Refuse a float32 table with a non-finite entry: the firmware would refuse it
    (STSP_ERR_BAD_VALUES) and its C source would not compile (``inff``). `exact` (optional, a
    callable: only called on failure) gives the same table before float32 rounding, for the
    size of the overflowing entry."""
    for name, per_tick, arr, kinds in _table_arrays(table):
        arr = np.asarray(arr)
        if np.all(np.isfinite(arr)):
            continue
        bad = np.argwhere(~np.isfinite(arr))[0]
        at, stage = "", None
        if per_tick:
            stage = table.stage_of_tick(int(bad[0]))
            at = f" at tick {int(bad[0])}"
        elif name in ("Lambda", "lambda0"):
            stage = int(bad[0])
            at = f" at stage {stage}"
        src = None if exact is None else {n: a for n, _, a, _ in _table_arrays(exact())}[name]
        if src is not None and np.all(np.isfinite(src)):
            big = np.abs(np.asarray(src, float))
            size = f"|{name}| up to {big.max():.3g}{at}, beyond float32's {F32_MAX:.3g}"
            what = "overflow float32"
        else:
            size = f"{name}{at} is {float(arr[tuple(bad)])}"
            what = "are not finite even in double precision"
        field, advice = _cause(problem, kinds, stage)
        raise ProblemError(field, f"the design's {_NOUN[name]} {what} ({size}); {advice}")


_NOUN = {"K": "feedback gains K", "k0": "feed-forward terms k0", "L": "multiplier gains L",
         "Lambda": "latch maps Lambda", "lambda0": "latch offsets lambda0",
         "band Nt": "band dual data Nt", "band W": "band dual matrix W",
         "band mt": "band dual offsets mt", "band lo/hi": "band bounds"}


def check_summary_finite(problem, summary: dict, what: str = "predicted numbers",
                         faults=None) -> None:
    """Refuse a summary holding a non-finite number (it could not be written as JSON). With
    the run's `faults` (a Monte Carlo run), a fault is blamed when no input is extreme."""
    hit = first_nonfinite(summary)
    if hit is None:
        return
    path, value = hit
    stage = None
    if path.startswith("knots["):
        stage = int(path[6:path.index("]")])
    kinds = _CORRIDOR if path.startswith("corridors[") else _MOMENTS
    fault = None
    if faults is not None and culprit(problem, kinds) is None:
        fault = _fault_cause(faults)
    if fault is not None:
        key, level = fault
        raise ProblemError(f"faults.{key}", f"the {what} overflow double precision ({path} is "
                                            f"{value}): the loop with {key} = {level} grows "
                                            f"beyond the double range (the designed loop "
                                            f"does not): use a smaller fault")
    field, advice = _cause(problem, kinds, stage)
    raise ProblemError(field, f"the {what} overflow double precision ({path} is {value}); "
                              f"{advice}")


def _fault_cause(faults):
    """``(key, level)`` of the fault that most likely drives a faulty loop's overflow (the
    model mismatch furthest from 1, else the largest noise level), or None without one."""
    scales = [(abs(math.log10(getattr(faults, k))), k) for k in
              ("plant_A_scale", "plant_B_scale", "plant_noise_scale")
              if getattr(faults, k) > 0 and getattr(faults, k) != 1.0]
    if scales:
        key = max(scales)[1]
        return key, f"{getattr(faults, key):g}"
    noises = [(float(np.max(getattr(faults, k))), k) for k in ("actuator_noise", "sensor_noise")
              if np.size(getattr(faults, k)) and np.max(getattr(faults, k)) > 0]
    if noises:
        level, key = max(noises)
        return key, f"{level:g}"
    return None


def quiet_numerics(func):
    """Run `func` with numpy's floating-point RuntimeWarnings collected: nothing when it
    raises (its error explains the failure), one summary line on stderr when it succeeds.
    A compiled kernel replaced by its numpy reference (`cache.FallbackWarning`) is one
    informational line, not counted as a floating-point warning."""
    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        from stospline.cache import FallbackWarning
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", RuntimeWarning)
            result = func(*args, **kwargs)
        fallback = [w for w in caught if issubclass(w.category, FallbackWarning)]
        numeric = [w for w in caught if issubclass(w.category, RuntimeWarning)
                   and w not in fallback]
        for w in caught:
            if w not in numeric and w not in fallback:
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        if fallback:
            print(f"stospline: note: {_fallback_text(fallback)}", file=sys.stderr)
        if numeric:
            first = str(numeric[0].message).splitlines()[0]
            print(f"stospline: warning: {len(numeric)} floating-point warning(s) during the "
                  f"computation (first: {first}); every number written was checked finite",
                  file=sys.stderr)
        return result
    return wrapper


def _fallback_text(caught) -> str:
    from stospline.cache import c_compiler
    compiler, found = c_compiler()
    if not found:
        return (f"no C compiler ({compiler!r} is not found), so the design ran its numpy "
                f"loops instead of the compiled kernels (slower); install one (e.g. apt-get "
                f"install gcc) or set CC to make it faster")
    return str(caught[0].message).splitlines()[0]


def fixed_scale_error(problem, arith: str, exc: ValueError) -> ProblemError:
    """A `table.qformat.quantize_table` refusal (scale exponents beyond the firmware's
    +-STSP_Q_EXP_MAX) as a ProblemError naming the most extreme input, else design.arith."""
    field = culprit(problem, _MOMENTS)
    advice = ("use float32 tables" if field is None else
              f"{field} has entries {_extreme_text(problem, field)}; give the problem in units "
              f"that keep its numbers moderate, or use float32 tables")
    return ProblemError(field or "design.arith",
                        f"no {arith.upper()} table can hold this design: {exc}; {advice}")
