"""Compile the firmware, generated C and the harness's own C into one cffi module, and load it.

`build_harness_module` is the one build of the harness: the controller (`controller`), the
estimator loop (`estimator_loop`) and the parametric loop (`params_loop`) each give it their
generated files, declarations and loop code. The firmware is ``firmware/src/*.c``
(`firmware_dir`); the harness's plant and normal generator (``plant.c``, ``normals.c``) are
compiled in, either as their own translation units or included by the loop code. Builds are
cached under a hash of every input (`stospline.cache.cached_build`). The firmware's objects
depend only on its sources and the flags of its build (arithmetic, fixed shape), not on the
table or the plant, so they are compiled once per such build and linked into every module
that shares it (`firmware_objects`).
"""
from __future__ import annotations

import re
from pathlib import Path
from typing import Callable

from stospline.cache import cached_build, compile_cffi, compile_objects, load_module, source_key
from stospline.firmware_interface import check_header

__all__ = ["build_harness_module", "firmware_dir", "firmware_objects", "loop_object",
           "HARNESS_CFLAGS", "PLANT_CDEF", "BATCH_CDEF"]

HERE = Path(__file__).parent
# The plant's interface (plant.h), for cffi: the header itself, without its comments.
PLANT_H = HERE / "plant.h"
PLANT_CDEF = re.sub(r"/\*.*?\*/", "", PLANT_H.read_text(), flags=re.S)
# The loops' declarations (batch.h), for cffi likewise.
BATCH_CDEF = re.sub(r"/\*.*?\*/", "", (HERE / "batch.h").read_text(), flags=re.S)
# The harness's C besides the loop code: every build's key covers all of it.
HARNESS_C = [HERE / "plant.c", HERE / "normals.c", PLANT_H, HERE / "batch.h",
             HERE / "ziggurat_tables.h"]

# -O3 as the host CMake build (Release); ISO C keeps floating-point contraction off, so the
# bits are those of any other build. Without the vectorizers: they moved the plant's small
# fixed-size state through the stack in 16-byte pieces written as 8-byte ones (a failed
# store-to-load forwarding per path, a third of the plant's time); they reorder no sums.
HARNESS_CFLAGS = ["-std=c99", "-O3", "-fno-tree-slp-vectorize", "-fno-tree-loop-vectorize",
                  "-Wall", "-Wextra", "-DSTSP_HOST_MESSAGES"]


def firmware_dir() -> Path:
    """The firmware source tree compiled by the harness (``STOSPLINE_FIRMWARE`` overrides;
    `stospline.firmware_files`)."""
    from stospline.firmware_files import firmware_dir as find
    return find()


def build_harness_module(modname: str, files: dict[str, str], cdef: str, source: str,
                         cflags: list[str], *, loop: tuple[str, dict[str, str]] | None = None,
                         plant_included: bool = False, build_dir: str | Path | None = None,
                         quiet: bool = True):
    """Compile and load (cached) the module ``{modname}_{key}``.

    `files` are the generated files written beside the build (name -> text; the ``.c`` ones
    are compiled), `cdef` the declarations cffi sees, `source` the module's own C (it includes
    the firmware's and the generated headers it needs), `cflags` the compiler flags after
    `HARNESS_CFLAGS`. `loop`, optional, is ``(text, its files)``: C that does not depend on
    `files`, compiled once into an object per text, files and flags (`loop_object`) and
    linked in. With `plant_included` the module's C includes ``plant.c`` (its step then
    inlines into the loop), else ``plant.c`` is compiled as its own translation unit.
    Returns the loaded module (``.ffi``, ``.lib``).
    """
    fw = firmware_dir()
    check_header(fw / "include")   # the shared constants are still the header's
    flags = HARNESS_CFLAGS + list(cflags)
    loop_text, loop_files = loop if loop is not None else ("", {})
    # With the loops in an object, what remains is the table's data and cffi's thin
    # wrappers: -O1 builds them in half the time of -O3, and no path-tick runs in them.
    module_flags = flags + (["-O1"] if loop is not None else [])
    key = source_key([f"{name}\n{text}" for name, text in sorted(files.items())]
                     + [f"{name}\n{text}" for name, text in sorted(loop_files.items())]
                     + [cdef, source, loop_text, " ".join(module_flags)]
                     + [p.read_bytes() for p in _inputs(fw)])
    full = f"{modname}_{key}"
    harness = [] if plant_included else [HERE / "plant.c"]

    def build(out: Path) -> Path:
        for name, text in files.items():
            (out / name).write_text(text)
        generated = [out / name for name in sorted(files) if name.endswith(".c")]
        objects = firmware_objects(fw, flags, build_dir=build_dir)
        if loop is not None:
            objects.append(loop_object(fw, loop_text, loop_files, flags, build_dir=build_dir))
        return compile_cffi(out, full, cdef, source, sources=[*generated, *harness],
                            include_dirs=[fw / "include", fw / "src", out, HERE],
                            cflags=module_flags, objects=objects, quiet=quiet)

    return load_module(cached_build(key, full, build, root=build_dir))


def _inputs(fw: Path) -> list[Path]:
    """Every file a harness build may include or compile besides the generated ones."""
    return sorted(fw.rglob("*.[ch]")) + HARNESS_C


def _cached_objects(key: str, sources: Callable[[Path], list[Path]], include_dirs,
                    flags: list[str], build_dir) -> list[Path]:
    """The objects of ``sources(out)`` (the C files to compile, written into `out` if they
    are generated) compiled with `flags`, cached under `key` (a hash of every input)."""
    listing = "objects.txt"

    def build(out: Path) -> Path:
        objects = compile_objects(out, sources(out), include_dirs=[*include_dirs, out],
                                  cflags=flags)
        (out / listing).write_text("".join(f"{o.name}\n" for o in objects))
        return out / listing

    def find(directory: Path) -> Path | None:
        return directory / listing if (directory / listing).is_file() else None

    done = cached_build(key, listing, build, root=build_dir, find=find)
    return [done.parent / name for name in done.read_text().split()]


def firmware_objects(fw: Path, flags: list[str], *,
                     build_dir: str | Path | None = None) -> list[Path]:
    """The object files of ``firmware/src/*.c`` and the normal generator for `flags` without
    the harness's own macros (``-DHARNESS_*``, which the firmware does not read)."""
    flags = [f for f in flags if not f.startswith("-DHARNESS_")]
    sources = sorted((fw / "src").glob("*.c")) + [HERE / "normals.c"]
    key = source_key([" ".join(flags)] + [p.read_bytes() for p in _inputs(fw)])
    return _cached_objects(f"fw-{key}", lambda out: sources,
                           [fw / "include", fw / "src", HERE], flags, build_dir)


def loop_object(fw: Path, text: str, files: dict[str, str], flags: list[str], *,
                build_dir: str | Path | None = None) -> Path:
    """The object of the loop code `text` (``harness_loop.c``) with the generated `files` it
    includes written beside it, compiled with `flags`."""
    key = source_key([text, " ".join(flags)]
                     + [f"{name}\n{body}" for name, body in sorted(files.items())]
                     + [p.read_bytes() for p in _inputs(fw)])

    def sources(out: Path) -> list[Path]:
        for name, body in files.items():
            (out / name).write_text(body)
        (out / "harness_loop.c").write_text(text)
        return [out / "harness_loop.c"]

    (obj,) = _cached_objects(f"loop-{key}", sources, [fw / "include", fw / "src", HERE],
                             flags, build_dir)
    return obj
