"""Build the real firmware sources plus generated tables into a cffi module, and load it.

Generate, build and load are separate steps: `generate_c` writes the table sources,
`build_controller` compiles them with ``firmware/src/*.c`` (cached by a hash of everything
that goes into the build), and the returned `CompiledController` steps C instances.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from stospline.firmware_interface import STATUS
from stospline.harness.build import build_harness_module, firmware_dir
from stospline.harness.controller_c import BATCH, VARIANTS, controller_cdef
from stospline.harness.loop_state import CorridorWatch, FaultDraws, TickStats
from stospline.harness.plant_spec import plant_source
from stospline.table.codegen import generate_c
from stospline.table.format import GainTable

__all__ = ["build_controller", "CompiledController", "q_io", "CorridorWatch", "FaultDraws", "TickStats",
           "firmware_dir", "STATUS", "VARIANTS"]


def _positive_count(count) -> int:
    """`count` as an int >= 1 (instances to allocate); ValueError otherwise."""
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 1:
        raise ValueError(f"the number of controller instances must be an integer >= 1, "
                         f"got {count!r}")
    return int(count)


def q_io(table):
    """``(to_q, to_real)`` for a Q15/Q31 table (`stospline.table.qformat.FixedPointTable`):
    ``to_q(X)`` rounds real states X (float64, (count, n)) half up to the table's Q format and
    saturates them at the Q range (as a quantizing sensor would deliver them), as integers of
    the table's type; ``to_real(U)`` is the integer commands times their LSB, float32 (exact
    for Q15, rounded to float32 for Q31), as the harness's plant takes them."""
    F = table.frac_bits
    scale = np.ldexp(1.0, F - np.asarray(table.x_exp, dtype=int))
    lsb = np.asarray(table.u_lsb, dtype=float)
    lo, hi = -(1 << F), (1 << F) - 1
    dtype = VARIANTS[table.arith][1]

    def to_q(X: np.ndarray) -> np.ndarray:
        return np.clip(np.floor(np.asarray(X, dtype=float) * scale + 0.5), lo, hi).astype(dtype)

    def to_real(U: np.ndarray) -> np.ndarray:
        return (U * lsb).astype(np.float32)

    return to_q, to_real


@dataclass
class CompiledController:
    """A compiled firmware + table module, with helpers to run many instances at once."""
    ffi: object
    lib: object
    table: GainTable
    plant_source: str | None = None     # the plant step compiled in (`plant_spec`), if any
    fixed_shape: bool = True

    def for_plant(self, problem) -> "CompiledController":
        """This controller in a module whose plant step is compiled for `problem`
        (`build_controller`'s `plant`): itself when it already is."""
        spec = plant_source(problem, self.table.tick_hz)
        if spec is None or spec == self.plant_source:
            return self
        return build_controller(self.table, fixed_shape=self.fixed_shape, plant=problem)

    @property
    def arith(self) -> str:
        return getattr(self.table, "arith", "float32")

    @property
    def dtype(self):
        """numpy type of x, u and the tables: float32, int16 (Q15) or int32 (Q31)."""
        return VARIANTS[self.arith][1]

    @property
    def c_table(self):
        return self.lib.harness_table()

    def new_instances(self, count: int):
        """`count` instances initialised on the compiled table (raises on a negative status).

        Raises ValueError unless ``count >= 1``: the C helper clones instance 0, and a
        zero-length array has none."""
        count = _positive_count(count)
        ctrls = self.ffi.new("stsp_ctrl_t[]", count)
        worst = self.lib.harness_init_batch(ctrls, count, self.c_table)
        if worst < 0:
            raise RuntimeError(f"stsp_init failed: {self.status_str(worst)}")
        return ctrls

    def status_str(self, status: int) -> str:
        return self.ffi.string(self.lib.stsp_status_str(status)).decode()

    def stepper(self, count: int):
        """Return ``step(tick, X) -> (U, status)`` driving `count` (>= 1) fresh instances."""
        count = _positive_count(count)
        n, m, _ = self.table.dims
        ctrls = self.new_instances(count)
        xbuf = np.zeros((count, n), dtype=self.dtype)
        ubuf = np.zeros((count, m), dtype=self.dtype)
        sbuf = np.zeros(count, dtype=np.intc)
        ffi, lib = self.ffi, self.lib
        px = ffi.cast("const stsp_scalar_t *", ffi.from_buffer(xbuf))
        pu = ffi.cast("stsp_scalar_t *", ffi.from_buffer(ubuf))
        ps = ffi.cast("int *", ffi.from_buffer(sbuf))

        def step(tick: int, X: np.ndarray):
            np.copyto(xbuf, X, casting="same_kind")
            lib.harness_step_batch(ctrls, count, tick, px, pu, ps)
            return ubuf, sbuf

        step.instances = ctrls
        return step

    def real_stepper(self, count: int):
        """``step(tick, X) -> (U, status)`` with real states X (float64, (count, n)) and real
        commands U (float32, (count, m)) whatever the table's arithmetic: `stepper` for a
        float32 table; for a Q15/Q31 one, X rounded half up to its Q format and saturated at
        the Q range (as a quantizing sensor would deliver it) and the integer commands times
        their LSB (exact in float32 for Q15, rounded to it for Q31). The Monte Carlo harness
        runs fixed-point tables through this."""
        step = self.stepper(count)
        if self.arith == "float32":
            return step
        to_q, to_real = q_io(self.table)

        def real(tick: int, X: np.ndarray):
            U, status = step(tick, to_q(X))
            return to_real(U), status

        real.instances = step.instances
        return real

    def pair_steps(self, t_latch, x_latch, tick, x):
        """For each sample k, a fresh instance latches at ``t_latch[k]`` from ``x_latch[k]``
        and is then stepped at ``tick[k]`` with ``x[k]``: returns ``(U, status)``."""
        n, m, _ = self.table.dims
        ffi = self.ffi
        proto = self.new_instances(1)
        arrs = [np.ascontiguousarray(t_latch, np.uint32),
                np.ascontiguousarray(x_latch, self.dtype).reshape(-1, n),
                np.ascontiguousarray(tick, np.uint32),
                np.ascontiguousarray(x, self.dtype).reshape(-1, n)]
        count = len(arrs[0])
        for name, a in zip(("x_latch", "tick", "x"), arrs[1:]):
            if len(a) != count:
                raise ValueError(f"pair_steps: {name} has {len(a)} samples, t_latch {count}")
        U = np.zeros((count, m), dtype=self.dtype)
        status = np.zeros(count, dtype=np.intc)
        self.lib.harness_pair_batch(
            proto, count, ffi.cast("const uint32_t *", ffi.from_buffer(arrs[0])),
            ffi.cast("const stsp_scalar_t *", ffi.from_buffer(arrs[1])),
            ffi.cast("const uint32_t *", ffi.from_buffer(arrs[2])),
            ffi.cast("const stsp_scalar_t *", ffi.from_buffer(arrs[3])),
            ffi.cast("stsp_scalar_t *", ffi.from_buffer(U)),
            ffi.cast("int *", ffi.from_buffer(status)))
        return U, status

    def normals(self, seed: np.random.SeedSequence):
        """``into(out) -> fill()``: a generator of standard normal numbers in C
        (``harness_normals``) seeded by `seed` (its first four 64-bit words); ``fill()``
        refills the float64 array `out` (bound once, so a tick pays one C call)."""
        state = np.ascontiguousarray(seed.generate_state(4, np.uint64))
        if not state.any():
            state[0] = 1                       # xoshiro's one forbidden state
        ffi, lib = self.ffi, self.lib
        pstate = ffi.from_buffer("uint64_t[]", state)

        def into(out: np.ndarray):
            if out.dtype != np.float64 or not out.flags.c_contiguous:
                raise ValueError("normals: out must be a C-contiguous float64 array")
            pout, size = ffi.from_buffer("double[]", out), out.size

            def fill() -> None:
                lib.harness_normals(pstate, pout, size)

            fill.keep = (state, out)
            return fill

        into.state = state                     # the generator's words (`runner` draws too)
        return into

    def runner(self, ctrls, count: int, normals, dZ: np.ndarray, X: np.ndarray,
               cost: np.ndarray, stats: "TickStats", watch: "CorridorWatch | None",
               x_sum: np.ndarray, sample_x: np.ndarray, sample_u: np.ndarray,
               record_x: np.ndarray | None, record_u: np.ndarray | None):
        """``run(j0, j1, plant) -> worst status``: ticks j0 .. j1 - 1 of `count` paths in one
        C call (``harness_run_ticks``; float32 tables, no faults): per tick the plant's
        normal numbers from `normals` (a `normals` generator) into dZ, then what a `ticker`
        tick does, the state sum written to row j + 1 of `x_sum`, path 0 to `sample_x` and
        `sample_u`, the first ``record_x.shape[1]`` paths to `record_x` and `record_u`."""
        ffi, lib = self.ffi, self.lib

        def buf(a, kind="double[]"):
            return ffi.NULL if a is None else ffi.from_buffer(kind, a)

        keep = [normals.state, dZ, X, cost, stats, x_sum, sample_x, sample_u, record_x,
                record_u]
        cors = watch.c_structs(ffi) if watch is not None else (ffi.NULL, None)
        keep.append(cors)
        args = [ffi.from_buffer("uint64_t[]", normals.state), buf(dZ), buf(X), buf(cost),
                ffi.cast("int64_t *", ffi.from_buffer(stats.saturated)),
                buf(stats.u_low), buf(stats.u_high), buf(x_sum),
                buf(stats.u_rec, "float[]"), len(stats.u_rec), cors[0],
                0 if watch is None else len(watch.corridors), buf(sample_x), buf(sample_u),
                buf(record_x, "float[]"), buf(record_u, "float[]"),
                0 if record_x is None else record_x.shape[1]]

        def run(j0: int, j1: int, plant) -> int:
            return lib.harness_run_ticks(ctrls, count, j0, j1, plant.c, *args)

        run.keep = keep
        return run

    def plant(self, stage, Ad, Bd, fd, dt: float, substeps: int):
        """The plant of one stage for `plant_tick`/`tick` (a ``harness_plant_t`` that keeps
        its arrays alive): step matrices Ad, Bd and drift fd (None: none) over dt, `substeps`
        steps per tick."""
        ffi = self.ffi
        GH = stage.noise_tensor                              # multipliers [x; u]
        nz = np.argwhere(GH != 0)                            # rows (i, a, k)
        keep = [np.ascontiguousarray(nz, dtype=np.uintp),
                np.ascontiguousarray(GH[tuple(nz.T)], dtype=float)]
        keep += [np.ascontiguousarray(a, dtype=float) for a in
                 (Ad, Bd, stage.Q, stage.S, stage.q, stage.R, stage.r)]
        n, m = stage.B.shape
        pl = ffi.new("harness_plant_t *")
        pl.n, pl.m, pl.mz, pl.substeps, pl.dt = n, m, stage.G.shape[2], substeps, dt
        pl.dz_scale = float(np.sqrt(dt))
        pl.g_count = len(keep[1])
        pl.g_index = ffi.cast("const size_t *", ffi.from_buffer(keep[0]))
        pl.g_value, pl.Ad, pl.Bd, pl.Q, pl.S, pl.q, pl.R, pl.r = (
            ffi.cast("const double *", ffi.from_buffer(a)) for a in keep[1:])
        pl.rho = float(stage.rho)
        pl.state_cost = int(bool(np.any(stage.Q) or np.any(stage.S) or np.any(stage.q)))
        if fd is None:
            pl.fd = ffi.NULL
        else:
            keep.append(np.ascontiguousarray(fd, dtype=float))
            pl.fd = ffi.cast("const double *", ffi.from_buffer(keep[-1]))
        return _Plant(pl, keep)

    def plant_tick(self, plant, dZ: np.ndarray, U: np.ndarray, X: np.ndarray,
                   cost: np.ndarray) -> None:
        """Advance X (paths, n) in place by one tick of the C plant integrator; dZ (paths,
        substeps, mz) holds standard normal numbers (scaled by sqrt(dt) in C)."""
        ffi = self.ffi
        assert X.flags.c_contiguous and X.dtype == np.float64 and U.dtype == np.float32
        self.lib.harness_plant_tick(plant.c, X.shape[0], ffi.from_buffer("double[]", dZ),
                                    ffi.from_buffer("float[]", U),
                                    ffi.from_buffer("double[]", X),
                                    ffi.from_buffer("double[]", cost))

    def ticker(self, ctrls, count: int, dZ: np.ndarray, X: np.ndarray, cost: np.ndarray,
               stats: "TickStats", faults: "FaultDraws | None" = None,
               watch: "CorridorWatch | None" = None):
        """``tick(j, plant) -> worst status``: one tick of `count` paths in one C call (float32
        tables): the controllers `ctrls` step from X, the plant advances X with dZ, the cost
        and `stats` (`TickStats`) accumulate. With `faults` (``harness_tick_faults``), the
        fault levels, the arrays the caller refills with each tick's random numbers and the
        actuator's held commands. With `watch` (``harness_tick_watch``), each path's first
        exit from the corridors (`CorridorWatch`). The arrays are bound once, here."""
        ffi, lib = self.ffi, self.lib

        def buf(a, kind="double[]"):
            return ffi.NULL if a is None else ffi.from_buffer(kind, a)

        keep = [dZ, X, cost, stats, faults]
        args = [buf(dZ), buf(X), buf(cost),
                ffi.cast("int64_t *", ffi.from_buffer(stats.saturated)),
                buf(stats.u_low), buf(stats.u_high), buf(stats.x_sum),
                buf(stats.u_rec, "float[]"), len(stats.u_rec)]
        step = lib.harness_tick
        if faults is not None:
            f = ffi.new("harness_faults_t *")
            levels = [buf(faults.sensor_std), buf(faults.quantum), buf(faults.actuator_std)]
            f.sensor_std, f.quantum, f.actuator_std = levels
            f.miss_probability = faults.miss_probability
            f.delay_ticks = faults.delay_ticks
            f.feed_held = faults.feed_held
            keep += [f, levels]
            args += [f, buf(faults.sensor_z), buf(faults.actuator_z), buf(faults.miss_u),
                     buf(faults.held)]
            step = lib.harness_tick_faults
        if watch is not None:
            if faults is None:
                args += [ffi.NULL] * 5
            cors = watch.c_structs(ffi)
            keep.append(cors)
            args += [cors[0], len(watch.corridors)]
            step = lib.harness_tick_watch

        def tick(j: int, plant) -> int:
            return step(ctrls, count, j, plant.c, *args)

        tick.keep = keep
        return tick


@dataclass
class _Plant:
    c: object         # harness_plant_t *
    keep: list        # the arrays it points into


# The generated C of recent tables: writing every gain as a shortest float32 literal takes
# about 0.2 s per 100 000 entries, and a run builds the same table's controller more than
# once (the substep pilot, then the run). Keyed by the table object's id; the entry holds the
# table, so the id cannot be reused while cached.
_SOURCES: dict = {}


def _table_sources(table) -> tuple[str, str]:
    hit = _SOURCES.get(id(table))
    if hit is not None and hit[0] is table:
        return hit[1]
    if len(_SOURCES) >= 4:
        _SOURCES.clear()
    text = generate_c(table)
    _SOURCES[id(table)] = (table, text)
    return text


def build_controller(table: GainTable, *, build_dir: str | Path | None = None,
                     quiet: bool = True, fixed_shape: bool = True,
                     plant=None) -> CompiledController:
    """Compile ``firmware/src/*.c`` with the table's generated C into a cffi module and load it.

    Builds are cached in `build_dir` (default: `stospline.cache.cache_root`) under a hash of
    every input (sources, flags, table), built atomically (`stospline.cache.cached_build`).

    Parameters
    ----------
    table : GainTable or FixedPointTable
        The firmware is compiled for the table's arithmetic.
    build_dir : str or Path, optional
    quiet : bool
        Hide the compiler's output.
    fixed_shape : bool
        True (default): the firmware's fixed-shape build for the table's dimensions
        (``STSP_FIXED_NX/NU/N_LATCH``, the fastest; it refuses a table of another shape).
        False: the generic build, which takes any table within the ``STSP_MAX_*`` limits.
        Both compute the same bits.
    plant : Problem, optional
        The plant the Monte Carlo harness will run: its step is compiled for it
        (`stospline.harness.plant_spec`: its zero and unit coefficients and noise entries
        built in), the same bits as the generic step, which still serves any other plant.

    Returns
    -------
    CompiledController
        ``stepper(count)`` gives ``step(tick, X) -> (U, status)`` over `count` instances of
        the real ``stsp_step``.

    Examples
    --------
    >>> import numpy as np, stospline
    >>> p = stospline.load_problem("examples/robot_corridor.toml")
    >>> ctl = stospline.build_controller(stospline.design_problem(p).table)
    >>> step = ctl.stepper(1)                      # one controller instance
    >>> u, status = step(0, p.x0[None, :].astype(np.float32))
    >>> u.shape, ctl.status_str(int(status[0]))    # the t0 tick latches and commands
    ((1, 2), 'ok')
    """
    header, source = _table_sources(table)
    arith = getattr(table, "arith", "float32")
    # The module serves this one table: its dimensions are compile-time constants of the
    # plant (HARNESS_N/M) and, by default, of the controller (the firmware's fixed-shape build,
    # which computes the same bits as the generic one; both are tested by ctest and QEMU).
    n, m, n_latch = table.dims
    cdef = controller_cdef(arith)
    n_plant = n - m * getattr(table, "delay_ticks", 0)   # a delayed law also measures u
    cflags = VARIANTS[arith][2] + [f"-DHARNESS_N={n_plant}", f"-DHARNESS_M={m}"]
    if fixed_shape:
        cflags += [f"-DSTSP_FIXED_NX={n}u", f"-DSTSP_FIXED_NU={m}u",
                   f"-DSTSP_FIXED_N_LATCH={n_latch}u"]
    spec = None if plant is None else plant_source(plant, table.tick_hz)
    loop_files = {}
    if spec is not None:
        cflags.append("-DHARNESS_PLANT_SPEC")
        loop_files["plant_spec.h"] = spec
    # The loops do not read the table (the module hands it over through harness_table), so
    # their object serves every table of this shape, arithmetic and plant.
    mod = build_harness_module(
        f"_stsp_{table.name}", {f"{table.name}.h": header, f"{table.name}.c": source}, cdef,
        f'#include "stospline/stsp_controller.h"\n#include "plant.h"\n#include "batch.h"\n'
        f'#include "{table.name}.h"\n'
        f"const stsp_table_t *harness_table(void) {{ return &{table.name}_table; }}\n",
        cflags, loop=('#include "stospline/stsp_controller.h"\n' + BATCH, loop_files),
        plant_included=True, build_dir=build_dir, quiet=quiet)
    return CompiledController(mod.ffi, mod.lib, table, spec, fixed_shape)
