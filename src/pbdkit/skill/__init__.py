"""The skill: demonstrations encoded by one GMM per space, reproduced for new placements
(:class:`Skill`), its controllers by name (:func:`controller_names`), where it is unsure
(:class:`Uncertainty`, :meth:`Skill.uncertainty`) and where to demonstrate next
(:class:`Suggestion`, :meth:`Skill.suggest`).

The top of the library: above :mod:`pbdkit.reproduction`; never imports the simulator, OpenCV
or matplotlib."""

from __future__ import annotations

from ._naming import controller_names
from ._skill import Skill
from ._suggest import Suggestion
from ._uncertainty import Uncertainty

__all__ = ["Skill", "Suggestion", "Uncertainty", "controller_names"]
