"""The shared validators: object positions."""

from __future__ import annotations

import numpy as np
import pytest

from pbdkit._validation import check_positions


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
