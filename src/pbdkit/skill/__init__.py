"""The skill: demonstrations encoded by one GMM per space, reproduced for new placements
(:class:`Skill`), and its controllers by name (:func:`controller_names`).

The top of the library: above :mod:`pbdkit.reproduction`; never imports the simulator, OpenCV
or matplotlib."""

from __future__ import annotations

from ._naming import controller_names
from ._skill import Skill

__all__ = ["Skill", "controller_names"]
