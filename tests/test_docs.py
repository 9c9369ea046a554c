"""The docs' sources (docs/): the README sections the pages include exist, the public names are
documented where they are defined. The build itself (``make docs``, in ``make test``) checks the
rest with warnings as errors; these catch the common breaks in the fast tests."""

from __future__ import annotations

import importlib
import inspect
import re
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


def test_every_included_readme_section_exists(ext: ModuleType) -> None:
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    markers = [
        (page.name, m.group(1))
        for page in sorted(DOCS.glob("*.md"))
        for m in re.finditer(r"^% readme-section: (.+?)\s*$", page.read_text(), re.MULTILINE)
    ]
    assert len(markers) >= 9  # the walkthroughs
    for page, heading in markers:
        assert ext.readme_section(readme, heading), f"{page}: README section {heading!r} is empty"


def test_a_readme_section_ends_at_the_next_heading_outside_code(ext: ModuleType) -> None:
    text = "# top\nintro\n## A\none\n```bash\n# a comment, not a heading\n```\n### B\ntwo\n## A2\n"
    assert ext.readme_section(text, "A") == ["one", "```bash", "# a comment, not a heading", "```"]
    assert ext.readme_section(text, "B") == ["two"]
    with pytest.raises(ValueError, match=r"README.md has 0 headings 'Missing', expected 1"):
        ext.readme_section(text, "Missing")
    with pytest.raises(ValueError, match=r"has 2 headings 'A', expected 1"):
        ext.readme_section(text + "## A\n", "A")


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
