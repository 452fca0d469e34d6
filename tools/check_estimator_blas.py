"""Are the estimator's tables the same bytes under every CPU's OpenBLAS kernels?

Regenerates the float32, Q15 and Q31 tables (`stospline design`, `--arith q15|q31`) of
examples/robot_position_sensor.toml and of sensor settings where a filter gain once landed on
a float32 rounding boundary, once per OpenBLAS kernel (``OPENBLAS_CORETYPE``, a
subprocess each: OpenBLAS reads it when it loads; one or two BLAS threads), and compares the
bytes of every written file with those of this machine's own kernel, run first. Each
subprocess reports the kernel OpenBLAS took, so a kernel silently not taken cannot pass.

    .venv/bin/python tools/check_estimator_blas.py [--coretype Haswell ...] [--setting NAME ...]

Prints one line per (setting, kernel): the files that differ, or "same", and how far the
filter's double gains are from this machine's kernel's, those of the numpy loop
(``STOSPLINE_FILTER_KERNEL=numpy``) and the compiled ones (`stospline.estimator.filter_kernel`),
the largest difference relative to the largest gain; exits 1 if any file differs. Settings: ``shipped`` (the example as it is), ``3cm_100hz`` (3 cm per axis at
100 Hz: V = 9e-4, every = 10), ``v1e-3`` (V = 1e-3 at 50 Hz), ``wide_0.5m`` (0.5 m at 50 Hz, the
start known to 0.5 m: an error covariance that is not a small difference of large moments).
On the own kernel's line: how far the compiled gains are from the numpy loop's.
"""
from __future__ import annotations

import argparse
import hashlib
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "examples" / "robot_position_sensor.toml"

# name -> (V per axis, every, x0_cov per position axis)
SETTINGS = {"shipped": None, "3cm_100hz": ("9e-4", 10, "9e-4"), "v1e-3": ("1e-3", 20, "4e-4"),
            "wide_0.5m": ("0.25", 20, "0.25")}
# The kernels of tests/python/table/test_gains_regenerate_elsewhere.py: (kernel asked for,
# kernel OpenBLAS reports, CPU flag it needs, BLAS threads); with its code that prints the
# kernels a process ran, and its reading of the CPU's flags.
sys.path[:0] = [str(REPO / "tests" / "python" / "table"), str(REPO / "tests" / "python")]
import test_gains_regenerate_elsewhere as elsewhere  # noqa: E402

KERNELS = elsewhere.BLAS_KERNELS
cpu_flags = elsewhere._cpu_flags
ARITHS = ("float32", "q15", "q31")

_CHILD = """
import ctypes, sys
sys.path.insert(0, sys.argv[1])
from stospline.cli import main
toml, out = sys.argv[2], sys.argv[3]
for arith in sys.argv[4:]:
    extra = [] if arith == "float32" else ["--arith", arith]
    assert main(["design", toml, "--out", out, "--quiet", *extra]) == 0
# The filter's double gains, compiled and from the numpy loop (the comparison's figures).
import os
import numpy as np
from stospline import pipeline
from stospline.estimator.oracle import evaluate_estimator
from stospline.problem import load_problem
d = pipeline.design_problem(load_problem(toml))
np.save(out + "/gains_compiled.npy", evaluate_estimator(d.problem, d.table).gain)
os.environ["STOSPLINE_FILTER_KERNEL"] = "numpy"
np.save(out + "/gains_numpy.npy", evaluate_estimator(d.problem, d.table).gain)
""" + elsewhere._CORENAMES


def setting_toml(name: str) -> str:
    """The example's text with the sensor of setting `name`."""
    text = EXAMPLE.read_text()
    if SETTINGS[name] is None:
        return text
    v, every, x0 = SETTINGS[name]
    head, meas = text.split("[measurement]", 1)
    meas = (meas.replace("4e-4, 0],\n     [0, 4e-4]]", f"{v}, 0],\n     [0, {v}]]", 1)
            .replace("every = 20", f"every = {every}")
            .replace("[[4e-4, 0, 0, 0]", f"[[{x0}, 0, 0, 0]")
            .replace("[0, 0, 4e-4, 0]", f"[0, 0, {x0}, 0]"))
    assert f"V = [[{v}, 0]" in meas and f"every = {every}" in meas, "the example's sensor changed"
    return head + "[measurement]" + meas


def regenerate(toml: Path, out: Path, coretype: str | None = None, threads: int = 1,
               ariths=ARITHS) -> tuple[dict[str, str], list[str], float]:
    """``(sha256 of each written file, kernels OpenBLAS ran, CPU seconds)`` of a subprocess
    that writes `toml`'s tables into `out` under OpenBLAS kernel `coretype` (None: its own)."""
    env = {**os.environ, "OPENBLAS_NUM_THREADS": str(threads), "OMP_NUM_THREADS": str(threads)}
    env.pop("OPENBLAS_CORETYPE", None)
    if coretype:
        env["OPENBLAS_CORETYPE"] = coretype
    out.mkdir(parents=True, exist_ok=True)
    before = os.times()
    proc = subprocess.run([sys.executable, "-c", _CHILD, str(REPO / "host"), str(toml), str(out),
                           *ariths], env=env, capture_output=True, text=True, timeout=1800)
    after = os.times()
    if proc.returncode != 0:
        raise RuntimeError(proc.stderr)
    ran = [line.split()[1] for line in proc.stdout.splitlines() if line.startswith("corename ")]
    digests = {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(out.iterdir())
               if p.suffix != ".npy"}
    cpu = (after.children_user - before.children_user) + (after.children_system
                                                          - before.children_system)
    return digests, ran, cpu


def gain_spread(folder: Path, coretype: str) -> str:
    """How far the double filter gains under `coretype` are from this machine's own kernel's:
    the numpy loop's and the compiled ones', the largest difference over the plan relative to
    the largest gain."""
    out = []
    for kind in ("numpy", "compiled"):
        own, other = (np.load(folder / d / f"gains_{kind}.npy") for d in ("own", coretype))
        diff = np.abs(other - own).max() / np.abs(own).max()
        out.append(f"{kind} gains {'identical' if diff == 0 else f'differ by {diff:.1e}'}")
    return ", ".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--coretype", action="append", choices=[k[0] for k in KERNELS])
    ap.add_argument("--setting", action="append", choices=list(SETTINGS))
    args = ap.parse_args(argv)
    kernels = [k for k in KERNELS if not args.coretype or k[0] in args.coretype]
    settings = args.setting or list(SETTINGS)
    flags = cpu_flags()
    bad = 0
    t_start = time.time()
    with tempfile.TemporaryDirectory() as tmp:
        for name in settings:
            toml = Path(tmp) / name / "robot_position_sensor.toml"
            toml.parent.mkdir()
            toml.write_text(setting_toml(name))
            ref, ran, cpu = regenerate(toml, Path(tmp) / name / "own")
            own = Path(tmp) / name / "own"
            compiled, numpy_loop = (np.load(own / f"gains_{k}.npy") for k in ("compiled", "numpy"))
            agree = np.abs(compiled - numpy_loop).max() / np.abs(numpy_loop).max()
            print(f"{name:10s} own kernel ({', '.join(ran)}): {len(ref)} files, "
                  f"{cpu:.1f} s CPU; compiled gains differ from the numpy loop's by {agree:.1e}")
            for coretype, corename, flag, threads in kernels:
                label = f"{name:10s} {coretype}-{threads}thread"
                if flag not in flags:
                    print(f"{label}: skipped (this CPU lacks {flag})")
                    continue
                got, ran, cpu = regenerate(toml, Path(tmp) / name / coretype, coretype, threads)
                if set(ran) != {corename}:
                    print(f"{label}: OpenBLAS ran {ran}, not {corename}")
                    bad += 1
                    continue
                differ = sorted(f for f in ref if got.get(f) != ref[f])
                bad += bool(differ)
                print(f"{label}: {'differ: ' + ', '.join(differ) if differ else 'same'}"
                      f" ({cpu:.1f} s CPU); {gain_spread(Path(tmp) / name, coretype)}")
    print(f"{'FAIL' if bad else 'ok'}: {bad} of the runs differ ({time.time() - t_start:.0f} s)")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
