"""The filter's flash tables (`stsp_est_table_t`, firmware/include/stospline/stsp_estimator.h):
float32 gains at the sampling ticks (or their spline, `estimator.gain_spline`), the
predictor's mean maps per stage (or per tick of a time-varying stage), the sensor's C and the
prior mean; their CRC-32 and C text."""
from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass

import numpy as np

from stospline.errors import DesignError, ProblemError
from stospline.estimator.gain_spline import EST_SPLINE_MAGIC, EstGainSpline, fit_gain_spline
from stospline.estimator.oracle import evaluate_estimator
from stospline.limits import MAX_NY
from stospline.table.codegen import _array, _f32_literal, _sha_initializer
from stospline.table.format import SCALAR_FLOAT32, positive_zeros

__all__ = ["EstimatorTable", "SplineEstimatorTable", "estimator_table", "estimator_crc32", "estimator_c",
           "with_estimator", "gain_spline_crc32", "EST_MAGIC", "EST_FORMAT_VERSION"]

EST_MAGIC = 0x45535453            # STSP_EST_MAGIC, "STSE"
EST_FORMAT_VERSION = 1            # STSP_EST_FORMAT_VERSION


@dataclass(frozen=True)
class EstimatorTable:
    """What `stsp_est_table_t` holds; the arrays float32 (model_start uint32).

    ``model[k]`` is ``[Ad | Bd | fd]`` (nx x (nx + nu + 1)); stage s uses maps
    ``model_start[s] .. model_start[s+1] - 1``, one per stage or one per tick. ``gain[s]`` (nx x
    ny) is the update gain of tick ``s * every``."""
    nx: int
    nu: int
    ny: int
    n_ticks: int
    every: int
    stage_start: np.ndarray
    model_start: np.ndarray
    model: np.ndarray
    C: np.ndarray
    gain: np.ndarray
    xhat0: np.ndarray
    problem_sha256: str | None

    @property
    def n_stages(self) -> int:
        return len(self.model_start) - 1

    def per_tick(self) -> tuple[np.ndarray, np.ndarray]:
        """``(gains, predictor)`` per tick as float64: the gains zero between samples (for
        `evaluate_estimator`'s ``gains=``/``predictor=``: the oracle of these tables)."""
        gain, model = self.filter_values()
        gains = np.zeros((self.n_ticks, self.nx, self.ny))
        gains[::self.every] = gain
        pred = np.empty((self.n_ticks, self.nx, model.shape[2]))
        for s in range(self.n_stages):
            a, b = int(self.stage_start[s]), int(self.stage_start[s + 1])
            maps = model[int(self.model_start[s]):int(self.model_start[s + 1])]
            pred[a:b] = maps if len(maps) == b - a else maps[0]
        return gains, pred.astype(float)

    def filter_values(self) -> tuple[np.ndarray, np.ndarray]:
        """``(gain, model)`` as the real numbers the firmware computes with."""
        return self.gain, self.model


@dataclass(frozen=True)
class SplineEstimatorTable(EstimatorTable):
    """An `EstimatorTable` whose gains the firmware stores as `gain_spline`
    (`stsp_est_gain_spline_t`; the C table's gain is NULL): ``gain`` is the spline's
    evaluation, bit for bit (`estimator.gain_spline.evaluate_gain_spline`)."""
    gain_spline: EstGainSpline | None = None


def estimator_table(problem, table, loop=None, *, spline_tolerance: float | None = None
                    ) -> EstimatorTable:
    """The float32 filter tables of `table`'s law on `problem`'s sensor: the LMMSE gains and
    the plant's exact mean maps of `evaluate_estimator` (`loop`, computed when not given).
    With `spline_tolerance`: the gains as a spline fitted to that relative tolerance
    (`estimator.gain_spline.fit_gain_spline`; SplineBudgetError when it cannot be met)."""
    meas = problem.measurement
    loop = evaluate_estimator(problem, table) if loop is None else loop
    n, m, _ = table.dims
    starts, maps = stage_maps(problem, table, loop)
    f32 = lambda a: positive_zeros(np.asarray(a, dtype=np.float32))  # noqa: E731
    spline = None
    if spline_tolerance is None:
        gain = _flushed_f32(loop.gain[::meas.every])
    else:
        spline, gain = fit_gain_spline(flushed(loop.gain[::meas.every]), table.stage_start,
                                       meas.every, spline_tolerance)
    kind = EstimatorTable if spline is None else SplineEstimatorTable
    return kind(
        n, m, meas.p, table.n_ticks, meas.every, np.asarray(table.stage_start, np.uint32),
        starts, _flushed_f32(maps), f32(meas.C), positive_zeros(gain), f32(problem.x0),
        table.problem_sha256, *(() if spline is None else (spline,)))


def stage_maps(problem, table, loop) -> tuple[np.ndarray, np.ndarray]:
    """``(model_start, model)``: the predictor maps ``[Ad | Bd | fd]`` of `loop` (double), one
    per stage, or one per tick of a time-varying stage, and each stage's first map."""
    n, m, _ = table.dims
    starts, maps = [0], []
    for k in range(table.n_stages):
        a, b = int(table.stage_start[k]), int(table.stage_start[k + 1])
        per_tick = problem.stages[k].varying is not None and b - a > 1
        maps.extend(loop.predict[a:b] if per_tick else loop.predict[a:a + 1])
        starts.append(len(maps))
    return np.asarray(starts, np.uint32), np.array(maps).reshape(-1, n, n + m + 1)


# Entries below this fraction of their array's largest are round-off of exact zeros (the
# cross gains of decoupled axes come out at 1e-15 .. 3e-11 of the largest, with digits that
# follow the BLAS kernel): flushed, so that the tables are the same on every machine. A real
# entry that small moves x-hat by less than float32 rounds it.
_ROUND_OFF = 1e-9


def _flushed_f32(a) -> np.ndarray:
    """`a` in float32 with its round-off zeros flushed to +0.0 (`_ROUND_OFF`)."""
    return positive_zeros(flushed(a).astype(np.float32))


def flushed(a) -> np.ndarray:
    """`a` (float64) with its round-off zeros (`_ROUND_OFF`) set to +0.0."""
    a = np.asarray(a, dtype=float)
    scale = float(np.abs(a).max()) if a.size else 0.0
    return np.where(np.abs(a) < _ROUND_OFF * scale, 0.0, a) + 0.0


def estimator_crc32(et: EstimatorTable) -> int:
    """The firmware's ``stsp_est_table_crc32``: nx, nu, ny, n_stages, n_ticks, every and the
    number of maps as little-endian u32, model_start as u32, then model, C, gain, xhat0 as
    binary32 bit patterns (gain not with a spline: its pointer is NULL), then the problem
    file's SHA-256 (zeros when unknown)."""
    return table_crc32(et, _f32_bytes)


def _f32_bytes(a) -> bytes:
    return positive_zeros(np.asarray(a, "<f4")).tobytes()


def gain_spline_crc32(et: EstimatorTable) -> int:
    """The firmware's ``stsp_est_gain_spline_crc32`` of `et`'s gain spline: n_stages, the
    number of entries of F (nx ny), of knots, stored entries and coefficients as
    little-endian u32, knot_start, then knot (binary32), entry_start, entry (bytes),
    coef_start, coef (binary32), then the estimator table's CRC-32 (u32)."""
    sp = et.gain_spline
    u32 = lambda a: np.asarray(a, "<u4").tobytes()  # noqa: E731
    parts = [struct.pack("<5I", sp.n_stages, sp.nx * sp.ny, sp.knot.size, sp.entry.size,
                         sp.coef.size),
             u32(sp.knot_start), _f32_bytes(sp.knot), u32(sp.entry_start),
             np.asarray(sp.entry, np.uint8).tobytes(), u32(sp.coef_start), _f32_bytes(sp.coef),
             struct.pack("<I", estimator_crc32(et))]
    crc = 0
    for part in parts:
        crc = zlib.crc32(part, crc)
    return crc & 0xFFFFFFFF


def table_crc32(et, entry_bytes, extra: tuple[bytes, ...] = ()) -> int:
    """The CRC-32 of an estimator table of any arithmetic: the dimensions, model_start,
    `entry_bytes` of model, C, gain and xhat0, the `extra` bytes (fixed point: exponents and
    shifts), the problem file's SHA-256."""
    parts = [struct.pack("<7I", et.nx, et.nu, et.ny, et.n_stages, et.n_ticks, et.every,
                         int(et.model_start[-1])),
             np.asarray(et.model_start, "<u4").tobytes()]
    gain = () if getattr(et, "gain_spline", None) is not None else (et.gain,)
    parts += [entry_bytes(a) for a in (et.model, et.C) + gain + (et.xhat0,)]
    parts += list(extra)
    parts.append(bytes.fromhex(et.problem_sha256 or "0" * 64))
    crc = 0
    for part in parts:
        crc = zlib.crc32(part, crc)
    return crc & 0xFFFFFFFF


def estimator_c(et: EstimatorTable, prefix: str) -> tuple[str, str]:
    """``(header, source)`` fragments: the header's declarations of ``<prefix>_estimator``
    and its macros, the source's arrays and the `stsp_est_table_t`."""
    p, name = prefix, prefix.upper()
    header = f"""
/* The filter on the sensor (stsp_estimator.h): y = C x at every tick j with j % EVERY == 0. */
#include "stospline/stsp_estimator.h"

#define {name}_NY {et.ny}u
#define {name}_EVERY {et.every}u
/* Layout model[map][r*(NX + NU + 1) + c] = [Ad | Bd | fd], C[i*NX + j],
 * gain[sample][r*NY + i], xhat0[j] (see stsp_estimator.h). */
extern const stsp_est_table_t {p}_estimator;
"""
    arrays = table_arrays(et, p, "stsp_f32_t", _f32_literal, ("[Ad | Bd | fd]", "",
                                                             "update gains", "prior mean"))
    source = table_source(et, p, arrays, SCALAR_FLOAT32, estimator_crc32(et))
    if getattr(et, "gain_spline", None) is None:
        return header, source
    header += f"""/* The update gains as cubic B-splines of the sample (stsp_est_init_spline()). */
extern const stsp_est_gain_spline_t {p}_est_gain_spline;
"""
    return header, source + _gain_spline_source(et, p)


def _gain_spline_source(et, p: str) -> str:
    sp = et.gain_spline
    u32 = lambda x: f"{int(x)}u"  # noqa: E731
    arrays = [
        _array("uint32_t", f"{p}_estg_knot_start", sp.knot_start, u32,
               "[n_stages + 1]: each stage's knots in knot[] (none: no samples)"),
        _array("stsp_f32_t", f"{p}_estg_knot", sp.knot, _f32_literal,
               f"[{sp.knot.size}]: clamped knot vectors, spans per stage {sp.spans()}"),
        _array("uint32_t", f"{p}_estg_entry_start", sp.entry_start, u32,
               "[n_stages + 1]: each stage's stored entries in entry[]"),
        _array("uint8_t", f"{p}_estg_entry", sp.entry, u32,
               "[entries]: r*NY + i of the gain F[r][i] stored, increasing per stage"),
        _array("uint32_t", f"{p}_estg_coef_start", sp.coef_start, u32,
               "[n_stages + 1]: each stage's coefficients in coef[]"),
        _array("stsp_f32_t", f"{p}_estg_coef", sp.coef, _f32_literal,
               "[entries of the stage][spans + 3] per stage"),
    ]
    return "\n" + "\n".join(arrays) + f"""
const stsp_est_gain_spline_t {p}_est_gain_spline = {{
    0x{EST_SPLINE_MAGIC:08X}u, {sp.knot.size}u, {sp.entry.size}u, {sp.coef.size}u,
    {p}_estg_knot_start, {p}_estg_knot, {p}_estg_entry_start, {p}_estg_entry,
    {p}_estg_coef_start, {p}_estg_coef,
    0x{estimator_crc32(et):08X}u, 0x{gain_spline_crc32(et):08X}u
}};
"""


def table_arrays(et, p: str, elem: str, literal, notes) -> list[str]:
    """The C arrays of an estimator table of element type `elem`: model_start, then model, C,
    gain and xhat0 with their `notes` (four strings)."""
    u32 = lambda x: f"{int(x)}u"  # noqa: E731
    w = et.nx + et.nu + 1
    model, C, gain, xhat0 = (f": {n}" if n else "" for n in notes)
    gains = [] if getattr(et, "gain_spline", None) is not None else [
        _array(elem, f"{p}_est_gain", et.gain, literal,
               f"[samples][nx][ny] = [{len(et.gain)}][{et.nx}][{et.ny}]{gain}")]
    return [
        _array("uint32_t", f"{p}_est_model_start", et.model_start, u32,
               "[n_stages + 1]: each stage's predictor maps in model[]"),
        _array(elem, f"{p}_est_model", et.model, literal,
               f"[maps][nx][nx + nu + 1] = [{len(et.model)}][{et.nx}][{w}]{model}"),
        _array(elem, f"{p}_est_C", et.C, literal, f"[ny][nx] = [{et.ny}][{et.nx}]{C}"),
        *gains,
        _array(elem, f"{p}_est_xhat0", et.xhat0, literal, f"[nx]{xhat0[1:]}"),
    ]


def table_source(et, p: str, arrays: list[str], kind: int, crc: int, tail: str = "") -> str:
    """The source text: `arrays`, then ``const stsp_est_table_t <p>_estimator`` of scalar
    `kind` with its `crc`, and `tail` (fixed point: the exponent and shift pointers) after the
    problem hash."""
    sha = et.problem_sha256 or "0" * 64
    gain = "NULL" if getattr(et, "gain_spline", None) is not None else f"{p}_est_gain"
    return "\n" + "\n".join(arrays) + f"""
const stsp_est_table_t {p}_estimator = {{
    0x{EST_MAGIC:08X}u, {EST_FORMAT_VERSION}u, {kind}u,
    {et.nx}u, {et.nu}u, {et.ny}u, {et.n_stages}u, {et.n_ticks}u, {et.every}u,
    {p}_est_model_start, {p}_est_model, {p}_est_C, {gain}, {p}_est_xhat0,
    0x{crc:08X}u,
    {_sha_initializer(sha)}{tail}
}};
"""


def with_estimator(header: str, source: str, problem, table, prefix: str | None = None, *,
                   spline_tolerance: float | None = None) -> tuple[str, str]:
    """`generate_c`'s text with the estimator tables added (a problem with [measurement] and
    a table the estimator loop runs; otherwise unchanged), the gains as a spline fitted to
    `spline_tolerance` when given. Raises ProblemError for a sensor with more outputs than the
    firmware takes, SplineBudgetError when the tolerance cannot be met."""
    if problem.measurement is None:
        return header, source
    if problem.measurement.p > MAX_NY:
        raise ProblemError("measurement.C", f"has {problem.measurement.p} rows (sensor "
                           f"outputs); the firmware's estimator takes at most {MAX_NY} "
                           f"(STSP_MAX_NY)")
    try:
        et = estimator_table(problem, table, spline_tolerance=spline_tolerance)
    except DesignError:
        raise
    except ValueError:                 # a delay or band table: no estimator form (summary)
        return header, source
    h, c = estimator_c(et, prefix or table.name)
    body, guard = header.rsplit("#endif", 1)
    return body + h.lstrip("\n") + "\n#endif" + guard, source + c
