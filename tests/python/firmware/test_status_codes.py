"""The harness's status names and values are the public header's (`stsp_status_t`): a status
added to or renumbered in the header cannot silently diverge from Python."""
import re

from conftest import REPO
from stospline.sim.controller import STATUS


def header_statuses() -> dict[str, int]:
    text = (REPO / "firmware/include/stospline/stsp_controller.h").read_text()
    enum = re.search(r"typedef enum\s*{(.*?)}\s*stsp_status_t;", text, re.S)
    assert enum, "stsp_status_t not found in the header"
    body = re.sub(r"/\*.*?\*/", "", enum.group(1), flags=re.S)
    return {name: int(value) for name, value in re.findall(r"STSP_(\w+)\s*=\s*(-?\d+)", body)}


def test_harness_status_table_is_the_headers():
    assert STATUS == header_statuses()
