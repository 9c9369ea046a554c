"""Self-collision check of one posture: the shipped Katana and Panda (all ``self_pairs`` of
their collision models), coal through pinocchio against MuJoCo on the same URDF.

Run: ``.venv/bin/python benchmarks/bench_collision_model.py``

pbdkit's path: ``pin.computeCollisions`` (placements of the geometry from q, then coal's
collision test of every pair: yes/no) and ``pin.computeDistances`` (signed distance of every
pair), on a GeometryModel holding the collision model's ``self_pairs``.

Peers, measured in the same run on the same URDF text and the same pairs: MuJoCo's
``mj_kinematics`` then ``mj_geomDistance`` of each pair (a Python loop, as a caller of that API
writes it), and ``mj_kinematics`` + ``mj_collision`` with the disabled link pairs excluded
(MuJoCo's own C loop: broad phase, then the contacts of the pairs that overlap). Times are
medians over repeats of a pass over 200 random postures within the limits, per posture.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import pinocchio as pin
from _common import fmt_time, median_time, print_table
from numpy.typing import NDArray

from pbdkit import robots
from pbdkit.robots import Robot

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from mujoco_geoms import collision_only_urdf

N_POSTURES = 200
REPEAT = 15


def mujoco_spec(robot: Robot) -> Any:
    """MuJoCo's spec of the robot's URDF text: collision geoms only, one body per link."""
    return mujoco.MjSpec.from_string(collision_only_urdf(robot.urdf))


def per_posture(
    run: Callable[[NDArray[np.float64]], object], postures: NDArray[np.float64]
) -> float:
    def loop() -> None:
        for q in postures:
            run(q)

    return median_time(loop, repeat=REPEAT) / len(postures)


def bench(robot: Robot) -> list[list[str]]:
    cm = robot.collision_model
    assert cm is not None
    geometry = cm.geometry.clone()
    for i, j in cm.self_pairs:
        geometry.addCollisionPair(pin.CollisionPair(i, j))
    data, gdata = cm.model.createData(), pin.GeometryData(geometry)

    spec = mujoco_spec(robot)
    for a, b in sorted(cm.disabled):
        spec.add_exclude(bodyname1=a, bodyname2=b)
    m = spec.compile()
    d = mujoco.MjData(m)
    by_body: dict[str, list[int]] = {}
    for g in range(m.ngeom):
        by_body.setdefault(m.body(int(m.geom_bodyid[g])).name, []).append(g)
    seen: dict[str, int] = {}
    mj_geom = []
    for link in cm.links:
        mj_geom.append(by_body[link][seen.setdefault(link, 0)])
        seen[link] += 1
    pairs = [(mj_geom[i], mj_geom[j]) for i, j in cm.self_pairs]
    qpos = [int(m.joint(j).qposadr[0]) for j in robot.joint_names]
    fromto = np.zeros(6)

    def coal_collisions(q: NDArray[np.float64]) -> bool:
        return bool(pin.computeCollisions(cm.model, data, geometry, gdata, q, False))

    def coal_distances(q: NDArray[np.float64]) -> int:
        return int(pin.computeDistances(cm.model, data, geometry, gdata, q))

    def mj_distances(q: NDArray[np.float64]) -> list[float]:
        d.qpos[qpos] = q
        mujoco.mj_kinematics(m, d)
        return [mujoco.mj_geomDistance(m, d, a, b, 10.0, fromto) for a, b in pairs]

    def mj_contacts(q: NDArray[np.float64]) -> int:
        d.qpos[qpos] = q
        mujoco.mj_kinematics(m, d)
        mujoco.mj_collision(m, d)
        return int(d.ncon)

    rng = np.random.default_rng(0)
    postures = rng.uniform(robot.lower, robot.upper, (N_POSTURES, robot.n_joints))
    # The four answer the same question, in collision or not (away from contact).
    for q in postures:
        dist = mj_distances(q)
        if min(abs(v) for v in dist) > 1e-3:
            assert coal_collisions(q) == (min(dist) < 0) == (mj_contacts(q) > 0)
    t_coll = per_posture(coal_collisions, postures)
    t_dist = per_posture(coal_distances, postures)
    t_mj_dist = per_posture(mj_distances, postures)
    t_mj_con = per_posture(mj_contacts, postures)
    name = f"{robot.name} ({len(cm.self_pairs)} pairs)"
    return [
        [name, "coal collisions (pinocchio)", fmt_time(t_coll), "1.0x"],
        [name, "coal distances (pinocchio)", fmt_time(t_dist), f"{t_dist / t_coll:.1f}x"],
        [name, "MuJoCo mj_geomDistance loop", fmt_time(t_mj_dist), f"{t_mj_dist / t_coll:.1f}x"],
        [name, "MuJoCo mj_collision (C)", fmt_time(t_mj_con), f"{t_mj_con / t_coll:.1f}x"],
    ]


def main() -> None:
    rows = bench(robots.katana()) + bench(robots.panda())
    print(
        f"Self-collision check of one posture (median over {REPEAT} passes of {N_POSTURES} "
        "random postures); ratio = time / coal collisions"
    )
    print_table(["robot", "check", "per posture", "ratio"], rows)


if __name__ == "__main__":
    main()
