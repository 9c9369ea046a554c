"""The package's public names (pbdkit/__init__.py): each resolves to its module's object, and
none of the numerical libraries is loaded before a name that needs it is used."""

from __future__ import annotations

import importlib
import subprocess
import sys

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
