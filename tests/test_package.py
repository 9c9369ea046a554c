"""The package's public names (pbdkit/__init__.py): each resolves to its module's object, and
none of the numerical libraries is loaded before a name that needs it is used."""

from __future__ import annotations

import ast
import importlib
import subprocess
import sys
from pathlib import Path

import pytest

import pbdkit

_HEAVY = ("sklearn", "scipy", "pinocchio", "mujoco", "cv2", "matplotlib", "distributed")


def _loaded_after(code: str) -> list[str]:
    probe = f"import sys\n{code}\nprint(' '.join(m for m in {_HEAVY!r} if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    return out.stdout.split()


@pytest.mark.slow
def test_the_command_line_starts_without_the_numerical_libraries() -> None:
    # `pbdkit --help`, and `evaluate --workers` starting its worker server, come first.
    assert _loaded_after("import pbdkit, pbdkit.apps._cli") == []
    assert _loaded_after("import pbdkit\npbdkit.__all__") == []
    # A name that needs them loads them.
    assert {"sklearn", "scipy"} <= set(_loaded_after("import pbdkit\npbdkit.GMM"))
    assert "pinocchio" in _loaded_after("from pbdkit import Robot")


@pytest.mark.parametrize("name", pbdkit.__all__)
def test_every_public_name_is_its_modules_object(name: str) -> None:
    value = getattr(pbdkit, name)
    modules = {"datasets": "pbdkit.datasets", "gaussian": "pbdkit.prob.gaussian"}
    if name in (*modules, "robots"):
        where = {**modules, "robots": "pbdkit.robots"}[name]
        assert value is importlib.import_module(where)
    else:
        assert getattr(importlib.import_module(value.__module__), name) is value
        assert value.__module__.startswith("pbdkit.")
    assert name in dir(pbdkit)


def test_star_import_and_an_unknown_name() -> None:
    scope: dict[str, object] = {}
    exec("from pbdkit import *", scope)
    assert set(pbdkit.__all__) <= set(scope)
    with pytest.raises(AttributeError, match="module 'pbdkit' has no attribute 'Skil'"):
        pbdkit.Skil  # type: ignore[attr-defined]  # noqa: B018


# ----------------------------------------------------------------------------- the house
SRC = Path(pbdkit.__file__).parent


def _public_modules() -> list[tuple[str, Path]]:
    """Every module a user may import: no part of its path starts with an underscore."""
    out = []
    for path in sorted(SRC.rglob("*.py")):
        parts = path.relative_to(SRC.parent).with_suffix("").parts
        parts = parts[:-1] if parts[-1] == "__init__" else parts
        if not any(p.startswith("_") for p in parts) and parts[-1] != "__main__":
            out.append((".".join(parts), path))
    return out


def _all_of(path: Path) -> list[str]:
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        if isinstance(node, ast.Assign | ast.AnnAssign):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            if any(isinstance(t, ast.Name) and t.id == "__all__" for t in targets):
                assert node.value is not None
                return list(ast.literal_eval(node.value))
    return []


def test_the_public_surface_is_what_the_packages_curate() -> None:
    # Implementation modules are private (_name.py); the public modules are the packages'
    # __init__s and the two public sub-modules, whose __all__s are the public surface (the docs
    # show exactly these names): at most 135 names (issue 33: 547 before, 117 after; issue 38's
    # collisions add a package of 7 and 8 names elsewhere).
    modules = dict(_public_modules())
    assert set(modules) == {
        "pbdkit",
        "pbdkit.apps",
        "pbdkit.collision",
        "pbdkit.data",
        "pbdkit.datasets",
        "pbdkit.motion",
        "pbdkit.prob",
        "pbdkit.prob.gaussian",
        "pbdkit.reproduction",
        "pbdkit.robots",
        "pbdkit.ros",
        "pbdkit.sim",
        "pbdkit.skill",
        "pbdkit.vision",
    }
    counts = {name: len(_all_of(path)) for name, path in modules.items()}
    assert all(counts.values()), counts
    assert sum(counts.values()) <= 135, counts
    for name in modules:
        module = importlib.import_module(name)
        for public in module.__all__:
            assert hasattr(module, public), f"{name}.{public}"


def test_every_source_file_is_one_concern_under_800_lines() -> None:
    # A module that needs a table of contents is two modules (house-style.md); its docstring's
    # first line names its one concern.
    too_long, undocumented = [], []
    for path in sorted(SRC.rglob("*.py")):
        text = path.read_text(encoding="utf-8")
        if text.count("\n") > 800:
            too_long.append(f"{path.relative_to(SRC)}: {text.count(chr(10))} lines")
        doc = ast.get_docstring(ast.parse(text))
        if not doc or not doc.splitlines()[0].strip():
            undocumented.append(str(path.relative_to(SRC)))
    assert too_long == []
    assert undocumented == []
