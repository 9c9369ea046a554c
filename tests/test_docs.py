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
PUBLIC = ("pbdkit", "pbdkit.robots", "pbdkit.sim", "pbdkit.vision")


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


@pytest.mark.parametrize("package", PUBLIC)
def test_every_reexported_name_is_in_its_modules_all(package: str) -> None:
    # The API reference documents a class or function on its defining module's page, which
    # lists that module's __all__: a name a package re-exports but its module leaves out of
    # __all__ has no page (pbdkit.sim.ObjectMove had none).
    module = importlib.import_module(package)
    missing = []
    for name in module.__all__:
        obj = getattr(module, name)
        if (inspect.isclass(obj) or inspect.isroutine(obj)) and obj.__module__ != package:
            home = importlib.import_module(obj.__module__)
            if name not in getattr(home, "__all__", [name]):
                missing.append(f"{package}.{name} ({obj.__module__})")
    assert missing == []
