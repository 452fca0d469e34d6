"""The filter's flash tables (`stsp_est_table_t`, firmware/include/stospline/stsp_estimator.h):
float32 gains at the sampling ticks, the predictor's mean maps per stage (or per tick of a
time-varying stage), the sensor's C and the prior mean; their CRC-32 and C text."""
from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass

import numpy as np

from stospline.errors import ProblemError
from stospline.estimator.oracle import evaluate_estimator
from stospline.limits import MAX_NY
from stospline.table.codegen import _array, _f32_literal, _sha_initializer
from stospline.table.format import SCALAR_FLOAT32, positive_zeros

__all__ = ["EstimatorTable", "estimator_table", "estimator_crc32", "estimator_c",
           "with_estimator", "EST_MAGIC", "EST_FORMAT_VERSION"]

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


def estimator_table(problem, table, loop=None) -> EstimatorTable:
    """The float32 filter tables of `table`'s law on `problem`'s sensor: the LMMSE gains and
    the plant's exact mean maps of `evaluate_estimator` (`loop`, computed when not given)."""
    meas = problem.measurement
    loop = evaluate_estimator(problem, table) if loop is None else loop
    n, m, _ = table.dims
    starts, maps = stage_maps(problem, table, loop)
    f32 = lambda a: positive_zeros(np.asarray(a, dtype=np.float32))  # noqa: E731
    return EstimatorTable(
        n, m, meas.p, table.n_ticks, meas.every, np.asarray(table.stage_start, np.uint32),
        starts, _flushed_f32(maps), f32(meas.C), _flushed_f32(loop.gain[::meas.every]),
        f32(problem.x0), table.problem_sha256)


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
    binary32 bit patterns, then the problem file's SHA-256 (zeros when unknown)."""
    return table_crc32(et, lambda a: positive_zeros(np.asarray(a, "<f4")).tobytes())


def table_crc32(et, entry_bytes, extra: tuple[bytes, ...] = ()) -> int:
    """The CRC-32 of an estimator table of any arithmetic: the dimensions, model_start,
    `entry_bytes` of model, C, gain and xhat0, the `extra` bytes (fixed point: exponents and
    shifts), the problem file's SHA-256."""
    parts = [struct.pack("<7I", et.nx, et.nu, et.ny, et.n_stages, et.n_ticks, et.every,
                         int(et.model_start[-1])),
             np.asarray(et.model_start, "<u4").tobytes()]
    parts += [entry_bytes(a) for a in (et.model, et.C, et.gain, et.xhat0)]
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
    return header, table_source(et, p, arrays, SCALAR_FLOAT32, estimator_crc32(et))


def table_arrays(et, p: str, elem: str, literal, notes) -> list[str]:
    """The C arrays of an estimator table of element type `elem`: model_start, then model, C,
    gain and xhat0 with their `notes` (four strings)."""
    u32 = lambda x: f"{int(x)}u"  # noqa: E731
    w = et.nx + et.nu + 1
    model, C, gain, xhat0 = (f": {n}" if n else "" for n in notes)
    return [
        _array("uint32_t", f"{p}_est_model_start", et.model_start, u32,
               "[n_stages + 1]: each stage's predictor maps in model[]"),
        _array(elem, f"{p}_est_model", et.model, literal,
               f"[maps][nx][nx + nu + 1] = [{len(et.model)}][{et.nx}][{w}]{model}"),
        _array(elem, f"{p}_est_C", et.C, literal, f"[ny][nx] = [{et.ny}][{et.nx}]{C}"),
        _array(elem, f"{p}_est_gain", et.gain, literal,
               f"[samples][nx][ny] = [{len(et.gain)}][{et.nx}][{et.ny}]{gain}"),
        _array(elem, f"{p}_est_xhat0", et.xhat0, literal, f"[nx]{xhat0[1:]}"),
    ]


def table_source(et, p: str, arrays: list[str], kind: int, crc: int, tail: str = "") -> str:
    """The source text: `arrays`, then ``const stsp_est_table_t <p>_estimator`` of scalar
    `kind` with its `crc`, and `tail` (fixed point: the exponent and shift pointers) after the
    problem hash."""
    sha = et.problem_sha256 or "0" * 64
    return "\n" + "\n".join(arrays) + f"""
const stsp_est_table_t {p}_estimator = {{
    0x{EST_MAGIC:08X}u, {EST_FORMAT_VERSION}u, {kind}u,
    {et.nx}u, {et.nu}u, {et.ny}u, {et.n_stages}u, {et.n_ticks}u, {et.every}u,
    {p}_est_model_start, {p}_est_model, {p}_est_C, {p}_est_gain, {p}_est_xhat0,
    0x{crc:08X}u,
    {_sha_initializer(sha)}{tail}
}};
"""


def with_estimator(header: str, source: str, problem, table, prefix: str | None = None
                   ) -> tuple[str, str]:
    """`generate_c`'s text with the estimator tables added (a problem with [measurement] and
    a table the estimator loop runs; otherwise unchanged). Raises ProblemError for a sensor
    with more outputs than the firmware takes."""
    if problem.measurement is None:
        return header, source
    if problem.measurement.p > MAX_NY:
        raise ProblemError("measurement.C", f"has {problem.measurement.p} rows (sensor "
                           f"outputs); the firmware's estimator takes at most {MAX_NY} "
                           f"(STSP_MAX_NY)")
    try:
        et = estimator_table(problem, table)
    except ValueError:                 # a delay or band table: no estimator form (summary)
        return header, source
    h, c = estimator_c(et, prefix or table.name)
    body, guard = header.rsplit("#endif", 1)
    return body + h.lstrip("\n") + "\n#endif" + guard, source + c
