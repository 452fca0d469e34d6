"""The generated netduinoplus2 project cross-builds under -Werror, and paths through it in QEMU
over the serial line (BATCH frames of two paths, then one) equal the host-compiled
controller's paths bit for bit."""
import json

from boardbuild import ROOT, build_project, hil, needs_tools
from stospline.board import frames


def test_frame_crc_and_parser_resync():
    f = frames.encode(frames.STATE, 7, b"\x01\x02\x03")
    assert frames.crc16(b"123456789") == 0x29B1            # CRC-16/CCITT-FALSE check value
    p = frames.Parser()
    bad = bytearray(f)
    bad[6] ^= 0x01                                          # one payload bit flipped
    got = p.feed(bytes(bad) + b"\xa5" + f)
    assert [(g.kind, g.seq, g.payload) for g in got] == [(frames.STATE, 7, b"\x01\x02\x03")]
    assert p.bad == 1


@needs_tools
def test_generated_project_builds_and_hil_paths_are_bit_identical(tmp_path):
    proj = build_project(tmp_path, "netduinoplus2", "cortex-m4", "float32")
    assert (proj / "robot_corridor.c").read_bytes() == \
        (ROOT / "gains/robot_corridor.c").read_bytes()
    r = hil(proj, "netduinoplus2", "--paths", "3", "--batch", "2", "--seed", "3")
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    assert s["hil"]["bit_identical"] and s["hil"]["mismatches"] == 0
    assert s["hil"]["statuses"] == {"0": 18000} and s["hil"]["batch"] == 2
    assert s["hil"]["bad_frames_board"] == 0 and s["hil"]["lost_frames"] == 0
