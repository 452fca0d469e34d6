"""As a new user outside the repository: build the wheel (and the sdist, and a wheel from the
sdist), install it into a fresh venv in a temporary directory, and run `stospline design`,
`simulate` and `plot` from a directory that is not the repository, with no STOSPLINE_FIRMWARE:
the wheel carries the firmware sources, and the cffi builds go to the user cache directory.

Offline: the wheel is built with this venv's setuptools (no build isolation) and installed
without dependencies; the fresh venv sees this venv's installed dependencies (numpy, scipy,
cffi, ...) through a .pth file, but not its (editable) stospline.
"""
import json
import os
import shutil
import subprocess
import sys
import sysconfig
import tarfile
import zipfile
from pathlib import Path

import pytest

import stospline

from conftest import EXAMPLES, REPO

VERSION = (REPO / "VERSION").read_text().strip()
FIRMWARE_FILES = sorted(
    str(p.relative_to(REPO / "firmware")) for p in
    [*(REPO / "firmware" / "src").glob("*.[ch]"), *(REPO / "firmware" / "include").rglob("*.h")])


def run(cmd, **kw):
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=300, **kw)
    assert res.returncode == 0, f"{cmd}\n{res.stdout}\n{res.stderr}"
    return res.stdout


@pytest.fixture(scope="module")
def wheel(tmp_path_factory):
    """A copy of host/ and firmware/ (the build writes its egg-info and build/ there, not in
    the checkout), its wheel and sdist, and a wheel built from that sdist."""
    tmp = tmp_path_factory.mktemp("pkg")
    src = tmp / "src"
    shutil.copytree(REPO / "host", src / "host",
                    ignore=shutil.ignore_patterns("*.egg-info", "build", "__pycache__",
                                                  "_firmware"))
    shutil.copytree(REPO / "firmware", src / "firmware")
    shutil.copy(REPO / "VERSION", src / "VERSION")
    pip = [sys.executable, "-m", "pip", "--disable-pip-version-check", "-q"]
    run([*pip, "wheel", "--no-deps", "--no-build-isolation", "-w", str(tmp / "wheel"),
         str(src / "host")])
    run([sys.executable, "-c", "import sys; from setuptools import build_meta; "
         "build_meta.build_sdist(sys.argv[1])", str(tmp / "sdist")], cwd=src / "host")
    (sdist,) = (tmp / "sdist").glob("stospline-*.tar.gz")
    run([*pip, "wheel", "--no-deps", "--no-build-isolation", "-w", str(tmp / "from_sdist"),
         str(sdist)])
    (whl,) = (tmp / "wheel").glob("stospline-*.whl")
    (whl2,) = (tmp / "from_sdist").glob("stospline-*.whl")
    return whl, sdist, whl2


PACKAGE = Path(stospline.__file__).parent


def test_wheel_and_sdist_carry_the_firmware(wheel):
    whl, sdist, whl2 = wheel
    for w in (whl, whl2):
        names = zipfile.ZipFile(w).namelist()
        have = sorted(n.split("stospline/_firmware/", 1)[1] for n in names
                      if "stospline/_firmware/" in n)
        assert have == FIRMWARE_FILES, w.name
        assert "stospline/design/tick_kernel.c" in names and "stospline/harness/plant.c" in names
        assert "stospline/table/compose_kernel.c" in names
        assert "stospline/table/qspline_kernel.c" in names
        assert "stospline/table/literal_kernel.c" in names
        assert "stospline/report/templates/report.html.j2" in names     # the report page
        # Every module of the source tree is in the wheel (a package missing from the build's
        # list would install and then fail at its first import).
        source = {f"stospline/{p.relative_to(PACKAGE).as_posix()}"
                  for p in PACKAGE.rglob("*.py") if "_firmware" not in p.parts}
        assert sorted(source - set(names)) == [], w.name
        data = {f"stospline/{p.relative_to(PACKAGE).as_posix()}"
                for p in PACKAGE.rglob("*") if p.suffix in (".c", ".h", ".j2", ".ld")
                and "_firmware" not in p.parts}
        assert sorted(data - set(names)) == [], w.name
    with tarfile.open(sdist) as tar:
        members = [m.split("stospline/_firmware/", 1)[1] for m in tar.getnames()
                   if "stospline/_firmware/" in m and m.endswith((".c", ".h"))]
    assert sorted(members) == FIRMWARE_FILES
    for w in (whl, whl2):
        assert w.name.startswith(f"stospline-{VERSION}-"), w.name


def test_installed_wheel_designs_simulates_and_plots_outside_the_repo(wheel, tmp_path):
    whl = wheel[0]
    venv = tmp_path / "venv"
    run([sys.executable, "-m", "venv", "--without-pip", str(venv)])
    py = venv / "bin" / "python"
    run([sys.executable, "-m", "pip", "--disable-pip-version-check", "-q", "--python", str(py),
         "install", "--no-deps", "--no-index", str(whl)])
    site = Path(run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"])
                .strip())
    (site / "_repo_venv_deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")

    work = tmp_path / "elsewhere"
    work.mkdir()
    shutil.copy(EXAMPLES / "robot_bands.toml", work / "robot.toml")
    env = {k: v for k, v in os.environ.items()
           if k not in ("STOSPLINE_FIRMWARE", "STOSPLINE_CACHE_DIR", "STOSPLINE_BUILD",
                        "PYTHONPATH", "VIRTUAL_ENV")}
    env.update(HOME=str(tmp_path / "home"), XDG_CACHE_HOME=str(tmp_path / "xdg"),
               MPLBACKEND="Agg")
    exe = str(venv / "bin" / "stospline")

    where = run([str(py), "-c", "import stospline, stospline.firmware_files as f; "
                 "print(stospline.__file__); print(f.firmware_dir())"], cwd=work, env=env)
    pkg, fw = (Path(line) for line in where.split())
    assert pkg.is_relative_to(venv) and fw.is_relative_to(venv), where
    assert run([exe, "--version"], cwd=work, env=env).strip() == f"stospline {VERSION}"

    out = run([exe, "design", "robot.toml", "--out", "gains"], cwd=work, env=env)
    assert "J0 (designed)" in out and "flash of the tables" in out
    assert sorted(p.name for p in (work / "gains").iterdir()) == [
        "robot_bands.c", "robot_bands.h", "robot_bands.json"]

    sim = json.loads(run([exe, "simulate", "robot.toml", "--paths", "40", "--json"],
                         cwd=work, env=env))
    assert sim["paths"] == 40 and sim["worst_status"] >= 0

    out = run([exe, "plot", "robot.toml", "--out", "robot.png", "--paths", "5"], cwd=work,
              env=env)
    assert (work / "robot.png").stat().st_size > 1000 and "wrote robot.png" in out

    out = run([exe, "report", "robot.toml", "--out", "robot.html", "--paths", "5",
               "--fault-paths", "0"], cwd=work, env=env)
    assert "<h1>robot_bands</h1>" in (work / "robot.html").read_text(encoding="utf-8")

    cached = list((tmp_path / "xdg" / "stospline" / "cffi").iterdir())
    assert len(cached) >= 2, cached         # the design kernels and the firmware + table
    assert not (site / "stospline" / "build").exists()
