"""`stospline.dist_version.installed_version` gives what ``importlib.metadata.version`` gives,
on the real installation and on made-up ``sys.path`` layouts: its own look-up where the
metadata is a plain dist-info directory, importlib's everywhere else."""
import importlib
import sys
from importlib import metadata

import pytest

from stospline import dist_version
from stospline.dist_version import installed_version


def _expected():
    try:
        return metadata.version("stospline")
    except metadata.PackageNotFoundError:
        return None


def _dist_info(root, name, version=None):
    info = root / name
    info.mkdir(parents=True)
    head = "Metadata-Version: 2.1\nName: stospline\n"
    (info / "METADATA").write_text(head + (f"Version: {version}\n" if version else "")
                                   + "\nThe description. Version: 9.9.9\n")
    return info


@pytest.fixture
def path(tmp_path, monkeypatch):
    """A ``sys.path`` of two empty directories, importlib's caches cleared around the test."""
    dirs = [tmp_path / "a", tmp_path / "b"]
    for d in dirs:
        d.mkdir()
    monkeypatch.setattr(sys, "path", [str(d) for d in dirs])
    importlib.invalidate_caches()
    yield dirs
    importlib.invalidate_caches()


def test_the_installation_agrees_with_importlib():
    assert installed_version() == _expected()
    assert dist_version._fast_lookup() in (None, _expected())


def test_the_first_directory_with_a_dist_info_wins(path):
    _dist_info(path[0], "stospline-1.2.3.dist-info", "1.2.3")
    _dist_info(path[1], "stospline-4.5.6.dist-info", "4.5.6")
    assert dist_version._fast_lookup() == "1.2.3"
    assert installed_version() == _expected() == "1.2.3"


def test_a_name_spelt_otherwise_is_the_same_distribution(path):
    _dist_info(path[1], "StoSpline-2.0.0.dist-info", "2.0.0")
    assert dist_version._fast_lookup() == "2.0.0"
    assert installed_version() == _expected() == "2.0.0"


@pytest.mark.parametrize("layout", ["two candidates", "egg-info", "no version header"])
def test_the_cases_it_leaves_to_importlib(path, layout):
    if layout == "two candidates":
        _dist_info(path[0], "stospline-1.0.0.dist-info", "1.0.0")
        _dist_info(path[0], "stospline-2.0.0.dist-info", "2.0.0")
    elif layout == "egg-info":
        info = path[0] / "stospline.egg-info"
        info.mkdir()
        (info / "PKG-INFO").write_text("Metadata-Version: 1.1\nName: stospline\nVersion: 3.0\n")
    else:
        _dist_info(path[0], "stospline-1.0.0.dist-info")
    assert dist_version._fast_lookup() is None
    assert installed_version() == _expected()


def test_not_installed(path):
    assert dist_version._fast_lookup() is None
    assert installed_version() is None
    assert _expected() is None
