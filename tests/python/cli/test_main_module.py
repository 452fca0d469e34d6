"""``python -m stospline`` is the ``stospline`` command (the package had no ``__main__``)."""
import subprocess
import sys

import stospline


def test_python_dash_m_runs_the_cli():
    done = subprocess.run([sys.executable, "-m", "stospline", "--version"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert stospline.__version__ in done.stdout


def test_python_dash_m_refuses_like_the_cli(tmp_path):
    done = subprocess.run([sys.executable, "-m", "stospline", "design",
                           str(tmp_path / "missing.toml"), "--out", str(tmp_path / "o")],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.count("\n") == 1 and "cannot read" in done.stderr
    assert not (tmp_path / "o").exists()
