"""The harness's status names and values are the public header's (`stsp_status_t`): a status
added to or renumbered in the header cannot silently diverge from Python."""
import re

from conftest import REPO
from stospline.firmware_interface import STATUS


def header_statuses() -> dict[str, int]:
    text = (REPO / "firmware/include/stospline/stsp_types.h").read_text()
    enum = re.search(r"typedef enum\s*{(.*?)}\s*stsp_status_t;", text, re.S)
    assert enum, "stsp_status_t not found in the header"
    body = re.sub(r"/\*.*?\*/", "", enum.group(1), flags=re.S)
    return {name: int(value) for name, value in re.findall(r"STSP_(\w+)\s*=\s*(-?\d+)", body)}


def test_harness_status_table_is_the_headers():
    assert STATUS == header_statuses()


def test_the_header_check_stops_a_build_on_a_diverged_header(tmp_path):
    """`build_controller` checks the header before compiling: a renumbered status or another
    magic or format version is named, not run with stale numbers."""
    import shutil

    import pytest

    from stospline.firmware_interface import InterfaceMismatch, check_header
    src = REPO / "firmware/include"
    check_header(src)
    for old, new, named in [("STSP_ERR_TABLE_CHANGED = -13", "STSP_ERR_TABLE_CHANGED = -14",
                             "stsp_status_t"),
                            ("STSP_TABLE_MAGIC 0x53545350u", "STSP_TABLE_MAGIC 0x53545351u",
                             "STSP_TABLE_MAGIC"),
                            ("STSP_FORMAT_VERSION 5u", "STSP_FORMAT_VERSION 6u",
                             "STSP_FORMAT_VERSION")]:
        inc = tmp_path / named
        shutil.copytree(src, inc)
        h, = [p for p in sorted((inc / "stospline").glob("*.h")) if old in p.read_text()]
        text = h.read_text()
        h.write_text(text.replace(old, new))
        with pytest.raises(InterfaceMismatch, match=named):
            check_header(inc)
