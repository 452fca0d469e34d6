"""docs/guide/integration.md shows the consumer's main.c verbatim: the file the consumer_* ctest tests
build three ways, run and compare with the harness (tests/consumer/)."""
import re

from conftest import REPO

GUIDE = (REPO / "docs" / "guide" / "integration.md").read_text(encoding="utf-8")


def test_guide_main_c_is_the_tested_file():
    block = re.search(r"^<!-- tests/consumer/main\.c -->\n```c\n(.*?)^```$", GUIDE,
                      flags=re.DOTALL | re.MULTILINE)
    assert block, "docs/guide/integration.md: no ```c block after <!-- tests/consumer/main.c -->"
    assert block.group(1) == (REPO / "tests" / "consumer" / "main.c").read_text(encoding="utf-8")


def test_guide_names_files_that_exist():
    for path in ("tests/consumer/CMakeLists.txt", "tests/consumer/run.sh", "CMakePresets.json",
                 "cmake/stosplineGains.cmake"):
        assert path in GUIDE and (REPO / path).is_file(), path
