"""The Python locks, host/requirements-py3.X.lock, one per CPython minor version
(tools/lock_deps.sh): each pins every declared dependency within its range, with hashes; a package
in two locks has one version (the same numeric libraries are what make gains/ regenerate byte for
byte on every Python); each lock's wheels download from PyPI for its Python on x86-64 and arm64
and match its hashes (the last test needs PyPI: 7-11 s per lock and machine, about 1 min for all
six on a busy 2-core machine, pip's cache warm or not)."""
import itertools
import re
import subprocess
import sys
import tomllib

import pytest
from packaging.requirements import Requirement
from packaging.specifiers import SpecifierSet

from conftest import REPO
from support.locks import committed_versions, lock_path, read_lock

VERSIONS = committed_versions()
# What computes the tables: a different version of any may move gains/ in its last bits.
NUMERIC = ("numpy", "scipy", "cffi", "osqp")
META = tomllib.loads((REPO / "host" / "pyproject.toml").read_text())


def _pins(version: str) -> dict[str, str]:
    return {name: v for name, (v, _) in read_lock(lock_path(version)).items()}


def test_the_script_writes_exactly_the_committed_locks():
    script = (REPO / "tools" / "lock_deps.sh").read_text()
    assert re.search(r"^versions=\(([^)]*)\)", script, re.M)[1].split() == VERSIONS
    assert len(VERSIONS) >= 3


def test_every_lock_is_for_a_python_the_package_accepts():
    requires = SpecifierSet(META["project"]["requires-python"])
    assert all(requires.contains(f"{v}.0") for v in VERSIONS)


@pytest.mark.parametrize("version", VERSIONS)
def test_every_locked_package_has_hashes(version):
    locked = read_lock(lock_path(version))
    assert len(locked) > 20
    assert all(hashes for _, hashes in locked.values())
    assert f"for CPython {version} " in lock_path(version).read_text()


@pytest.mark.parametrize("version", VERSIONS)
def test_every_declared_dependency_is_locked_within_its_range(version):
    locked = _pins(version)
    declared = (META["project"]["dependencies"] + META["project"]["optional-dependencies"]["test"]
                + META["build-system"]["requires"])
    for req in map(Requirement, declared):
        name = re.sub(r"[-_.]+", "-", req.name).lower()
        assert name in locked, \
            f"{req.name} is not in {lock_path(version).name}: run tools/lock_deps.sh"
        assert req.specifier.contains(locked[name]), \
            f"{req.name}=={locked[name]} is outside {req.specifier} ({lock_path(version).name})"


@pytest.mark.parametrize("name", NUMERIC)
def test_the_numeric_stack_is_in_every_lock(name):
    assert all(name in _pins(v) for v in VERSIONS)


def test_a_package_in_two_locks_has_one_version():
    # The sets of names may differ: a dependency under an environment marker (dask's
    # `importlib_metadata; python_version < "3.12"`) is locked only for the Pythons that need it.
    for a, b in itertools.combinations(VERSIONS, 2):
        pa, pb = _pins(a), _pins(b)
        differ = {n: (pa[n], pb[n]) for n in pa.keys() & pb.keys() if pa[n] != pb[n]}
        assert not differ, f"versions differ between the {a} and {b} locks: {differ}"


def _platforms(arch: str) -> list[str]:
    """The manylinux tags tools/lock_deps.sh resolves for (a glibc 2.36 machine)."""
    tags = [f"manylinux_2_{minor}_{arch}" for minor in range(36, 16, -1)]
    return [arg for tag in tags + [f"manylinux2014_{arch}"] for arg in ("--platform", tag)]


@pytest.mark.parametrize("arch", ["x86_64", "aarch64"])
@pytest.mark.parametrize("version", VERSIONS)
def test_lock_downloads_for_its_python(version, arch, tmp_path):
    """pip finds a wheel of every pinned version for this Python and machine, and its hash is in
    the lock (pip's cache makes a second run cheap; the hashes are checked all the same)."""
    lock = lock_path(version)
    run = subprocess.run(
        [sys.executable, "-m", "pip", "download", "--quiet", "--disable-pip-version-check",
         "--no-deps", "--only-binary=:all:", "--implementation", "cp", "--python-version", version,
         *_platforms(arch), "--require-hashes", "--dest", str(tmp_path), "-r", str(lock)],
        capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stderr[-3000:]
    assert len(list(tmp_path.glob("*.whl"))) == len(read_lock(lock))
