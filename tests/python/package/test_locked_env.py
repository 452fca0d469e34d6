"""The venv is host/requirements.lock, exactly (tools/setup.sh builds it from the lock), and the
lock covers every dependency host/pyproject.toml declares: two machines run the same versions."""
import re
import sysconfig
import tomllib
from importlib import metadata

from packaging.requirements import Requirement

from conftest import REPO

LOCK = REPO / "host" / "requirements.lock"


def _name(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def _locked() -> dict[str, tuple[str, list[str]]]:
    """name -> (version, hashes) of every entry of the lock."""
    out = {}
    for entry in re.split(r"\n(?=\S)", LOCK.read_text()):
        m = re.match(r"([A-Za-z0-9_.-]+)==(\S+)", entry)
        if m:
            out[_name(m[1])] = (m[2], re.findall(r"--hash=sha256:([0-9a-f]{64})", entry))
    return out


def test_every_locked_package_has_hashes():
    locked = _locked()
    assert len(locked) > 20
    assert all(hashes for _, hashes in locked.values())


def test_installed_packages_are_exactly_the_locked_ones():
    locked = {n: v for n, (v, _) in _locked().items()}
    # The venv's own site-packages only (setuptools puts its vendored packages on sys.path).
    site = [sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]]
    installed = {_name(d.metadata["Name"]): d.version for d in metadata.distributions(path=site)}
    installed.pop("stospline")
    assert installed == locked, "the venv is not host/requirements.lock: run tools/setup.sh"


def test_every_declared_dependency_is_locked_within_its_range():
    locked = {n: v for n, (v, _) in _locked().items()}
    meta = tomllib.loads((REPO / "host" / "pyproject.toml").read_text())
    declared = (meta["project"]["dependencies"] + meta["project"]["optional-dependencies"]["test"]
                + meta["build-system"]["requires"])
    for req in map(Requirement, declared):
        assert _name(req.name) in locked, f"{req.name} is not locked: run tools/lock_deps.sh"
        assert req.specifier.contains(locked[_name(req.name)]), \
            f"{req.name}=={locked[_name(req.name)]} is outside {req.specifier}"
