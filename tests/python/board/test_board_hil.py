"""The generated netduinoplus2 project cross-builds under -Werror, and paths through it in QEMU
over the serial line (BATCH frames of two paths, then one) equal the host-compiled
controller's paths bit for bit."""
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from stospline.board import frames

ROOT = Path(__file__).resolve().parents[3]
TOOLS = ("arm-none-eabi-gcc", "qemu-system-arm", "cmake", "ninja")


def test_frame_crc_and_parser_resync():
    f = frames.encode(frames.STATE, 7, b"\x01\x02\x03")
    assert frames.crc16(b"123456789") == 0x29B1            # CRC-16/CCITT-FALSE check value
    p = frames.Parser()
    bad = bytearray(f)
    bad[6] ^= 0x01                                          # one payload bit flipped
    got = p.feed(bytes(bad) + b"\xa5" + f)
    assert [(g.kind, g.seq, g.payload) for g in got] == [(frames.STATE, 7, b"\x01\x02\x03")]
    assert p.bad == 1


@pytest.mark.skipif(any(shutil.which(t) is None for t in TOOLS),
                    reason="needs arm-none-eabi-gcc, qemu-system-arm, cmake, ninja "
                           "(tools/setup.sh installs them)")
def test_generated_project_builds_and_hil_paths_are_bit_identical(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT / "host")}
    prefix = tmp_path / "stsp"
    build = tmp_path / "lib"
    subprocess.run(["cmake", "-S", str(ROOT), "-B", str(build), "-G", "Ninja",
                    f"-DCMAKE_TOOLCHAIN_FILE={ROOT}/tools/arm/arm-none-eabi.cmake",
                    "-DCMAKE_BUILD_TYPE=Release", "-DCMAKE_C_FLAGS_RELEASE=-O2",
                    "-DSTSP_BUILD_TESTS=OFF", "-DSTSP_INSTALL=ON"], check=True,
                   capture_output=True)
    subprocess.run(["cmake", "--build", str(build)], check=True, capture_output=True)
    subprocess.run(["cmake", "--install", str(build), "--prefix", str(prefix)], check=True,
                   capture_output=True)
    proj = tmp_path / "proj"
    subprocess.run([sys.executable, "-m", "stospline", "board",
                    str(ROOT / "examples/robot_corridor.toml"), "--board", "netduinoplus2",
                    "--out", str(proj)], check=True, env=env, capture_output=True)
    assert (proj / "robot_corridor.c").read_bytes() == \
        (ROOT / "gains/robot_corridor.c").read_bytes()
    benv = {**env, "STOSPLINE_PREFIX": str(prefix)}
    subprocess.run(["cmake", "--preset", "qemu"], cwd=proj, check=True, env=benv,
                   capture_output=True)
    r = subprocess.run(["cmake", "--build", "--preset", "qemu"], cwd=proj, env=benv,
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr                # -Werror inside
    r = subprocess.run([sys.executable, "-m", "stospline", "hil",
                        str(ROOT / "examples/robot_corridor.toml"), "--board", "netduinoplus2",
                        "--elf", str(proj / "build/qemu/firmware.elf"), "--paths", "3",
                        "--batch", "2",
                        "--seed", "3", "--json", "--quiet"], env=env, capture_output=True,
                       text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    import json
    s = json.loads(r.stdout)
    assert s["hil"]["bit_identical"] and s["hil"]["mismatches"] == 0
    assert s["hil"]["statuses"] == {"0": 18000} and s["hil"]["batch"] == 2
    assert s["hil"]["bad_frames_board"] == 0 and s["hil"]["lost_frames"] == 0
