"""What a skill does with the demonstrations it keeps (private): learn one more at once, say
where it is unsure and where to demonstrate next (:doc:`/active`). :class:`pbdkit.Skill` has
these methods."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Self

import numpy.typing as npt

from ..data._demonstration import Demonstration
from ._suggest import Suggestion, suggest
from ._uncertainty import PARTS, Uncertainty, uncertainty
from ._update import update_skill

__all__ = ["ActiveMixin"]


class ActiveMixin:
    """:meth:`update`, :meth:`uncertainty` and :meth:`suggest` of :class:`pbdkit.Skill`."""

    def update(self, new: Demonstration | Sequence[Demonstration]) -> Self:
        """The skill that has also learned ``new`` (a demonstration or several).

        All the demonstrations are encoded again (aligned in time as the skill was learned),
        each space's EM starting from its GMM with its K kept, unless K is chosen (``"auto"``)
        and the demonstrations have doubled since it was chosen or a new one is not predicted
        (its left-out error over twice the others' worst): then that space chooses K again,
        as :meth:`learn` does (``selection_[space].n_folds`` is the number of demonstrations
        K was chosen with). Its cost and how far its reproductions are from a refit's:
        :doc:`/active`, "One more demonstration".

        Parameters
        ----------
        new : Demonstration or sequence of Demonstration
            With the joints, objects and gripper of the skill's demonstrations.

        Returns
        -------
        skill : Skill
            A new skill; this one is unchanged.

        Raises
        ------
        ValueError
            One line: the skill does not keep its demonstrations (:attr:`demonstrations_` is
            None: a version 1 or 2 file, or built by hand; re-learn it), or ``new`` is empty or
            does not match them.
        """
        return update_skill(self, new)  # type: ignore[no-any-return]

    def uncertainty(
        self, objects: Mapping[str, npt.ArrayLike], *, parts: Sequence[str] = PARTS
    ) -> Uncertainty:
        """How unsure the skill is at this placement of its objects, from the model alone.

        Parameters
        ----------
        objects : dict str -> array-like
            A placement of every object of the skill, as :meth:`reproduce` takes them.
        parts : sequence of str
            The candidate measures to compute (``"placement"``, ``"ensemble"``,
            ``"conflict"``, ``"reach"``; the score's is always computed). The first call that
            asks for ``"ensemble"`` learns the skills that leave one demonstration out.

        Returns
        -------
        Uncertainty
            ``score`` (larger: less sure) and ``parts``; what each measures and which one is
            the score, and why: :doc:`/active`.

        Raises
        ------
        ValueError
            One line: the skill does not keep its demonstrations, an object is missing, or a
            part is unknown.
        """
        return uncertainty(self, objects, tuple(parts))

    def suggest(
        self, ranges: Mapping[str, Mapping[str, object]], n: int = 1, *, seed: int = 0
    ) -> list[Suggestion]:
        """Where a new demonstration would help the skill most, inside the ranges allowed.

        Parameters
        ----------
        ranges : dict str -> dict
            Per object to place, ``{"low": (3,), "high": (3,), "yaw": (lo, hi) or None}`` in
            the robot's base frame (m, rad). An object of the skill without a range stays at
            its first demonstration's place; with a yaw range it is placed as a pose.
        n : int
            How many suggestions (1 .. 100): each counts as demonstrated for the next, so they
            spread out.
        seed : int
            Seeds the candidate placements (a scrambled Halton sequence).

        Returns
        -------
        list of Suggestion
            ``objects`` (every object of the skill) and ``score`` (the uncertainty there), the
            one whose demonstration would lower the uncertainty over the ranges most first
            (:doc:`/active`, "Where to demonstrate next"); placements the arm cannot reach are
            left out, so fewer than ``n`` when the ranges hold fewer.

        Raises
        ------
        ValueError
            One line: the skill does not keep its demonstrations, or a range is malformed or
            names an object the skill does not have.
        """
        return suggest(self, ranges, n, seed=seed)
