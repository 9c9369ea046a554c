"""The arm of ``pbdkit view --skill`` drawn from its URDF (:class:`UrdfArm`): yourdfpy's meshes
through viser's ``ViserUrdf``, and a stick figure through the links (for a URDF without visual
geometry). Imported only when the view runs (the ``view`` extra).
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    import viser


__all__ = ["UrdfArm"]

Float = NDArray[np.float64]


class UrdfArm:
    """The arm drawn from a URDF with yourdfpy (viser's ``ViserUrdf``), plus a stick figure
    through its links' origins (a URDF without visual geometry, such as one made from a DH
    table, still shows)."""

    def __init__(self, server: viser.ViserServer, robot: Any, urdf: Path | None) -> None:
        from functools import partial

        import yourdfpy
        from viser.extras import ViserUrdf

        if urdf is not None:
            loaded = yourdfpy.URDF.load(
                str(urdf),
                build_scene_graph=True,
                load_meshes=True,
                filename_handler=partial(yourdfpy.filename_handler_magic, dir=urdf.parent),
            )
        else:
            loaded = yourdfpy.URDF.load(
                io.StringIO(robot.urdf), build_scene_graph=True, load_meshes=True
            )
        self.urdf = loaded
        self.viser_urdf = ViserUrdf(server, loaded, root_node_name="/arm")
        names = list(self.viser_urdf.get_actuated_joint_names())
        self._index = [names.index(j) if j in names else -1 for j in robot.joint_names]
        self._cfg = np.zeros(len(names))
        self._links = [j.child for j in loaded.robot.joints]
        self._parents = [j.parent for j in loaded.robot.joints]
        self._base = loaded.base_link
        self._server = server
        self.sticks: Any = None

    def show(self, q: Float) -> None:
        for i, k in enumerate(self._index):
            if k >= 0:
                self._cfg[k] = q[i]
        self.viser_urdf.update_cfg(self._cfg)
        pts = []
        for parent, child in zip(self._parents, self._links, strict=True):
            a = self.urdf.get_transform(parent, self._base)[:3, 3]
            b = self.urdf.get_transform(child, self._base)[:3, 3]
            if np.linalg.norm(b - a) > 1e-6:
                pts.append([a, b])
        if pts:
            self.sticks = self._server.scene.add_line_segments(
                "/arm_sticks",
                points=np.array(pts, dtype=np.float32),
                colors=(60, 60, 60),
                thickness=0.012,
            )
