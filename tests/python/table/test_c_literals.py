"""The table kernel writes a table's float32 literals (`literal_kernel.c`) byte for byte as
numpy's shortest round trip does (`format_float_scientific(unique=True, trim="0",
exp_digits=2)`), which the C text was written with before and is written with without a
compiler: random bit patterns over the whole binary32 range, the kinds of value the kernel
hands back to numpy (powers of two, subnormals, |x| >= 2^22, below 2^-60), decade edges and
gains-like values."""
import numpy as np
import pytest

from stospline.table import codegen, kernels


def _numpy_body(x: np.ndarray, per_line: int) -> str:
    lit = [np.format_float_scientific(v + np.float32(0), unique=True, trim="0", exp_digits=2)
           + "f" for v in x]
    return "\n".join("    " + ", ".join(lit[i:i + per_line]) + ","
                     for i in range(0, len(lit), per_line))


def _values(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    bits = rng.integers(0, 2 ** 32, 60_000, dtype=np.uint64).astype(np.uint32).view(np.float32)
    tens = 10.0 ** np.arange(-20, 8)
    parts = [bits[np.isfinite(bits)],
             (rng.standard_normal(60_000) * 10.0 ** rng.uniform(-9, 5, 60_000)),
             np.ldexp(1.0, np.arange(-149, 128)), -np.ldexp(1.0, np.arange(-149, 128)),
             np.concatenate([np.nextafter(tens.astype(np.float32), np.float32(d))
                             for d in (-np.inf, np.inf)]), tens,
             (2.0 ** np.arange(18, 26)[:, None] + np.arange(-3, 4) / 4).ravel(),
             np.ldexp(1.0, -60) * np.array([0.999, 1.0, 1.001]),
             [0.0, -0.0, 1.0, 0.5, 9.999999, 1e-45, 3.4028235e38, -3.4028235e38, 0.1, 1 / 3]]
    return np.concatenate([np.asarray(p, dtype=np.float32).ravel() for p in parts])


@pytest.fixture(autouse=True)
def _kernel_built():
    if kernels._kernel() is None:
        pytest.skip("the table kernel is not built here (numpy writes the literals)")


@pytest.mark.parametrize("seed", [1, 2])
def test_kernel_literals_are_numpys(seed):
    x = _values(seed)
    assert kernels.f32_array_text(x, 6) == _numpy_body(x, 6)


@pytest.mark.parametrize("per_line", [1, 5, 6])
def test_array_layout_is_the_same(per_line):
    for n in (1, 2, per_line, per_line + 1, 13):
        x = np.linspace(-3, 7, n, dtype=np.float32)
        assert kernels.f32_array_text(x, per_line) == _numpy_body(x, per_line)


def test_zero_has_no_sign_and_short_values_keep_one_decimal():
    text = kernels.f32_array_text(np.array([-0.0, 0.0, 1.0, -0.5, 1e10], np.float32), 6)
    assert text == "    0.0e+00f, 0.0e+00f, 1.0e+00f, -5.0e-01f, 1.0e+10f,"


@pytest.mark.parametrize("bad", [np.inf, -np.inf, np.nan])
def test_a_non_finite_value_is_refused(bad):
    with pytest.raises(ValueError, match="finite numbers only"):
        kernels.f32_array_text(np.array([1.0, bad], np.float32), 6)
    with pytest.raises(ValueError, match="finite numbers only"):
        codegen._array("stsp_f32_t", "a", np.array([bad], np.float32), codegen._f32_literal, "")


def test_the_c_text_is_the_same_without_the_kernel(robot_zoh, monkeypatch):
    header, source = codegen.generate_c(robot_zoh.table)
    monkeypatch.setenv("STOSPLINE_TABLE_KERNEL", "numpy")
    assert codegen.generate_c(robot_zoh.table) == (header, source)
