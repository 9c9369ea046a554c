"""The docs' sources (docs/): the public names are documented where they are defined. The build
itself (``make docs``, in ``make test``) checks the rest with warnings as errors; these catch the
common breaks in the fast tests. The README's commands and code: tests/test_readme.py."""

from __future__ import annotations

import importlib
import inspect
import sys
from pathlib import Path
from types import ModuleType

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"


@pytest.fixture(scope="module")
def ext() -> ModuleType:
    pytest.importorskip("sphinx")
    sys.path.insert(0, str(DOCS / "_ext"))
    try:
        return importlib.import_module("pbdkit_docs")
    finally:
        sys.path.remove(str(DOCS / "_ext"))


def test_every_public_class_and_function_has_a_summary(ext: ModuleType) -> None:
    # A package's page documents its __all__ (its modules are private and have no page of
    # their own); the names table of the API reference shows each docstring's first paragraph.
    missing = []
    for package in ext.PUBLIC_PACKAGES:
        module = importlib.import_module(package)
        missing += [
            f"{package}.{name}"
            for name in module.__all__
            if (inspect.isclass(obj := getattr(module, name)) or inspect.isroutine(obj))
            and not (inspect.getdoc(obj) or "").strip()
        ]
    assert missing == []
