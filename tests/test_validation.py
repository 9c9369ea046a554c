"""The shared validators: arrays of real numbers, object positions."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from pbdkit._validation import check_array, check_positions


def test_check_positions_cleans_and_orders() -> None:
    src = {"b": [1, 2, 3], "a": np.array([0.5, 0.0, -1.0])}
    out = check_positions(src)
    assert list(out) == ["b", "a"] and out["b"].dtype == np.float64
    ordered = check_positions(src, expected=["a", "b"])
    assert list(ordered) == ["a", "b"]
    ordered["a"][0] = 9.0  # a copy: the caller's array is untouched
    assert src["a"][0] == 0.5


@pytest.mark.parametrize(
    ("objects", "kwargs", "match"),
    [
        (
            [1, 2, 3],
            {},
            r"objects must be a dict mapping object names to positions \(3,\), got list",
        ),
        ({"": [0, 0, 0]}, {}, "keys must be non-empty strings"),
        ({3: [0, 0, 0]}, {}, "keys must be non-empty strings, got 3"),
        ({"joint": [0, 0, 0]}, {}, "'joint' is reserved for the joint-space constraint"),
        ({"a": [0, 0]}, {}, r"objects\['a'\] must have shape \(3,\), got \(2,\)"),
        ({"a": [0, np.nan, 0]}, {}, r"objects\['a'\] must be finite"),
        (
            {"a": [0, 0, 0], "x": [0, 0, 0]},
            {"expected": ["a"]},
            r"unknown object name\(s\) \['x'\]",
        ),
        ({"a": [0, 0, 0]}, {"expected": ["a", "b"]}, r"missing position\(s\) for \['b'\]"),
        ({"a": [0, 0, 0]}, {"expected": ["b"], "what": "the push task"}, "the push task knows"),
    ],
)
def test_check_positions_errors(objects: object, kwargs: dict[str, object], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        check_positions(objects, **kwargs)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("value", "match"),
    [
        ([1.0 + 2.0j, 3.0], r"x must be an array of numbers, got complex \(not real\) values "),
        (np.array([1.0, 2.0], dtype=np.complex64), r"got complex .*\(dtype complex64\)"),
        (["1.5", "2"], r"x must be an array of numbers, got strings \(dtype <U3\)"),
        (np.array([b"1"]), r"got bytes \(dtype \|S1\)"),
        (np.array(["2020-01-01"], dtype="datetime64[D]"), r"got dates"),
        ([True, False], r"x must be an array of numbers, got booleans \(dtype bool\)"),
        ([1, None, "a"], r"x must be an array of numbers, got list"),
    ],
)
def test_check_array_refuses_what_is_not_real_numbers(value: object, match: str) -> None:
    """Issue 22: complex values lost their imaginary part, strings were parsed, booleans taken
    for joint angles."""
    with pytest.raises(ValueError, match=match):
        check_array(value, "x", allow_bool=False)  # type: ignore[arg-type]


def test_check_array_converts_real_numbers_as_before() -> None:
    ints = check_array([1, 2, 3], "x")
    assert ints.dtype == np.float64 and ints.flags.c_contiguous
    np.testing.assert_array_equal(ints, [1.0, 2.0, 3.0])
    floats = np.arange(6.0)
    assert check_array(floats, "x") is floats  # no copy
    np.testing.assert_array_equal(check_array(np.float32([0.5]), "x"), [0.5])
    np.testing.assert_array_equal(check_array([True, False], "gripper"), [1.0, 0.0])
    # Python numbers beyond int64 and Fractions make object arrays: converted one by one.
    np.testing.assert_array_equal(check_array([2**70, Fraction(1, 4)], "x"), [2.0**70, 0.25])
