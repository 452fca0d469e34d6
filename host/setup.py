"""Build hooks: the wheel and the sdist carry the firmware sources that `stospline simulate`
compiles, as package data under ``stospline/_firmware`` (``src/*.[ch]``, ``include/**/*.h``).

The repository's ``firmware/`` is the single source of truth: nothing is committed under
``host/``. A build from the repository copies ``../firmware`` into the build tree (wheel) or
the release tree (sdist); a build from an unpacked sdist copies its ``stospline/_firmware``.
An editable install copies nothing: the package then finds ``../firmware`` itself
(`stospline.firmware_files`).

The version is the repository's top-level ``VERSION`` file, which CMake's ``project()`` reads
too; the sdist carries a copy at its root. Everything else is in ``pyproject.toml``.
"""
import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py
from setuptools.command.sdist import sdist

HERE = Path(__file__).resolve().parent
PACKAGED = Path("stospline") / "_firmware"
MARKER = Path("include") / "stospline" / "stsp_controller.h"
PATTERNS = (("src", "*.[ch]"), ("include", "**/*.h"))


def firmware_source() -> Path:
    """``../firmware`` in a repository checkout, else the unpacked sdist's copy."""
    for candidate in (HERE.parent / "firmware", HERE / PACKAGED):
        if (candidate / MARKER).is_file():
            return candidate
    raise SystemExit(f"stospline: no firmware sources to package: neither "
                     f"{HERE.parent / 'firmware'} nor {HERE / PACKAGED} has {MARKER}")


def package_version() -> str:
    """The first line of ``../VERSION`` in a repository checkout, else of the sdist's copy."""
    for candidate in (HERE.parent / "VERSION", HERE / "VERSION"):
        if candidate.is_file():
            return candidate.read_text().splitlines()[0].strip()
    raise SystemExit(f"stospline: no VERSION file: neither {HERE.parent / 'VERSION'} "
                     f"nor {HERE / 'VERSION'}")


def copy_firmware(dest: Path) -> None:
    src = firmware_source()
    if dest.resolve() == src.resolve():
        return
    shutil.rmtree(dest, ignore_errors=True)
    for sub, pattern in PATTERNS:
        for path in sorted((src / sub).glob(pattern)):
            target = dest / sub / path.relative_to(src / sub)
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(path, target)


class BuildPyWithFirmware(build_py):
    def run(self):
        super().run()
        if not getattr(self, "editable_mode", False):
            copy_firmware(Path(self.build_lib) / PACKAGED)


class SdistWithFirmware(sdist):
    def make_release_tree(self, base_dir, files):
        super().make_release_tree(base_dir, files)
        copy_firmware(Path(base_dir) / PACKAGED)
        version_file = Path(base_dir) / "VERSION"
        version_file.unlink(missing_ok=True)
        version_file.write_text(package_version() + "\n")


setup(version=package_version(),
      cmdclass={"build_py": BuildPyWithFirmware, "sdist": SdistWithFirmware})
