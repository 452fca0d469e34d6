"""Shared by the board tests: cross-build and install the stospline package for a core, then
generate and cross-build a board's project for the robot corridor (-Werror inside)."""
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]
TOOLS = ("arm-none-eabi-gcc", "qemu-system-arm", "cmake", "ninja")
needs_tools = pytest.mark.skipif(any(shutil.which(t) is None for t in TOOLS),
                                 reason="needs arm-none-eabi-gcc, qemu-system-arm, cmake, "
                                        "ninja (tools/setup.sh installs them)")
ENV = {**os.environ, "PYTHONPATH": str(ROOT / "host")}


def build_project(tmp_path: Path, board: str, cpu: str, arith: str) -> Path:
    """The project's directory; its image is build/qemu/firmware.elf."""
    prefix, build, proj = tmp_path / "stsp", tmp_path / "lib", tmp_path / "proj"
    subprocess.run(["cmake", "-S", str(ROOT), "-B", str(build), "-G", "Ninja",
                    f"-DCMAKE_TOOLCHAIN_FILE={ROOT}/tools/arm/arm-none-eabi.cmake",
                    f"-DSTSP_ARM_CPU={cpu}", f"-DSTSP_ARITH={arith}",
                    "-DCMAKE_BUILD_TYPE=Release", "-DCMAKE_C_FLAGS_RELEASE=-O2",
                    "-DSTSP_BUILD_TESTS=OFF", "-DSTSP_INSTALL=ON"], check=True,
                   capture_output=True)
    subprocess.run(["cmake", "--build", str(build)], check=True, capture_output=True)
    subprocess.run(["cmake", "--install", str(build), "--prefix", str(prefix)], check=True,
                   capture_output=True)
    subprocess.run([sys.executable, "-m", "stospline", "board",
                    str(ROOT / "examples/robot_corridor.toml"), "--board", board,
                    "--arith", arith, "--out", str(proj)], check=True, env=ENV,
                   capture_output=True)
    benv = {**ENV, "STOSPLINE_PREFIX": str(prefix)}
    subprocess.run(["cmake", "--preset", "qemu"], cwd=proj, check=True, env=benv,
                   capture_output=True)
    r = subprocess.run(["cmake", "--build", "--preset", "qemu"], cwd=proj, env=benv,
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
    return proj


def hil(proj: Path, board: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "stospline", "hil",
                           str(ROOT / "examples/robot_corridor.toml"), "--board", board,
                           "--elf", str(proj / "build/qemu/firmware.elf"), *args,
                           "--json", "--quiet"], env=ENV, capture_output=True, text=True,
                          timeout=600)
