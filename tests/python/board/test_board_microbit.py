"""The ARMv6-M board: the generated micro:bit project (nRF51822, Cortex-M0, a Q15 table)
cross-builds under -Werror, and HIL paths through it in QEMU, whose `microbit` machine runs
ARMv6-M code on a Cortex-M0 model, equal the host-compiled Q15 controller's bit for bit."""
import json

from boardbuild import build_project, hil, needs_tools


@needs_tools
def test_microbit_q15_project_hil_paths_are_bit_identical(tmp_path):
    proj = build_project(tmp_path, "microbit", "cortex-m0", "q15")
    assert "#define BOARD_BATCH 16u" in (proj / "board_config.h").read_text()
    r = hil(proj, "microbit", "--paths", "3", "--seed", "5")
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)["hil"]
    assert s["arith"] == "q15" and s["batch"] == 16
    assert s["bit_identical"] and s["mismatches"] == 0
    assert s["statuses"] == {"0": 18000}
    assert s["bad_frames_board"] == 0 and s["lost_frames"] == 0 and s["timeouts"] == 0
