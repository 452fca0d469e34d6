"""One exception hierarchy: every exception class the package defines derives from
`stospline.errors.StosplineError`, and the command line reports any of them in one line with
exit status 2."""
import ast
import functools
import importlib
from pathlib import Path

import pytest

import stospline
from stospline import cli
from stospline.errors import KernelBuildError, StosplineError

PACKAGE = Path(stospline.__file__).parent

# A signal that aborts a write is not an error: it derives from BaseException so that no
# ``except Exception`` swallows it, and the command line exits 128 + N for it.
NOT_ERRORS = {"stospline.atomic.Interrupted"}


def modules() -> dict[str, Path]:
    """The package's modules by name (the compiled firmware copies excepted)."""
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        if "_firmware" in path.parts:
            continue
        parts = list(path.relative_to(PACKAGE).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(["stospline", *parts])] = path
    return out


@functools.cache
def defined_exceptions() -> dict[str, type]:
    """Every exception class defined at the top level of a package module, by qualified name."""
    found = {}
    for name, path in modules().items():
        classes = [node.name for node in ast.parse(path.read_text()).body
                   if isinstance(node, ast.ClassDef)]
        if not classes:
            continue
        module = importlib.import_module(name)
        for cls_name in classes:
            cls = getattr(module, cls_name)
            # A warning category is not raised: it is issued through `warnings`.
            if isinstance(cls, type) and issubclass(cls, BaseException) \
                    and not issubclass(cls, Warning):
                found[f"{name}.{cls_name}"] = cls
    return found


def test_every_exception_derives_from_the_base():
    found = defined_exceptions()
    assert len(found) > 10                   # the walk found the package's classes
    outside = sorted(name for name, cls in found.items()
                     if not issubclass(cls, StosplineError) and name not in NOT_ERRORS)
    assert outside == []


def test_the_design_oracle_and_table_kernels_raise_one_build_error():
    from stospline.design import kernels as design_kernels
    from stospline.oracle import kernel as oracle_kernel
    from stospline.table import kernels as table_kernels
    assert design_kernels.KernelBuildError is table_kernels.KernelBuildError is KernelBuildError
    assert oracle_kernel.KernelBuildError is KernelBuildError


def _raising(exc: BaseException):
    def command(args):
        raise exc
    return command


@pytest.mark.parametrize("exc", [
    KernelBuildError("cannot build tick_kernel.c: gcc failed\n  tick_kernel.c:1: error"),
    StosplineError("something the package refused"),
], ids=lambda e: type(e).__name__)
def test_the_cli_reports_a_package_error_in_one_line(monkeypatch, capsys, exc):
    monkeypatch.setattr(cli, "_design", _raising(exc))
    status = cli.main(["design", "examples/robot_corridor.toml"])
    out, err = capsys.readouterr()
    assert status == 2
    assert out == ""
    assert err.count("\n") == 1 and err.startswith("stospline: error: ")
    assert str(exc).split()[-1] in err


@pytest.mark.parametrize("name", sorted(set(defined_exceptions()) - NOT_ERRORS))
def test_each_exception_class_maps_to_exit_2(monkeypatch, capsys, name):
    """Whatever its constructor, each class raised from a command ends in exit status 2."""
    cls = defined_exceptions()[name]
    try:
        exc = cls("a reason")
    except TypeError:                        # ProblemError and its kin: (field, reason)
        exc = cls("field", "a reason")
    monkeypatch.setattr(cli, "_design", _raising(exc))
    status = cli.main(["design", "examples/robot_corridor.toml"])
    out, err = capsys.readouterr()
    assert (status, out, err.count("\n")) == (2, "", 1)
