"""The command line starts fast because it loads only what a command needs: importing it
loads no numpy, harness or plotting, and a design loads no harness, plotting or Monte Carlo
report (tools/bench/cli_startup.py times the command)."""
import json
import subprocess
import sys
from pathlib import Path

ROBOT = str(Path(__file__).resolve().parents[3] / "examples" / "robot_corridor.toml")

# What a design never needs: the cffi controller and its Monte Carlo, plotting, HTML, the
# every-tick designer (the robot has no regions at every tick), Dask, SciPy.
HARNESS = ("stospline.harness", "stospline.refine.every_tick",
           "stospline.report.plot", "stospline.report.html",
           "stospline.report.simulation_summary", "matplotlib", "scipy", "dask", "jinja2")


def loaded_after(code: str) -> list[str]:
    """The modules (of those `code` may load) in a fresh interpreter after running `code`."""
    probe = (f"{code}\nimport sys, json\n"
             f"print(json.dumps(sorted(sys.modules)), file=sys.stderr)")
    res = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         check=True)
    return json.loads(res.stderr.strip().splitlines()[-1])


def under(modules: list[str], packages) -> list[str]:
    """The modules that are one of `packages` or inside one."""
    return [m for m in modules if any(m == p or m.startswith(p + ".") for p in packages)]


def test_importing_the_cli_loads_no_numpy_harness_or_plotting():
    heavy = ("numpy", "_cffi_backend", "stospline.pipeline", "stospline.oracle", "stospline.refine",
             "stospline.report", "stospline.design", *HARNESS)
    assert under(loaded_after("import stospline.cli"), heavy) == []


def test_a_design_loads_no_harness_or_plotting():
    code = ("import contextlib, io\nfrom stospline.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            f"    assert main(['design', {ROBOT!r}, '--json']) == 0")
    modules = loaded_after(code)
    assert "stospline.pipeline" in modules          # the probe ran the design
    assert under(modules, HARNESS) == []
