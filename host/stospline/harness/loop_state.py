"""What a block of paths carries through the harness's tick loop besides the controllers: the
faults' levels and random numbers (`FaultDraws`), the corridors' exit watch (`CorridorWatch`)
and the run's per-tick statistics (`TickStats`)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["FaultDraws", "CorridorWatch", "TickStats"]


@dataclass
class FaultDraws:
    """The faults of a block of paths for `CompiledController.fault_ticker`: levels (None: no
    such fault), the per-tick random numbers (refilled by `draw`) and the actuator's held
    commands."""
    sensor_std: np.ndarray | None
    quantum: np.ndarray | None
    actuator_std: np.ndarray | None
    miss_probability: float
    delay_ticks: int
    feed_held: int                   # 1: a table designed for the delay (`GainTable`)
    sensor_z: np.ndarray | None      # (paths, n) standard normal
    actuator_z: np.ndarray | None    # (paths, m) standard normal
    miss_u: np.ndarray | None        # (paths,) uniform in [0, 1)
    held: np.ndarray                 # (paths, m)

    @classmethod
    def of(cls, faults, paths: int, n: int, hold: np.ndarray,
           table_delay: int = 0) -> "FaultDraws":
        """The draws of `faults` for `paths` paths of n states; the actuator of every path
        starts on the safe command `hold` (m,). `table_delay` 1: the table is designed for a
        one-tick delay, so the loop has one (its controller also measures the held command);
        a delay fault on top of it is refused (ValueError)."""
        if table_delay and faults.delay_ticks:
            raise ValueError("a table designed for a one-tick delay runs with that delay; a "
                             "delay fault on top of it is not simulated")
        m = len(hold)

        def vec(a):
            return np.ascontiguousarray(a, dtype=float) if np.any(a) else None
        sensor, quantum, actuator = (vec(faults.sensor_noise), vec(faults.sensor_quantum),
                                     vec(faults.actuator_noise))
        return cls(sensor, quantum, actuator, float(faults.miss_probability),
                   int(faults.delay_ticks) or int(table_delay), int(table_delay),
                   np.empty((paths, n)) if sensor is not None else None,
                   np.empty((paths, m)) if actuator is not None else None,
                   np.empty(paths) if faults.miss_probability > 0 else None,
                   np.tile(np.asarray(hold, dtype=float), (paths, 1)))

    def draw(self, rng: np.random.Generator, rows: slice = slice(None)) -> None:
        """This tick's numbers of the paths `rows` (default all), from the faults' own stream
        `rng`."""
        if self.sensor_z is not None:
            rng.standard_normal(out=self.sensor_z[rows])
        if self.actuator_z is not None:
            rng.standard_normal(out=self.actuator_z[rows])
        if self.miss_u is not None:
            rng.random(out=self.miss_u[rows])


@dataclass
class CorridorWatch:
    """Each path's first exit from each corridor (`stospline.problem.corridors`): the state
    tick (``exit_tick``, corridors x paths, -1: never) and the wall (``exit_wall``). The C
    tick (``harness_tick_watch``) fills them; `check` does the same in numpy, for the tick-0
    state and for runs that step the plant outside that C call."""
    corridors: tuple
    ticks: list                    # (first, last) state tick per corridor
    exit_tick: np.ndarray          # (corridors, paths) int32
    exit_wall: np.ndarray

    @classmethod
    def of(cls, corridors, paths: int, t0: float, tick_hz: int) -> "CorridorWatch":
        from stospline.problem.corridors import corridor_ticks
        k = len(corridors)
        return cls(tuple(corridors), [corridor_ticks(c, t0, tick_hz) for c in corridors],
                   np.full((k, paths), -1, np.int32), np.full((k, paths), -1, np.int32))

    def check(self, state_tick: int, X: np.ndarray) -> None:
        """Record the paths that are outside at `state_tick` (states X) for the first time."""
        for i, (c, (lo, hi)) in enumerate(zip(self.corridors, self.ticks)):
            if lo <= state_tick <= hi:
                fresh = self.exit_tick[i] < 0
                wall = c.exit_wall(X[fresh] @ c.C.T)
                idx = np.flatnonzero(fresh)[wall >= 0]
                self.exit_tick[i, idx] = state_tick
                self.exit_wall[i, idx] = wall[wall >= 0]

    def c_structs(self, ffi):
        """``(harness_corridor_t[], arrays they point into)`` for the C tick."""
        cors = ffi.new("harness_corridor_t[]", len(self.corridors))
        keep = []

        def ptr(a, kind):
            keep.append(a)
            return ffi.cast(kind, ffi.from_buffer(a))
        for i, c in enumerate(self.corridors):
            A, b = c.unit_walls()
            cs = cors[i]
            cs.first, cs.last = self.ticks[i]
            cs.p, cs.n_poly = c.p, len(c.polygons)
            cs.C = ptr(np.ascontiguousarray(c.C, dtype=float), "const double *")
            cs.row_start = ptr(np.ascontiguousarray(c.row_start, dtype=np.uintp),
                               "const size_t *")
            cs.A = ptr(A, "const double *")
            cs.b = ptr(b, "const double *")
            cs.exit_tick = ptr(self.exit_tick[i], "int32_t *")
            cs.exit_wall = ptr(self.exit_wall[i], "int32_t *")
        return cors, keep


@dataclass
class TickStats:
    """What a `CompiledController.ticker` tick accumulates (saturated ticks per path, the
    extreme commands per input) and writes (the sum of the states after the tick, the
    commands applied to the first ``len(u_rec)`` paths)."""
    saturated: np.ndarray
    u_low: np.ndarray
    u_high: np.ndarray
    x_sum: np.ndarray
    u_rec: np.ndarray           # (recorded paths >= 1, m) float32

    @classmethod
    def zeros(cls, paths: int, n: int, m: int, record: int = 1) -> "TickStats":
        return cls(np.zeros(paths, np.int64), np.full(m, np.inf), np.full(m, -np.inf),
                   np.zeros(n), np.zeros((max(1, min(record, paths)), m), np.float32))
