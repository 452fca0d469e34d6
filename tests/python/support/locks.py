"""The Python locks, host/requirements-py3.X.lock (tools/lock_deps.sh writes them)."""
import re
from pathlib import Path

HOST = Path(__file__).resolve().parents[3] / "host"


def lock_path(version: str) -> Path:
    """The lock for CPython `version` ("3.12")."""
    return HOST / f"requirements-py{version}.lock"


def committed_versions() -> list[str]:
    """The Python versions that have a lock, oldest first."""
    found = [re.fullmatch(r"requirements-py(3\.\d+)\.lock", p.name) for p in HOST.iterdir()]
    return sorted((m[1] for m in found if m), key=lambda v: tuple(map(int, v.split("."))))


def normalise(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def read_lock(path: Path) -> dict[str, tuple[str, list[str]]]:
    """name -> (version, hashes) of every entry of a lock."""
    out = {}
    for entry in re.split(r"\n(?=\S)", path.read_text()):
        m = re.match(r"([A-Za-z0-9_.-]+)==(\S+)", entry)
        if m:
            out[normalise(m[1])] = (m[2], re.findall(r"--hash=sha256:([0-9a-f]{64})", entry))
    return out
