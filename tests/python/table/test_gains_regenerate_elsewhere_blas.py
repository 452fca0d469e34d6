"""gains/ regenerates byte for byte under other CPUs' OpenBLAS kernels and thread counts
(test_gains_regenerate_elsewhere.py has the other perturbations, the reasons and the list of
kernels; this part is a file of its own so that pytest-xdist's ``--dist loadfile`` runs it
beside that one).

Under each kernel that OpenBLAS has a table of its own for, a subprocess regenerates every
shipped file (OpenBLAS reads ``OPENBLAS_CORETYPE`` and its thread count when it loads) and
reports the kernels it ran, so that a kernel silently not taken cannot pass. A kernel it has no
table for (asked for it, OpenBLAS names another's) is checked to run that other table, which
is regenerated.
"""
import os
import subprocess
import sys
from pathlib import Path

import pytest

from test_gains_regenerate_elsewhere import BLAS_KERNELS, _assert_same_as_gains, _cpu_flags

# (kernel asked for, kernel reported, CPU flag, BLAS threads): regenerated, and the ones that
# run another kernel's table (Zen: Haswell's), checked to be one of those regenerated.
OWN_TABLE = [k for k in BLAS_KERNELS if k[0] == k[1]]
OTHERS_TABLE = [k for k in BLAS_KERNELS if k[0] != k[1]]
_HERE = os.path.dirname(os.path.abspath(__file__))      # this file's folder and conftest.py's


def _run(code: str, coretype: str, threads: int, *args: str) -> str:
    """Stdout of `code` run in a subprocess with OpenBLAS forced to `coretype` and `threads`
    threads, then `_CORENAMES` (a line ``corename <kernel>`` per OpenBLAS loaded)."""
    env = {**os.environ, "OPENBLAS_CORETYPE": coretype, "OPENBLAS_NUM_THREADS": str(threads),
           "OMP_NUM_THREADS": str(threads)}
    code = ("import sys; sys.path[:0] = sys.argv[1:3]; " + code
            + "; import test_gains_regenerate_elsewhere as t; exec(t._CORENAMES)")
    proc = subprocess.run([sys.executable, "-c", code, _HERE, os.path.dirname(_HERE), *args],
                          env=env, capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout


def _ran(stdout: str) -> list[str]:
    return [line.split()[1] for line in stdout.splitlines() if line.startswith("corename ")]


@pytest.mark.parametrize("coretype,corename,flag,threads", OWN_TABLE,
                         ids=[f"{k[0]}-{k[3]}thread" for k in OWN_TABLE])
def test_other_blas_kernels_change_no_byte(tmp_path, coretype, corename, flag, threads):
    """gains/ as another CPU's OpenBLAS kernels and thread count compute it."""
    if flag not in _cpu_flags():
        pytest.skip(f"this CPU lacks {flag}: it cannot run OpenBLAS's {coretype} kernels")
    ran = _ran(_run("from pathlib import Path; import test_gains_regenerate_elsewhere as r; "
                    "r._regenerate(Path(sys.argv[3]))", coretype, threads, str(tmp_path)))
    assert ran and set(ran) == {corename}, f"OpenBLAS ran {ran}, not {corename}"
    _assert_same_as_gains(tmp_path)


@pytest.mark.parametrize("coretype,corename,flag,threads", OTHERS_TABLE,
                         ids=[f"{k[0]}-{k[3]}thread" for k in OTHERS_TABLE])
def test_kernel_without_a_table_of_its_own_is_one_regenerated(coretype, corename, flag,
                                                               threads):
    """The OpenBLAS of numpy's and scipy's wheels has no Zen kernels: asked for Zen, it runs
    Haswell's. It names the kernel table it selected (``gotoblas_corename()`` compares the
    table pointer with each table's), so "Haswell" is Haswell's very table, kernels and block
    sizes: gains/ under Zen with one thread is computed exactly as under Haswell with one
    thread, which `test_other_blas_kernels_change_no_byte` regenerates; that regeneration is
    not repeated here. Every OpenBLAS the design can load (those of numpy and scipy) must be
    loaded and name it; an OpenBLAS with Zen kernels of its own names "Zen" and fails this
    test, and BLAS_KERNELS should then say ("Zen", "Zen", ...)."""
    if flag not in _cpu_flags():
        pytest.skip(f"this CPU lacks {flag}: it cannot run OpenBLAS's {coretype} kernels")
    assert (corename, corename, flag, threads) in OWN_TABLE
    import numpy
    import scipy
    shipped = sorted(p.name for pkg in (numpy, scipy)
                     for p in (Path(pkg.__file__).parent.parent / f"{pkg.__name__}.libs").glob(
                         "*openblas*.so*"))
    out = _run("import numpy, scipy.linalg; "
               "print(*sorted({l.split()[-1].rsplit('/', 1)[-1] for l in open('/proc/self/maps') "
               "if 'openblas' in l and l.rstrip().endswith('.so')}))", coretype, threads)
    assert shipped and out.splitlines()[0].split() == shipped
    ran = _ran(out)
    assert len(ran) == len(shipped) and set(ran) == {corename}, \
        f"OpenBLAS ran {ran}, not {corename}"
