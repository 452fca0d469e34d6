"""cffi builds: in the user cache directory (STOSPLINE_CACHE_DIR overrides), keyed by a hash of
their sources, renamed into place whole, and safe when two processes build at once; the
firmware tree: STOSPLINE_FIRMWARE, else the installed copy, else the checkout's firmware/."""
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from stospline import cache
from stospline.firmware_files import FirmwareNotFoundError, firmware_dir

from conftest import REPO


def test_default_root_is_the_user_cache_dir(monkeypatch, tmp_path):
    for var in ("STOSPLINE_CACHE_DIR", "STOSPLINE_BUILD"):
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    from platformdirs import user_cache_dir
    assert cache.cache_root() == Path(user_cache_dir("stospline")) / "cffi"
    assert cache.cache_root().is_relative_to(tmp_path)
    monkeypatch.setenv("STOSPLINE_CACHE_DIR", str(tmp_path / "c"))
    assert cache.cache_root() == tmp_path / "c"


def test_kernels_are_built_under_the_override(monkeypatch, tmp_path):
    from stospline.design.kernels import build_kernels
    monkeypatch.setenv("STOSPLINE_CACHE_DIR", str(tmp_path))
    path = build_kernels()
    assert path.is_relative_to(tmp_path) and path.parent.parent == tmp_path
    assert build_kernels() == path                              # cached: the same module
    assert [p.name for p in tmp_path.iterdir()] == [path.parent.name]   # no temporary left


def test_a_failed_build_leaves_nothing(tmp_path):
    def broken(out: Path) -> Path:
        (out / "half.so").write_text("x")
        raise RuntimeError("compiler died")
    with pytest.raises(RuntimeError):
        cache.cached_build("k", "half", broken, root=tmp_path)
    assert list(tmp_path.iterdir()) == []


def test_key_depends_on_every_input():
    assert cache.source_key(["ab", "c"]) != cache.source_key(["a", "bc"])
    assert cache.source_key([b"x"]) == cache.source_key(["x"])


@pytest.mark.parametrize("what", ["kernels", "controller"])
def test_nothing_appears_in_place_before_the_build_is_complete(what, tmp_path, monkeypatch,
                                                               robot_zoh):
    """While the compiler runs, the cache holds nothing under a final name: a reader (another
    process) either finds the whole module or nothing."""
    import cffi
    seen = []
    compile_ = cffi.FFI.compile

    def spy(self, *args, **kwargs):
        seen.append(sorted(p.name for p in tmp_path.iterdir() if not p.name.startswith(".")))
        return compile_(self, *args, **kwargs)

    monkeypatch.setattr(cffi.FFI, "compile", spy)
    if what == "kernels":
        from stospline.design.kernels import build_kernels
        path = build_kernels(tmp_path)
    else:
        from stospline.harness.controller import build_controller
        build_controller(robot_zoh.table, build_dir=tmp_path)
        (path,) = tmp_path.glob("*/_stsp_robot_corridor_*.so")
    # Every compile (with a cold user cache the controller's helper kernels compile too) found
    # nothing under a final name in the build directory but the objects of the firmware and
    # of the loops, builds of their own, complete (renamed into place) before the module
    # links them.
    shared = ("fw-", "loop-")
    assert seen and all([n for n in names if not n.startswith(shared)] == []
                        for names in seen), seen
    assert path.is_file() and path.parent.parent == tmp_path


RACE = textwrap.dedent("""
    import sys, time
    from pathlib import Path
    from stospline.pipeline import design_problem
    from stospline.problem import load_problem
    from stospline.harness.controller import build_controller
    root, go = Path(sys.argv[1]), Path(sys.argv[2])
    d = design_problem(load_problem(sys.argv[3]))
    while not go.exists():
        time.sleep(0.01)
    ctl = build_controller(d.table, build_dir=root)
    print(ctl.lib.harness_table().n_ticks)
""")


def test_two_processes_build_the_same_module_at_once(tmp_path):
    """Both start compiling the same key together: both load a working module, one build
    (and one of each object it links) stays in the cache, no temporary directory is left."""
    root, go = tmp_path / "cache", tmp_path / "go"
    script = tmp_path / "race.py"
    script.write_text(RACE)
    from support.problems import cart          # any problem: the smallest one
    toml = tmp_path / "cart.toml"
    toml.write_text(cart(t="2.0"))            # 20 ticks at 10 Hz
    env = dict(os.environ, STOSPLINE_CACHE_DIR=str(tmp_path / "kernels"))
    procs = [subprocess.Popen([sys.executable, str(script), str(root), str(go), str(toml)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
             for _ in range(2)]
    time.sleep(0.5)
    go.touch()
    outs = [p.communicate(timeout=300) for p in procs]
    for p, (out, err) in zip(procs, outs):
        assert p.returncode == 0, err
        assert out.strip() == "20"
    entries = sorted(p.name for p in root.iterdir())
    assert len(entries) == 3 and entries[1].startswith("fw-"), entries
    assert entries[2].startswith("loop-") and not entries[0].startswith("."), entries


def test_firmware_override_and_checkout(monkeypatch, tmp_path):
    monkeypatch.delenv("STOSPLINE_FIRMWARE", raising=False)
    assert firmware_dir() == REPO / "firmware"        # the checkout: the single source
    monkeypatch.setenv("STOSPLINE_FIRMWARE", str(tmp_path))
    with pytest.raises(FirmwareNotFoundError, match="STOSPLINE_FIRMWARE"):
        firmware_dir()
    monkeypatch.setenv("STOSPLINE_FIRMWARE", str(REPO / "firmware"))
    assert firmware_dir() == REPO / "firmware"
