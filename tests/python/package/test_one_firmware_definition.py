"""One firmware definition: the top-level CMake project is the only one that compiles
firmware/src, and the Cortex-M builds are its presets, not a second project."""
import json
import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[3]


def test_presets_are_the_five_targets():
    presets = json.loads((REPO / "CMakePresets.json").read_text(encoding="utf-8"))
    visible = [p["name"] for p in presets["configurePresets"] if not p.get("hidden")]
    assert visible == ["host-gcc", "host-clang", "arm-m4f", "arm-m0plus", "arm-m0"]
    arm = {p["name"]: p for p in presets["configurePresets"]}
    assert arm["arm-base"]["toolchainFile"].endswith("tools/arm/arm-none-eabi.cmake")


def test_only_the_top_level_project_compiles_the_firmware():
    # Every CMake file that names firmware/src sources: only the top-level CMakeLists.txt
    # (tests/consumer builds against the installed or fetched package, never the sources).
    compiling = []
    for path in REPO.rglob("*"):
        if path.name != "CMakeLists.txt" and path.suffix != ".cmake":
            continue
        rel = path.relative_to(REPO)
        if rel.parts[0] in ("build", ".venv") or not path.is_file():
            continue
        text = path.read_text(encoding="utf-8")
        if re.search(r"firmware/src/\*\.c", text):
            compiling.append(str(rel))
    assert compiling == ["CMakeLists.txt"], compiling
    projects = sorted(str(p.relative_to(REPO)) for p in REPO.rglob("CMakeLists.txt")
                      if p.relative_to(REPO).parts[0] not in ("build", ".venv")
                      and re.search(r"^\s*project\(", p.read_text(encoding="utf-8"), re.M))
    assert projects == ["CMakeLists.txt", "tests/consumer/CMakeLists.txt"], projects
