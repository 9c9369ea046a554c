"""The skill: demonstrations encoded by one GMM per space, reproduced for new placements
(:class:`Skill`), its controllers by name (:func:`controller_names`), and where it is unsure
(:class:`Uncertainty`, :meth:`Skill.uncertainty`).

The top of the library: above :mod:`pbdkit.reproduction`; never imports the simulator, OpenCV
or matplotlib."""

from __future__ import annotations

from ._naming import controller_names
from ._skill import Skill
from ._uncertainty import Uncertainty

__all__ = ["Skill", "Uncertainty", "controller_names"]
