"""The link pairs self-collision checking can skip, found by sampling postures as MoveIt's setup
assistant does (:func:`disabled_pairs`)."""

from __future__ import annotations

from collections import defaultdict

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from .._validation import short
from ._robot import Robot
from ._srdf import LinkPair, _pair

__all__ = ["MAX_SAMPLES", "disabled_pairs"]

#: The most postures :func:`disabled_pairs` samples (the Panda checks about 14000 a second).
MAX_SAMPLES = 1_000_000


def disabled_pairs(robot: Robot, n: int = 10_000, *, seed: int = 0) -> set[LinkPair]:
    """Link pairs self-collision checking can skip, found as MoveIt's setup assistant does.

    For an arm without an SRDF: save them with :func:`write_srdf` and load the robot with
    ``srdf=``. The robot's own SRDF (if any) is not used: the pairs come from its geometry.

    - Adjacent: joined by a joint, also through links without geometry, or moving as one
      body (see :attr:`CollisionModel.adjacent`);
    - Default: in collision at the default posture, 0 clipped into the joint limits;
    - Always: in collision in each of the ``n`` sampled postures;
    - Never: in collision in none of ``n`` postures drawn uniformly within the joint limits.

    A pair that collides only in a small corner of the joint space may be missed by the
    sampling and disabled as "Never": check the result (more postures find more).

    Parameters
    ----------
    robot : Robot
        With a collision model (:attr:`Robot.has_collision_model`).
    n : int
        Postures sampled, 1 to 10^6 (``pbdkit.robots._pairs.MAX_SAMPLES``); about
        0.1 ms each for the Panda.
    seed : int
        Seed of ``np.random.default_rng``: the same seed gives the same pairs.

    Returns
    -------
    pairs : set of (str, str)
        Link names, each pair sorted alphabetically.

    Raises
    ------
    ValueError
        If the robot has no collision model, or ``n`` or ``seed`` is not valid.
    """
    return set(_disabled_pair_reasons(robot, n, seed))


def _disabled_pair_reasons(robot: Robot, n: int, seed: int) -> dict[LinkPair, str]:
    """:func:`disabled_pairs` with MoveIt's reason of each pair."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 1 <= n <= MAX_SAMPLES:
        raise ValueError(
            f"n must be an integer in [1, {MAX_SAMPLES}] (postures sampled), got {short(n)}"
        )
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be an integer >= 0, got {short(seed)}")
    cm = robot.collision_model
    if cm is None:
        raise ValueError(
            f"robot {short(robot.name)} has no collision model (its URDF has no <collision> "
            "element); add collision geometry to its links"
        )
    reasons = dict.fromkeys(cm.adjacent, "Adjacent")
    check = cm.geometry.clone()
    geom_pairs: dict[LinkPair, list[int]] = defaultdict(list)
    for i in range(len(cm.links)):
        for j in range(i + 1, len(cm.links)):
            link_pair = _pair(cm.links[i], cm.links[j])
            if cm.links[i] != cm.links[j] and link_pair not in cm.adjacent:
                geom_pairs[link_pair].append(len(check.collisionPairs))
                check.addCollisionPair(pin.CollisionPair(i, j))
    link_of = {k: p for p, ks in geom_pairs.items() for k in ks}
    data, gdata = cm.model.createData(), pin.GeometryData(check)
    active = sorted(link_of)

    def colliding(q: NDArray[np.float64]) -> set[LinkPair]:
        pin.computeCollisions(cm.model, data, check, gdata, q, False)
        results = gdata.collisionResults
        return {link_of[k] for k in active if results[k].isCollision()}

    def drop(pairs: set[LinkPair]) -> list[int]:
        for p in pairs:
            for k in geom_pairs[p]:
                gdata.deactivateCollisionPair(k)
        return [k for k in active if link_of[k] not in pairs]

    lower, upper = np.asarray(robot.lower), np.asarray(robot.upper)
    default = colliding(np.clip(np.zeros(robot.n_joints), lower, upper))
    reasons.update(dict.fromkeys(default, "Default"))
    active = drop(default)
    never = set(geom_pairs) - default
    always = set(never)
    rng = np.random.default_rng(int(seed))
    chunk = 1000
    for start in range(0, int(n), chunk):
        for q in rng.uniform(lower, upper, size=(min(chunk, int(n) - start), robot.n_joints)):
            hits, before = colliding(q), never | always
            never -= hits
            always &= hits
            decided = before - never - always
            if decided:
                active = drop(decided)
    reasons.update(dict.fromkeys(always, "Always"))
    reasons.update(dict.fromkeys(never, "Never"))
    return reasons
