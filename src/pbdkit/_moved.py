"""Module paths of before the layer sub-packages (0.1), kept importable for one release.

``import pbdkit.gmm`` still works and gives :mod:`pbdkit.prob.gmm` itself (the same module
object, so monkeypatching either name patches both), with a :class:`DeprecationWarning` that
names the new path.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import warnings
from collections.abc import Sequence
from importlib.machinery import ModuleSpec
from types import ModuleType

MOVED = {
    "pbdkit.gaussian": "pbdkit.prob.gaussian",
    "pbdkit.gmm": "pbdkit.prob.gmm",
    "pbdkit.gmr": "pbdkit.prob.gmr",
    "pbdkit.robot": "pbdkit.robots.model",
    "pbdkit.kinematics": "pbdkit.robots.kinematics",
    "pbdkit.limits": "pbdkit.motion.limits",
    "pbdkit.otg": "pbdkit.motion.otg",
    "pbdkit.demos": "pbdkit.learning.demonstration",
    "pbdkit.reproduce": "pbdkit.learning.probabilistic_ik",
    "pbdkit.controller": "pbdkit.learning.controller",
    "pbdkit.skill": "pbdkit.learning.skill",
    "pbdkit.datasets": "pbdkit.learning.datasets",
    "pbdkit.bags": "pbdkit.learning.bags",
    "pbdkit.cli": "pbdkit.apps.cli",
    "pbdkit.demo": "pbdkit.apps.demo",
    "pbdkit.plots": "pbdkit.apps.plots",
    "pbdkit.report": "pbdkit.apps.report",
    "pbdkit.sim.study": "pbdkit.apps.study",
}


class _MovedFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    def __init__(self) -> None:
        self._specs: dict[str, ModuleSpec | None] = {}

    def find_spec(
        self, fullname: str, path: Sequence[str] | None, target: ModuleType | None = None
    ) -> ModuleSpec | None:
        if fullname not in MOVED:
            return None
        return importlib.util.spec_from_loader(fullname, self)

    def create_module(self, spec: ModuleSpec) -> ModuleType:
        new = MOVED[spec.name]
        warnings.warn(
            f"{spec.name} is now {new}; the old path goes in pbdkit 0.3",
            DeprecationWarning,
            stacklevel=2,
        )
        module = importlib.import_module(new)
        self._specs[new] = module.__spec__
        return module

    def exec_module(self, module: ModuleType) -> None:
        # The module is the new one, already executed; the import system has just set its
        # __spec__ to the old name's, which would make its own relative imports warn.
        module.__spec__ = self._specs[module.__name__]


def install() -> None:
    """Let the old module paths import (idempotent)."""
    if not any(isinstance(f, _MovedFinder) for f in sys.meta_path):
        sys.meta_path.append(_MovedFinder())
