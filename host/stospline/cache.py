"""Where compiled cffi modules are cached, and how one is built into the cache safely.

Builds live in ``<cache root>/<key>/`` where `key` is a hash of every input of the build, so
a changed source never loads a stale module. The root is, in order: ``STOSPLINE_CACHE_DIR``,
``STOSPLINE_BUILD`` (older name, same meaning), else the user cache directory
(``platformdirs.user_cache_dir("stospline")/cffi``, e.g. ``~/.cache/stospline/cffi``).

A build happens in a private temporary directory beside its final place and is then renamed
into place in one step, so a reader never sees a half-written module, and two processes that
build the same key at once both succeed: the second rename fails, and that process uses the
winner's module (identical, as the inputs are).
"""
from __future__ import annotations

import hashlib
import os
import threading
from pathlib import Path
from typing import Callable, Iterable

from stospline.errors import KernelBuildError, StosplineError

__all__ = ["cache_root", "source_key", "cached_build", "compile_cffi", "load_module",
           "compile_objects", "build_source_module", "build_kernel_sources", "KERNEL_CFLAGS", "LoadOnce",
           "CompilerMissing", "FallbackWarning", "c_compiler"]

# The flags of the host kernels (double-precision C of the designer, the oracle, the table).
KERNEL_CFLAGS = ["-std=c99", "-O3", "-Wall", "-Wextra"]


class CompilerMissing(StosplineError, RuntimeError):
    """A C module had to be built and there is no C compiler (``CC``, else the one Python was
    built with, not found on ``PATH``). ``compiler`` names what was looked for."""

    def __init__(self, compiler: str):
        super().__init__(f"no C compiler: {compiler!r} is not found (set CC, or install one, "
                         f"e.g. apt-get install gcc)")
        self.compiler = compiler


class FallbackWarning(RuntimeWarning):
    """A compiled host kernel could not be built, so its numpy reference runs instead (the
    same computation, slower): information, not a numerical problem."""


def c_compiler() -> tuple[str, bool]:
    """``(compiler, found)``: the compiler cffi's build runs (``CC``, else Python's own) and
    whether it is on ``PATH``."""
    import shlex
    import shutil
    import sysconfig
    cc = os.environ.get("CC") or sysconfig.get_config_var("CC") or "cc"
    try:
        exe = shlex.split(cc)[0]
    except (ValueError, IndexError):
        return cc, False
    return exe, shutil.which(exe) is not None


def cache_root() -> Path:
    """The directory under which every cffi build is cached (see the module docstring)."""
    for var in ("STOSPLINE_CACHE_DIR", "STOSPLINE_BUILD"):
        env = os.environ.get(var)
        if env:
            return Path(env)
    from platformdirs import user_cache_dir
    return Path(user_cache_dir("stospline")) / "cffi"


def source_key(blobs: Iterable[bytes | str]) -> str:
    """A 16-hex-digit SHA-256 of the build inputs, in order."""
    digest = hashlib.sha256()
    for blob in blobs:
        data = blob.encode() if isinstance(blob, str) else blob
        digest.update(len(data).to_bytes(8, "little"))   # "ab"+"c" differs from "a"+"bc"
        digest.update(data)
    return digest.hexdigest()[:16]


def _find(directory: Path, modname: str) -> Path | None:
    found = sorted(directory.glob(f"{modname}*.so")) + sorted(directory.glob(f"{modname}*.pyd"))
    return found[0] if found else None


def cached_build(key: str, modname: str, build: Callable[[Path], Path], *,
                 root: str | Path | None = None,
                 find: Callable[[Path], Path | None] | None = None) -> Path:
    """The path of the extension module `modname` cached under `key`, built on first use.

    `build(tmpdir)` compiles into the empty directory `tmpdir` and returns the module's path
    (inside `tmpdir`). It runs only when the key is not cached yet; its directory is renamed
    to ``<root>/<key>`` afterwards, or discarded if another process got there first.
    `find(directory)` locates the build's product in a cached directory (None: not there);
    by default the extension module `modname`.
    """
    if find is None:
        def find(directory: Path) -> Path | None:
            return _find(directory, modname)
    base = Path(root) if root is not None else cache_root()
    final = base / key
    hit = find(final) if final.is_dir() else None
    if hit is not None:
        return hit
    import shutil
    import tempfile
    base.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{key}.tmp-", dir=base))
    try:
        built = Path(build(tmp))
        name = built.relative_to(tmp)
        for _ in range(2):
            try:
                os.rename(tmp, final)      # atomic; fails if `final` exists (not empty)
                return final / name
            except OSError:
                hit = find(final) if final.is_dir() else None
                if hit is not None:        # another process built the same key first
                    return hit
                shutil.rmtree(final, ignore_errors=True)   # a leftover without a module
        os.rename(tmp, final)
        return final / name
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def compile_cffi(out: Path, modname: str, cdef: str, source: str, *, sources=(),
                 include_dirs=(), cflags=(), objects=(), quiet: bool = True) -> Path:
    """Build step of `cached_build`: compile a cffi API-mode module in `out` and return its
    path. `cdef` declares what Python calls, `source` is the C text cffi wraps (its includes),
    `sources` further C files compiled into the module, `objects` object files linked in
    (`compile_objects`)."""
    import cffi
    ffib = cffi.FFI()
    ffib.cdef(cdef)
    ffib.set_source(modname, source, sources=[str(s) for s in sources],
                    include_dirs=[str(d) for d in include_dirs], extra_compile_args=list(cflags),
                    extra_objects=[str(o) for o in objects])
    try:
        return Path(ffib.compile(tmpdir=str(out), verbose=not quiet))
    except Exception:
        compiler, found = c_compiler()
        if not found:                # the usual cause on a bare machine: say so plainly
            raise CompilerMissing(compiler) from None
        raise


def compile_objects(out: Path, sources, *, include_dirs=(), cflags=()) -> list[Path]:
    """Compile the C files `sources` into ``out/<stem>.o`` with the compiler, flags and
    position-independent code of a cffi build (the objects `compile_cffi` would build for
    them), for linking into several modules (its ``objects=``). Returns their paths, in the
    order of `sources`."""
    import cffi._shimmed_dist_utils as dist   # distutils (setuptools' on 3.12+), as cffi's
    from distutils.ccompiler import new_compiler
    cc = new_compiler()
    dist.sysconfig.customize_compiler(cc)
    objects = []
    for source in map(Path, sources):
        try:
            built = cc.compile([str(source)], output_dir=str(out / "tmp"),
                               include_dirs=[str(d) for d in include_dirs],
                               extra_postargs=list(cflags))
        except Exception:
            compiler, found = c_compiler()
            if not found:
                raise CompilerMissing(compiler) from None
            raise
        target = out / f"{source.stem}.o"
        os.replace(built[0], target)
        objects.append(target)
    import shutil
    shutil.rmtree(out / "tmp", ignore_errors=True)
    return objects


def load_module(path: Path):
    """Load step: the extension module at `path` (once per process; later calls return the
    loaded module)."""
    import importlib.util
    import sys
    modname = Path(path).name.split(".")[0]
    mod = sys.modules.get(modname)
    if mod is None:
        spec = importlib.util.spec_from_file_location(modname, path)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        sys.modules[modname] = mod
    return mod


def build_source_module(prefix: str, source: bytes, cdef: str, cflags: list[str], *,
                        root: str | Path | None = None, quiet: bool = True) -> Path:
    """The path of the cffi module of one C `source` (wrapped as is, `cdef` its declarations),
    cached under the hash of source, declarations and flags (`cached_build`) as
    ``<prefix>_<key>``: the host kernels of the designer and of the table layer."""
    key = source_key([source, cdef, " ".join(cflags)])
    modname = f"{prefix}_{key}"

    def build(out: Path) -> Path:
        return compile_cffi(out, modname, cdef, source.decode(), cflags=cflags, quiet=quiet)

    return cached_build(key, modname, build, root=root)


def build_kernel_sources(prefix: str, sources: Iterable[Path], cdef: str,
                         cflags: list[str] = KERNEL_CFLAGS, *, root: str | Path | None = None,
                         quiet: bool = True) -> Path:
    """`build_source_module` of the C files `sources` joined into one text: the host kernels
    of the designer, the oracle and the table layer. Any failure (a missing file, no
    compiler, no cffi) is a `KernelBuildError` that names the files."""
    sources = list(sources)
    try:
        source = b"\n".join(p.read_bytes() for p in sources)
        return build_source_module(prefix, source, cdef, cflags, root=root, quiet=quiet)
    except Exception as exc:  # noqa: BLE001 - any failure here means "no compiled kernel"
        names = ", ".join(p.name for p in sources)
        raise KernelBuildError(f"cannot build {names}: {exc}") from exc


class LoadOnce:
    """``loader()``: the module at ``build()`` (`load_module`), built and loaded on the first
    call, once, whichever thread asks first."""

    def __init__(self, build: Callable[[], Path]):
        self._build = build
        self._module = None
        self._lock = threading.Lock()

    def __call__(self):
        with self._lock:
            if self._module is None:
                self._module = load_module(self._build())
        return self._module
