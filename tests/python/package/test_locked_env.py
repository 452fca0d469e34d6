"""The venv is the lock of its Python, host/requirements-py3.X.lock, exactly (tools/setup.sh
builds it from the lock): two machines run the same versions. The locks themselves:
test_locks.py."""
import sys
import sysconfig
from importlib import metadata

from support.locks import lock_path, normalise, read_lock

LOCK = lock_path(f"{sys.version_info[0]}.{sys.version_info[1]}")


def test_installed_packages_are_exactly_the_locked_ones():
    locked = {n: v for n, (v, _) in read_lock(LOCK).items()}
    # The venv's own site-packages only (setuptools puts its vendored packages on sys.path).
    site = [sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]]
    installed = {normalise(d.metadata["Name"]): d.version
                 for d in metadata.distributions(path=site)}
    installed.pop("stospline")
    assert installed == locked, f"the venv is not {LOCK.name}: run tools/setup.sh"
