"""Every zero a table or a summary stores is +0.0: the sign of a computed zero follows the sign
of round-off the value no longer shows (another CPU's BLAS kernel flips it), and the sign is
part of the bytes (the C literal, the CRC a flashed device checks, the JSON)."""
import json
import re
from dataclasses import replace

import numpy as np
import pytest

from stospline import strict
from stospline.table import codegen
from stospline.table.format import positive_zeros, table_crc32

from conftest import GAINS

NEGATIVE_ZERO = re.compile(r"(?<![0-9.eE])-0(\.0*)?(e[+-]?0+)?f?(?![0-9.])")


def test_positive_zeros_changes_the_sign_of_zeros_only():
    for dtype in (np.float32, np.float64):
        a = np.array([-0.0, 0.0, -1.5, 2.0, -np.finfo(dtype).tiny, np.inf, -np.inf], dtype)
        b = positive_zeros(a)
        assert b.dtype == dtype
        assert not np.any(np.signbit(b[:2]))
        np.testing.assert_array_equal(b[2:], a[2:])            # every other value exact
        assert np.signbit(b[2]) and np.signbit(b[4]) and np.signbit(b[6])
    assert np.isnan(positive_zeros(np.array([np.nan]))[0])
    ints = np.array([0, -3], np.int16)
    assert positive_zeros(ints).dtype == np.int16


def test_c_literals_write_zero_without_a_sign():
    assert codegen._f32_literal(np.float32(-0.0)) == codegen._f32_literal(np.float32(0.0))
    assert codegen._f32_literal(np.float32(-0.0)) == "0.0e+00f"
    assert codegen._f64_literal(-0.0) == "0.0"
    assert codegen._f32_literal(np.float32(-2.5)) == "-2.5e+00f"


def test_json_writes_zero_without_a_sign():
    out = json.loads(strict.dumps({"a": -0.0, "b": [np.float64(-0.0), (-0.0, 1.0)], "c": -1.0}))
    assert out == {"a": 0.0, "b": [0.0, [0.0, 1.0]], "c": -1.0}
    assert "-0" not in strict.dumps({"a": -0.0, "b": [np.float64(-0.0)]})


def test_a_table_differing_in_the_sign_of_zeros_only_is_the_same_table(robot_zoh):
    """The CRC (and the table's arrays) are the same whatever the sign of its zeros."""
    table = robot_zoh.table
    K = table.K.copy()
    zeros = K == 0
    assert zeros.any(), "the robot's gains have structural zeros"
    K[zeros] = -0.0
    flipped = replace(table, K=K)
    assert not np.any(np.signbit(flipped.K[zeros]))
    assert table_crc32(flipped) == table_crc32(table)


def test_spline_coefficients_have_no_negative_zero(robot_zoh):
    from stospline.table.spline import fit as spline
    C = np.array([[-1e-30, 1e-30, -0.0, 0.5]])
    coef = spline._coefficients(C, np.array([1.0]))
    assert not np.any(np.signbit(coef[0, :3])) and coef[0, 3] == 0.5


@pytest.mark.parametrize("path", sorted(p for p in GAINS.iterdir()
                                        if p.suffix in (".c", ".h", ".json")),
                         ids=lambda p: p.name)
def test_no_shipped_file_holds_a_negative_zero(path):
    text = path.read_text()
    hits = [m.group(0) for m in NEGATIVE_ZERO.finditer(text)]
    assert not hits, f"{path.name} holds negative zeros: {hits[:5]}"
