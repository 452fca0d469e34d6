"""gains/ regenerates byte for byte on another machine, not only on this one.

Another CPU, BLAS kernel, thread count or library build changes the last bits of the design's
doubles (measured here: the numpy tick loop against the C one moves the robot's gains by up to
1.5e-14 relative). Every number written to gains/ must be printed at a precision those bits do
not reach (docs/guide/firmware.md, "Reproducible tables"). These tests regenerate every shipped file
(`tools/regen_gains.sh`) with the last bits changed in three ways and compare byte for byte:

* every double the design and the oracle hand on is multiplied by ``1 + r``, ``|r|`` drawn
  log-uniformly in [1e-15, 1e-14] (5 to 45 ulps), with a random sign (seeded);
* the numpy reference tick loop instead of the compiled one (another summation order);
* other CPUs' OpenBLAS kernels (forced with ``OPENBLAS_CORETYPE``) and one or two BLAS
  threads (a subprocess each: OpenBLAS reads both at load time), in
  test_gains_regenerate_elsewhere_blas.py: a file of its own, so that pytest-xdist's
  ``--dist loadfile`` gives the two files' regenerations to both workers.

`test_no_table_entry_is_near_a_rounding_boundary` makes the first one a proof for the tables:
no entry of a shipped table is within reach of such a perturbation of its rounding boundary.
"""
import dataclasses

import numpy as np
import pytest

from stospline import pipeline

from stospline.oracle import evaluate as oracle
from stospline.cli import main
from stospline.problem import load_problem

from conftest import EXAMPLES, GAINS, REPO, SPLINE_EXAMPLES, gains_stem

# Examples whose shipped table is per tick (the others ship only their spline table).
PER_TICK_EXAMPLES = sorted(p.stem for p in EXAMPLES.glob("*.toml") if gains_stem(p.stem) == p.stem)
SPLINE_SHIPPED = sorted({*SPLINE_EXAMPLES, *(p.stem for p in EXAMPLES.glob("*.toml")
                                              if gains_stem(p.stem) != p.stem)})

# Spline tables of designs that latch the state (`stospline.table.spline.restore`).
STATE_LATCHING = ("robot_monotone", "robot_narrow_corridor")

# Relative size of the perturbation, and an absolute part relative to each array's largest
# entry (a structural zero may come out as 1e-18 elsewhere, a small entry with a larger
# relative error than a large one).
REL = (1e-15, 1e-14)
ABS = 1e-16
# Computed from the problem file, not by floating-point arithmetic: left exact.
_GIVEN = {"problem", "stage", "lower", "upper", "_sol"}


def _regenerate(out) -> None:
    """What tools/regen_gains.sh does, into `out`."""
    for toml in sorted(EXAMPLES.glob("*.toml")):
        assert main(["design", str(toml), "--out", str(out)]) == 0
    for arith in ("q15", "q31"):
        assert main(["design", str(EXAMPLES / "robot_corridor.toml"), "--arith", arith,
                     "--out", str(out)]) == 0
    for arith in ("q15", "q31"):
        assert main(["design", str(EXAMPLES / "robot_position_sensor.toml"), "--arith", arith,
                     "--out", str(out)]) == 0
    for example in SPLINE_EXAMPLES:
        assert main(["design", str(EXAMPLES / f"{example}.toml"), "--table", "spline",
                     "--out", str(out)]) == 0
    for arith in ("q15", "q31"):
        assert main(["design", str(EXAMPLES / "robot_corridor.toml"), "--arith", arith,
                     "--table", "spline", "--out", str(out)]) == 0
    assert _params_tables().main(["--fixed", "--out", str(out)]) == 0
    assert _params_tables().main(["--spline", "--out", str(out)]) == 0


def _params_tables():
    """tools/params_tables.py (the Q15/Q31 and spline parametric controllers), as a module."""
    return tool_module("params_tables")


def tool_module(name: str):
    """tools/<name>.py, as a module."""
    import importlib.util
    spec = importlib.util.spec_from_file_location(name, REPO / "tools" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _assert_same_as_gains(out) -> None:
    names = sorted(p.name for p in GAINS.iterdir())
    assert sorted(p.name for p in out.iterdir()) == names
    differ = [n for n in names if (out / n).read_bytes() != (GAINS / n).read_bytes()]
    assert not differ, f"regenerated with other last bits, these differ from gains/: {differ}"


def _jiggle(x, rng):
    """`x` with every computed double perturbed (dataclasses, lists and tuples walked)."""
    if isinstance(x, np.ndarray) and x.dtype.kind == "f" and x.size:
        rel = rng.choice([-1.0, 1.0], x.shape) * 10.0 ** rng.uniform(*np.log10(REL), x.shape)
        return x * (1.0 + rel) + ABS * np.abs(x).max() * rng.uniform(-1.0, 1.0, x.shape)
    if isinstance(x, float):
        return float(x * (1.0 + rng.choice([-1.0, 1.0]) * 10.0 ** rng.uniform(*np.log10(REL))))
    if isinstance(x, list):
        return [_jiggle(v, rng) for v in x]
    if isinstance(x, tuple):
        return tuple(_jiggle(v, rng) for v in x)
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return dataclasses.replace(x, **{f.name: _jiggle(getattr(x, f.name), rng)
                                         for f in dataclasses.fields(x)
                                         if f.init and f.name not in _GIVEN})
    return x


def _perturbing(fn, rng):
    def wrapped(*args, **kwargs):
        return _jiggle(fn(*args, **kwargs), rng)
    return wrapped


@pytest.mark.parametrize("seed", [1, 2])
def test_design_doubles_perturbed_by_ulps_change_no_byte(tmp_path, monkeypatch, seed):
    rng = np.random.default_rng(seed)
    # Where the designs hand their results to the tables and the summary, and the oracle's
    # moments (also computed by `oracle.state_range` for the fixed-point scales).
    from stospline import design_method
    from stospline.design import continuous
    for module, name in ((design_method, "design_zoh"), (continuous, "design_continuous"),
                         (design_method, "design_bands"), (pipeline, "evaluate_table"),
                         (pipeline, "evaluate_continuous")):
        monkeypatch.setattr(module, name, _perturbing(getattr(module, name), rng))
    monkeypatch.setattr(oracle, "evaluate_table", _perturbing(oracle.evaluate_table, rng))
    _regenerate(tmp_path)
    _assert_same_as_gains(tmp_path)


def test_numpy_tick_loop_changes_no_byte(tmp_path, monkeypatch):
    monkeypatch.setenv("STOSPLINE_ZOH_KERNEL", "numpy")
    _regenerate(tmp_path)
    _assert_same_as_gains(tmp_path)


# OpenBLAS picks its kernels for the CPU it runs on; OPENBLAS_CORETYPE forces another one's,
# so this machine computes as those would (each pair: the kernel asked for, the one OpenBLAS
# reports, the CPU flag it needs). Zen runs Haswell's kernels; Nehalem's are SSE only.
# (Used by test_gains_regenerate_elsewhere_blas.py.)
BLAS_KERNELS = [("Haswell", "Haswell", "avx2", 1), ("SkylakeX", "SkylakeX", "avx512f", 2),
                ("Sandybridge", "Sandybridge", "avx", 2), ("Zen", "Haswell", "avx2", 1),
                ("Nehalem", "Nehalem", "sse4_2", 2)]
_CORENAMES = """
import ctypes, sys
names = []
for line in open("/proc/self/maps"):
    path = line.split()[-1]
    if "openblas" in path and path.endswith(".so") and path not in names:
        names.append(path)
for path in names:
    lib = ctypes.CDLL(path)
    for sym in ("scipy_openblas_get_corename64_", "scipy_openblas_get_corename",
                "openblas_get_corename64_", "openblas_get_corename"):
        if hasattr(lib, sym):
            fn = getattr(lib, sym); fn.restype = ctypes.c_char_p
            print("corename", fn().decode()); break
"""


def _cpu_flags() -> set[str]:
    try:
        with open("/proc/cpuinfo") as f:
            return next((set(line.split(":")[1].split()) for line in f
                         if line.startswith("flags")), set())
    except OSError:
        return set()


def _reach(a: np.ndarray) -> np.ndarray:
    """How far the test's perturbation can move each entry of `a` (its largest: REL[1])."""
    return REL[1] * np.abs(a) + ABS * np.abs(a).max()


def _f32_boundary_distance(a: np.ndarray) -> np.ndarray:
    """Distance of each double to the nearest midpoint between two float32 neighbours."""
    f = a.astype(np.float32)
    up = np.nextafter(f, np.float32(np.inf)).astype(float)
    down = np.nextafter(f, np.float32(-np.inf)).astype(float)
    return np.minimum(np.abs((f + up) / 2 - a), np.abs(a - (f + down) / 2))


@pytest.mark.parametrize("example", PER_TICK_EXAMPLES)
def test_no_table_entry_is_near_a_rounding_boundary(monkeypatch, example):
    """Every number a shipped table stores is rounded from a double (float32, Q15/Q31 integers,
    the band dual's 10 digits); none lies within `_reach` of where its rounding changes, so no
    perturbation of the size used above (nor the float32 flush of round-off zeros) changes it.
    Found here: the nearest is a Q31 gain 2.1e-5 LSB (5.9 times its reach) from a boundary."""
    from stospline.design import bands
    from stospline.table import qformat as fixed
    from stospline.table import format as tables
    rounded = {"float32": [], "q": [], "band": []}

    def capture(kind, fn):
        def wrapped(a, *args):
            rounded[kind].append(np.array(a, dtype=float))
            return fn(a, *args)
        return wrapped
    monkeypatch.setattr(tables, "_to_float32", capture("float32", tables._to_float32))
    monkeypatch.setattr(fixed, "_rhu", capture("q", fixed._rhu))
    monkeypatch.setattr(bands, "round_to_scale", capture("band", bands.round_to_scale))
    problem = load_problem(EXAMPLES / f"{example}.toml")
    d = pipeline.design_problem(problem, mode=problem.options.get("mode", "stagewise"))
    if example == "robot_corridor":
        for arith in ("q15", "q31"):
            pipeline.fixed_point_table(d, arith)
    assert rounded["float32"] and (rounded["q"] or example != "robot_corridor")

    def assert_clear(distance, a, what):
        near = int(np.sum(distance <= _reach(a)))
        assert near == 0, f"{near} {what} entries within reach of a rounding boundary"
    for a in (a for a in rounded["float32"] if np.any(a)):
        flush = 1e-12 * np.abs(a).max()          # tables._to_float32: below it, 0
        kept = np.abs(a) >= flush
        assert_clear(np.where(kept, _f32_boundary_distance(a), np.inf), a, "float32")
        assert_clear(np.abs(np.abs(a) - flush), a, "flushed")
    for a in (a for a in rounded["q"] if np.any(a)):
        assert_clear(np.abs(a - np.floor(a) - 0.5), a, "Q")
    for a in (a for a in rounded["band"] if np.any(a)):
        q = 10.0 ** (np.floor(np.log10(np.abs(a).max())) - bands.BANDQP_DIGITS + 1)
        assert_clear(np.abs(a / q - np.floor(a / q) - 0.5) * q, a, "band dual")


@pytest.mark.parametrize("example", SPLINE_SHIPPED)
def test_no_spline_entry_is_near_a_rounding_boundary(monkeypatch, example):
    """The same for the shipped spline tables: every coefficient (the least squares fit's,
    rounded to the float32 spacing at its entry's largest gain, `spline._coefficients`) and
    every re-solved latch entry of a band table (rounded after the flush of round-off zeros)
    is clear of where its rounding changes; a band table's re-solved dual (10 digits) clear of
    where its decimal rounding changes. The other tables' latch maps are chosen by
    `spline_latch.round_latch` from its inputs snapped to SNAP_BITS bits (the exact maps, the
    planned means, C2 Gamma): every snapped number is clear of where its snapping changes,
    and every exact map entry clear of the flush of round-off zeros; the choices are exact
    functions of the snapped numbers from there on (BLAS-free)."""
    from stospline.table.spline import band as spline_band, compress as spline_compress
    from stospline.table.spline import fit as spline, latch as spline_latch
    rounded = {"coef": [], "latch": [], "band": [], "snap": [], "flush": []}

    def capture(kind, fn):
        def wrapped(*args):
            rounded[kind].append(tuple(np.array(a, dtype=float) for a in args[:2]))
            return fn(*args)
        return wrapped
    monkeypatch.setattr(spline, "_coefficients", capture("coef", spline._coefficients))
    monkeypatch.setattr(spline_compress, "_to_float32",
                        capture("latch", spline_compress._to_float32))
    snap, round_latch, latch_grid = (spline_latch._snap, spline_latch.round_latch,
                                     spline_latch.latch_grid)

    def snap_capture(a, scale):                  # scale: one, or one per entry of a
        rounded["snap"].append((np.array(a, dtype=float),
                                np.broadcast_to(np.array(scale, dtype=float), np.shape(a))))
        return snap(a, scale)

    def round_capture(problem, table, groups, Lam, lam0):
        rounded["flush"].append((np.array(Lam, dtype=float), np.array(lam0, dtype=float)))
        return round_latch(problem, table, groups, Lam, lam0)

    def grid_capture(lam0, Lam, m):
        rounded["grid"].append(np.maximum(np.abs(lam0), np.abs(Lam * m).max(axis=1,
                                                                           initial=0.0)))
        return latch_grid(lam0, Lam, m)
    rounded["grid"] = []
    monkeypatch.setattr(spline_latch, "_snap", snap_capture)
    monkeypatch.setattr(spline_latch, "round_latch", round_capture)
    monkeypatch.setattr(spline_latch, "latch_grid", grid_capture)

    def band_capture(a, digits):
        rounded["band"].append(np.array(a, dtype=float))
        return round_to_scale(a, digits)
    round_to_scale = spline_band.round_to_scale
    monkeypatch.setattr(spline_band, "round_to_scale", band_capture)
    problem = load_problem(EXAMPLES / f"{example}.toml")
    pipeline.design_problem(problem, table="spline",
                            mode=problem.options.get("mode", "stagewise"))
    # The state-latching tables keep the per-tick latch (Lambda = I, lambda0 = 0) and restore
    # their constraints through the k0 coefficients, rounded by `_coefficients` too.
    assert rounded["coef"] and (rounded["latch"] or rounded["snap"]
                                or example in STATE_LATCHING)
    # The latch rounding (spline_latch.round_latch): what it reads is snapped to a multiple
    # of 2^-SNAP_BITS of the binade of a scale (the planned state's largest entry, the
    # multiplier's grid binade, C2 Gamma's largest), whose last bits move by REL[1] of it.
    for a, scale in rounded["snap"]:
        a, scale = a[scale > 0], scale[scale > 0]
        quantum = np.ldexp(1.0, np.frexp(scale)[1] - spline_latch.SNAP_BITS)
        distance = np.abs(a / quantum - np.floor(a / quantum) - 0.5) * quantum
        near = int(np.sum(distance <= REL[1] * scale))
        assert near == 0, f"{near} latch rounding inputs within reach of a snapping boundary"
    for Lam, lam0 in rounded["flush"]:
        for a in (a for a in (Lam, lam0) if np.any(a)):
            flush = 1e-12 * np.abs(a).max()
            near = int(np.sum(np.abs(np.abs(a) - flush) <= _reach(a)))
            assert near == 0, f"{near} latch entries within reach of the flush of round-off zeros"
        # Lambda's candidates are its exact entries' float32 neighbours.
        kept = np.abs(Lam) >= 1e-12 * np.abs(Lam).max(initial=0.0)
        near = int(np.sum(np.where(kept, _f32_boundary_distance(Lam), np.inf) <= _reach(Lam)))
        assert near == 0, f"{near} spline latch entries within reach of a rounding boundary"
    for peak in (p[p > 0] for p in rounded["grid"]):
        # lambda0's grid is the float32 spacing in the binade of its row's peak.
        binade = np.ldexp(1.0, np.frexp(peak)[1] - 1)
        near = int(np.sum(np.minimum(peak - binade, 2 * binade - peak) <= REL[1] * peak))
        assert near == 0, f"{near} latch rows' peaks within reach of a binade boundary"
    for a in (a for a in rounded["band"] if np.any(a)):
        q = 10.0 ** (np.floor(np.log10(np.abs(a).max())) - spline_band.BANDQP_DIGITS + 1)
        near = int(np.sum(np.abs(a / q - np.floor(a / q) - 0.5) * q <= _reach(a)))
        assert near == 0, f"{near} band dual entries within reach of a rounding boundary"
    # Every fit is checked, the refinement's discarded ones too (a superset of those kept).
    for a, peak in (p for p in rounded["coef"] if np.any(p[0])):
        # The grid of each entry: the float32 spacing in the binade of its peak; a
        # coefficient changes where it crosses a midpoint of that grid.
        q = np.ldexp(1.0, np.frexp(peak)[1] - 24)[:, None]
        distance = np.abs(a / q - np.floor(a / q) - 0.5) * q
        near = int(np.sum(distance <= _reach(a)))
        assert near == 0, f"{near} spline coefficients within reach of a rounding boundary"
    for a, *_ in (p for p in rounded["latch"] if np.any(p[0])):
        kept = np.abs(a) >= 1e-12 * np.abs(a).max()
        near = int(np.sum(np.where(kept, _f32_boundary_distance(a), np.inf) <= _reach(a)))
        assert near == 0, f"{near} spline latch entries within reach of a rounding boundary"


@pytest.mark.parametrize("example", ["robot_corridor", "robot_goal"])
@pytest.mark.parametrize("arith", ["q15", "q31"])
def test_no_fixed_point_spline_entry_is_near_a_rounding_boundary(monkeypatch, arith, example):
    """The same for the robot's shipped Q15/Q31 spline tables and robot_goal's Q15/Q31 spline
    parametric controllers (their spline columns too): every integer coefficient
    (``floor(c 2^s_e / 6 + 1/2)`` of the least squares fit, with the shift kept), every shift
    (``floor(log2(...))`` of the entry's peak) and every re-solved or rounded latch entry
    (``_rhu``) is clear of where its rounding changes, for every fit tried (a superset of
    those kept)."""
    from stospline.table import qformat
    from stospline.table.spline import fixed_point as qspline
    fits, shifts, latch = [], [], []
    lsq, fit_uniform, shifts_fn, rhu = (qspline._lsq, qspline._fit_uniform, qspline._shifts,
                                        qformat._rhu)

    def capture_lsq(*args):
        out = lsq(*args)
        fits.append(np.array(out, dtype=float))
        return out

    def capture_fit(*args):
        out = fit_uniform(*args)
        if out is not None:
            fits[-1] = (fits[-1], out[1])         # the coefficients in LSB and the shift kept
        return out

    def capture_shifts(peak, bits, k):
        top = float(2 ** (bits - 1) - 1)
        with np.errstate(divide="ignore"):
            shifts.append(np.log2(top * 6.0 / (qspline._COEF_HEADROOM
                                               * np.maximum(np.asarray(peak), 1e-300))))
        return shifts_fn(peak, bits, k)

    def capture_rhu(a):
        latch.append(np.array(a, dtype=float))
        return rhu(a)
    monkeypatch.setattr(qspline, "_lsq", capture_lsq)
    monkeypatch.setattr(qspline, "_fit_uniform", capture_fit)
    monkeypatch.setattr(qspline, "_shifts", capture_shifts)
    monkeypatch.setattr(qformat, "_rhu", capture_rhu)
    problem = load_problem(EXAMPLES / f"{example}.toml")
    if example == "robot_goal":
        from stospline.oracle.parametric import fixed_spline_parametric
        from stospline.options import resolve_options
        monkeypatch.setattr("stospline.table.spline.qparams._fit_uniform", capture_fit)
        fixed_spline_parametric(problem, options=resolve_options(problem, arith=arith))
    else:
        pipeline.fixed_point_spline(pipeline.design_problem(problem, table="spline"), arith)
    kept = [f for f in fits if isinstance(f, tuple)]
    assert kept and shifts and latch

    def assert_clear(distance, a, what):
        near = int(np.sum(distance <= _reach(a)))
        assert near == 0, f"{near} {what} within reach of a rounding boundary"
    for Cf, shift in kept:
        a = Cf * (np.ldexp(1.0, shift) / 6.0)[:, None]
        assert_clear(np.abs(a - np.floor(a) - 0.5), a, "Q spline coefficients")
    for a in (a[np.isfinite(a)] for a in shifts):
        if a.size:
            assert_clear(np.abs(a - np.round(a)), a, "Q spline shifts")
    for a in (a for a in latch if np.any(a)):
        assert_clear(np.abs(a - np.floor(a) - 0.5), a, "Q latch entries")


def test_written_bound_is_rounded_up_never_down(robot_zoh):
    """The bound in gains/ (JSON, and the header comment) is at least the exact bound plus the
    margin for other machines' last bits, and has at most 3 significant digits."""
    import json
    from decimal import Decimal
    from stospline.table.qformat import GAIN_AGREEMENT
    from stospline.precision import ceil_significant
    assert ceil_significant(2.928018756, 3) == 2.93 and ceil_significant(2.5, 3) == 2.5
    assert ceil_significant(9.991, 3) == 10.0 and ceil_significant(1.23e-12, 2) == 1.3e-12
    for arith in ("q15", "q31"):
        ft = pipeline.fixed_point_table(robot_zoh, arith)
        written = json.loads((GAINS / f"robot_corridor_{arith}.json").read_text())["fixed"]
        header = (GAINS / f"robot_corridor_{arith}.h").read_text()
        margin = 3 * GAIN_AGREEMENT * 2.0 ** ft.frac_bits
        exact = ft.bound_lsb.max(axis=0)
        for w, w_real, b, lsb in zip(written["u_error_bound_lsb"], written["u_error_bound"],
                                     exact, ft.u_lsb):
            assert Decimal(repr(w)) >= Decimal(b) + Decimal(margin)
            assert Decimal(repr(w_real)) >= Decimal(repr(w)) * Decimal(lsb)
            assert len(Decimal(repr(w)).as_tuple().digits) <= 3
            assert f"{w_real:.3g}" in header.split("|u_fixed - u_double| <=")[1].split("]")[0]
