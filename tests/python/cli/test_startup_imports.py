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


# What a float32 design of a problem without [plant], [measurement] or [[parameters]] does not
# need either: package metadata (`stospline.dist_version` reads it), a thread pool, the
# linearisation of a [plant], the estimator's tables, the parametric oracle, the continuous
# designer, the spline fitter, the fixed-point tables, decimal and difflib.
PLAIN_DESIGN = ("importlib.metadata", "concurrent.futures", "stospline.nonlinear.iterate",
                "stospline.estimator", "stospline.oracle.parametric", "stospline.design.continuous",
                "stospline.table.spline", "stospline.table.qformat", "decimal", "difflib")


def _design_modules() -> list[str]:
    code = ("import contextlib, io, tempfile\nfrom stospline.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()), tempfile.TemporaryDirectory() as d:\n"
            f"    assert main(['design', {ROBOT!r}, '--json', '--out', d]) == 0")
    modules = loaded_after(code)
    assert "stospline.pipeline" in modules          # the probe ran the design
    return modules


def test_a_design_loads_no_harness_or_plotting():
    assert under(_design_modules(), HARNESS) == []


def test_a_plain_design_loads_only_what_it_uses():
    assert under(_design_modules(), PLAIN_DESIGN) == []
