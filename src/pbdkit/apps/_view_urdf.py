"""The arm of ``pbdkit view --skill`` drawn from its URDF (:class:`UrdfArm`): yourdfpy's meshes
through viser's ``ViserUrdf``, and a stick figure through the links (for a URDF without visual
geometry, or one whose mesh files are not found: one line says so, :func:`missing_meshes`);
:func:`check_arm_urdf` checks a URDF given for it first. Imported only when the view runs (the
``view`` extra).
"""

from __future__ import annotations

import contextlib
import io
import logging
import os
import xml.etree.ElementTree as ET
from collections.abc import Iterator, Sequence
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from .._validation import short

if TYPE_CHECKING:
    import viser


__all__ = ["UrdfArm", "arm_urdf", "check_arm_urdf", "joint_order", "missing_meshes"]

Float = NDArray[np.float64]

#: A URDF file larger than this is refused (its meshes are separate files).
URDF_MAX_BYTES = 64 * 2**20

_log = logging.getLogger(__name__)


@contextlib.contextmanager
def _quiet_yourdfpy() -> Iterator[None]:
    """yourdfpy logs a file it cannot parse as errors on stderr before it raises: the caller
    reports it in one line."""
    logger = logging.getLogger("yourdfpy.urdf")
    disabled = logger.disabled
    logger.disabled = True
    try:
        yield
    finally:
        logger.disabled = disabled


class _Held(logging.Handler):
    """Keeps the records it is given, for the caller to sort."""

    def __init__(self) -> None:
        super().__init__()
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)


def _load(urdf: Path | str, *, meshes: bool, found: dict[str, bool] | None = None) -> Any:
    """``urdf`` (a file, or URDF XML text) loaded with yourdfpy; meshes beside a file (for
    text, from the working directory: yourdfpy's default). ``found``: filled with each mesh
    file the URDF names (as it names it) and whether it was found."""
    import yourdfpy

    lookup = partial(
        yourdfpy.filename_handler_magic, dir=urdf.parent if isinstance(urdf, Path) else ""
    )

    def handler(fname: str) -> str:
        path: str = lookup(fname=fname)  # the name itself when nothing is found
        if found is not None:
            found.setdefault(fname, os.path.isfile(path))
        return path

    source = str(urdf) if isinstance(urdf, Path) else io.StringIO(urdf)
    return yourdfpy.URDF.load(
        source, build_scene_graph=meshes, load_meshes=meshes, filename_handler=handler
    )


def missing_meshes(missing: Sequence[str], n_files: int, what: str) -> str:
    """The line that says the mesh files ``missing`` (as the URDF names them, at least one; of
    the ``n_files`` it names) of the URDF ``what`` were not found, and how the arm is drawn."""
    n = len(missing)
    named = short(missing[0]) if n == 1 else f"e.g. {short(missing[0])}"
    if n == n_files:
        count = "1 file:" if n == 1 else f"{n} files,"
        return f"{what}: meshes not found ({count} {named}): the arm is drawn as a stick figure"
    return (
        f"{what}: {n} of its {n_files} mesh files not found ({named}): the arm is drawn "
        "without them, and as a stick figure"
    )


def _load_drawn(urdf: Path | str, what: str) -> Any:
    """``urdf`` (``what`` in a message) loaded with its meshes (:func:`_load`). yourdfpy logs
    two lines for each mesh file it cannot find (a page of them for an arm's URDF copied without
    its meshes) although the stick figure draws the arm without them: they become one line
    (:func:`missing_meshes`, a warning of this module's logger); whatever else it logs goes out
    as it came."""
    logger = logging.getLogger("yourdfpy.urdf")
    held = _Held()
    handlers, propagate = logger.handlers, logger.propagate
    found: dict[str, bool] = {}
    logger.handlers, logger.propagate = [held], False
    try:
        return _load(urdf, meshes=True, found=found)
    finally:
        logger.handlers, logger.propagate = handlers, propagate
        missing = [name for name, ok in found.items() if not ok]
        for record in held.records:
            if not any(name in record.getMessage() for name in missing):
                logger.handle(record)
        if missing:
            _log.warning(missing_meshes(missing, len(found), what))


def joint_order(
    urdf_joints: Sequence[str], joint_names: Sequence[str], name: str, what: str = "the URDF"
) -> list[int]:
    """Where each of the arm's joints ``joint_names`` is among a URDF's actuated joints
    ``urdf_joints``: by name when the URDF has them all, else in order when it has as many.

    Raises
    ------
    ValueError
        Neither: the URDF would draw another arm, or one that does not move.
    """
    urdf_joints, joint_names = list(urdf_joints), list(joint_names)
    if all(j in urdf_joints for j in joint_names):
        return [urdf_joints.index(j) for j in joint_names]
    if len(urdf_joints) == len(joint_names):
        return list(range(len(joint_names)))
    raise ValueError(
        f"{name}: {what} has {len(urdf_joints)} moving joints {short(urdf_joints)}, the "
        f"skill's arm {len(joint_names)} {short(joint_names)}: give a URDF of the skill's arm"
    )


def check_arm_urdf(urdf: Path | str, joint_names: Sequence[str], name: str = "--robot") -> None:
    """Check that ``urdf`` (a file, or URDF XML text) is a URDF that can draw an arm of the
    joints ``joint_names`` (:func:`joint_order`), before the page is built.

    Raises
    ------
    ValueError
        It is not a URDF (larger than :data:`URDF_MAX_BYTES`, not UTF-8 XML, no ``<robot>``
        root, or yourdfpy cannot read it), or not of this arm.
    """
    what = short(str(urdf)) if isinstance(urdf, Path) else "the URDF text"
    if isinstance(urdf, Path) and urdf.stat().st_size > URDF_MAX_BYTES:
        raise ValueError(
            f"{name}: {what} is not a URDF ({urdf.stat().st_size} bytes, more than "
            f"{URDF_MAX_BYTES}: meshes are separate files)"
        )
    try:
        text = urdf.read_text(encoding="utf-8") if isinstance(urdf, Path) else urdf
        root = ET.fromstring(text)
    except (UnicodeDecodeError, ET.ParseError) as exc:
        raise ValueError(f"{name}: {what} is not a URDF (not XML: {short(str(exc))})") from None
    if root.tag != "robot":
        raise ValueError(
            f"{name}: {what} is not a URDF (its root element is {short(root.tag)}, not 'robot')"
        )
    try:
        with _quiet_yourdfpy():
            loaded = _load(urdf, meshes=False)
    except Exception as exc:  # yourdfpy raises KeyError, TypeError ... on a bad element
        reason = " ".join(str(exc).split()) or type(exc).__name__
        raise ValueError(f"{name}: {what} is not a URDF ({short(reason)})") from None
    if not loaded.robot.links:
        raise ValueError(f"{name}: {what} is not a URDF (no links)")
    joint_order(loaded.actuated_joint_names, joint_names, name, what)


def arm_urdf(robot: str | None, arm: Any) -> Path | str | None:
    """``pbdkit view --robot``: the URDF to draw the skill's arm ``arm`` (a Robot) from: a file,
    or a shipped robot's (its file, or its URDF text); None (``robot`` None): the skill's own.

    Raises
    ------
    ValueError
        A shipped robot of another number of joints than ``arm``; no such file; a file that
        is not a URDF, or not of this arm (:func:`check_arm_urdf`). The message names --robot.
    """
    from .. import robots

    if robot is None:
        return None
    urdf: Path | str
    if robot in robots.available():
        named = robots.load(robot)
        if named.n_joints != arm.n_joints:
            raise ValueError(
                f"--robot: {robot} has {named.n_joints} joints, the skill's arm "
                f"{arm.n_joints} {short(arm.joint_names)}: name the skill's arm, or leave "
                "--robot out to draw the URDF the skill file keeps"
            )
        urdf = robots.katana_urdf_path() if robot == "katana" else named.urdf
    else:
        urdf = Path(robot)
        if not urdf.is_file():
            raise ValueError(
                f"--robot must be a URDF file or one of {', '.join(robots.available())}, "
                f"got {short(robot)} ({'a directory' if urdf.is_dir() else 'no such file'})"
            )
    check_arm_urdf(urdf, arm.joint_names, "--robot")
    return urdf


class UrdfArm:
    """The arm drawn from a URDF with yourdfpy (viser's ``ViserUrdf``), plus a stick figure
    through its links' origins (a URDF without visual geometry, such as one made from a DH
    table, still shows)."""

    def __init__(self, server: viser.ViserServer, robot: Any, urdf: Path | str | None) -> None:
        from viser.extras import ViserUrdf

        if urdf is None:
            loaded = _load_drawn(robot.urdf, "the skill's URDF")
        else:
            loaded = _load_drawn(urdf, short(str(urdf)) if isinstance(urdf, Path) else "the URDF")
        self.urdf = loaded
        self.viser_urdf = ViserUrdf(server, loaded, root_node_name="/arm")
        names = list(self.viser_urdf.get_actuated_joint_names())
        self._index = joint_order(names, robot.joint_names, "urdf")
        self._cfg = np.zeros(len(names))
        self._links = [j.child for j in loaded.robot.joints]
        self._parents = [j.parent for j in loaded.robot.joints]
        self._base = loaded.base_link
        self._server = server
        self.sticks: Any = None

    def show(self, q: Float) -> None:
        for i, k in enumerate(self._index):
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
