"""The paper's vision system in the simulated world: object positions from the two cameras.

The experiment's object positions came from a stereo pair of 320x240 webcams tracking colored
patches (paper Sec. III, 5.9 +- 2.8 mm). Here the same :class:`pbdkit.vision.StereoTracker` runs on
the simulator's renders, calibrated the way a real session would be, with nothing hard-coded:

- cameras: K, R, t from :meth:`Simulation.camera_parameters` (or given, e.g. with a deliberate
  pose error, :meth:`pbdkit.vision.PinholeCamera.perturbed`);
- colors: one CbCr Gaussian per tracked object, fitted on a labelled image pair of the scene at
  the nominal placement. The labels are MuJoCo's segmentation rendering: a pixel belongs to an
  object's patch when the geom drawn there is one of the patch's geoms (the task's
  :attr:`pbdkit.sim.tasks.TaskSpec.patches`). Both cameras' pixels are pooled, so the model
  covers both views' shading;
- bias: a per-object offset measured once at the same calibration placement (see below).

Bias correction: why an offset, and not tracked positions in the demonstrations
-------------------------------------------------------------------------------
The cameras measure the centroid of what they see of a patch, which is not the object's reference
point (:mod:`pbdkit.sim.tasks`): they see the front half of the glass's red band, and the top face
plus the near rim of the coaster. Measured over 100 random placements per task
(``benchmarks/bench_tracking.py``, error = tracked - true, mm): the glass reads 11.9 low on the
shelf (coaster task) and 16.2 low on the table (basin task, seen more from above), the coaster
3.8 low, each with a spread of at most 0.7 mm per axis. The bias is a property of the object, its
support and the camera rig, nearly constant over a task's placement range, so it is calibrated
once per task, like the colors: the object stands at a known place (the nominal placement), and
``offset = true position - tracked position`` (:class:`pbdkit.vision.StereoTracker`'s
``offsets``). The corrected error is 0.5-1.0 +- 0.3-0.5 mm (max 2.4 mm), against 4-16 mm raw.
Corrected positions estimate the same point the teacher and the success criteria use, and their
error against the truth is the figure to compare with the paper's 5.9 +- 2.8 mm.

The alternative, recording tracked positions as the demonstrations' object positions (as in the
paper, where one vision system served both phases), cancels a constant bias too, but only inside
the skill: positions stay off by ~12 mm for anything else (plots, the reach checks of
:meth:`pbdkit.Skill.reproduce`, a skill shared with ground-truth users), and it cancels nothing of
the placement-dependent part either. The offset gives the same cancellation and keeps every
position in one frame. It also absorbs most of a small camera-pose error when measured with the
miscalibrated cameras (camera b off by 1 mm and 0.1 deg: 0.75 mm mean error with the offsets
measured afterwards, 2.6 mm with offsets measured before the camera moved).

Occlusion is not detected (see :class:`pbdkit.vision.Track`): the arm must be out of the
cameras' way while they look. With the arm at rest (q = 0) its fingers hide part of a coaster
placed near the robot (up to 10 mm error) or of the glass on the table (up to 32 mm); at the
skill's start posture (hand raised in front of the robot) nothing is hidden.

Failures are never hidden: :func:`observed_objects` raises :class:`ObjectNotSeenError` (with every
object's :class:`pbdkit.vision.Track`) when a tracked object has no position; there is no
fallback to the simulator's ground truth.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._validation import check_array, check_positions
from ..vision import ColorModel, PinholeCamera, StereoTracker, Track
from .scene import CAMERAS, Simulation
from .tasks import tracked_objects  # re-exported: the objects the cameras track

__all__ = [
    "Calibration",
    "ObjectNotSeenError",
    "SimTracker",
    "label_patches",
    "observed_objects",
    "patch_geom_ids",
    "tracked_objects",
]

Float = NDArray[np.float64]


class ObjectNotSeenError(RuntimeError):
    """A tracked object has no position in the current frame pair.

    Attributes
    ----------
    tracks : dict str -> Track
        Every tracked object's result for the frame (statuses, blobs), for diagnosis.
    missing : list of str
        The objects without a position.
    """

    def __init__(self, tracks: Mapping[str, Track]) -> None:
        self.tracks = dict(tracks)
        self.missing = [k for k, tr in self.tracks.items() if not tr.ok]
        detail = ", ".join(
            f"{k}: {self.tracks[k].status} (blob areas {self.tracks[k].area_a}, "
            f"{self.tracks[k].area_b} px)"
            for k in self.missing
        )
        super().__init__(
            f"the cameras did not locate {self.missing}: {detail}; statuses: 'not_visible_X' = "
            "no patch in camera X, 'clipped_X' = patch cut by the image border, 'ambiguous_X' = "
            "two blobs, 'inconsistent' = the views disagree. Move the object into both cameras' "
            "view, or run with ground-truth positions (--ground-truth)"
        )


def patch_geom_ids(sim: Simulation, name: str) -> NDArray[np.intp]:
    """Geom ids of the colored patch of object ``name`` in ``sim``'s scene.

    The geoms are those whose name starts with the task's prefix for the object
    (:attr:`pbdkit.sim.tasks.TaskSpec.patches`: e.g. the glass's red band is 12 thin boxes
    ``glass_patch0..11``, the coaster one blue cylinder ``coaster``).

    Parameters
    ----------
    sim : Simulation
    name : str
        An object with a patch in the task's ``patches``.

    Returns
    -------
    ids : ndarray of int, shape (n_geoms,)
        At least one id.
    """
    patches = sim.info.spec.patches
    if name not in patches:
        raise ValueError(
            f"objects: no colored patch is known for {name!r} in the {sim.info.task!r} task; "
            f"expected one of {sorted(patches)}"
        )
    prefix = patches[name]
    model = sim.model
    ids = np.array(
        [i for i in range(model.ngeom) if model.geom(i).name.startswith(prefix)], dtype=np.intp
    )
    if ids.size == 0:
        raise ValueError(
            f"objects: the scene has no geom named {prefix!r}... for {name!r} (is {name!r} an "
            "object of this task?)"
        )
    return ids


def label_patches(
    sim: Simulation, camera: str, objects: Sequence[str]
) -> dict[str, NDArray[np.bool_]]:
    """Pixels of each object's patch in one camera's image, from a segmentation render.

    Parameters
    ----------
    sim : Simulation
        The scene in its current state.
    camera : str
        One of ``sim.info.cameras``.
    objects : sequence of str
        Objects with a patch (the task's ``patches``).

    Returns
    -------
    masks : dict str -> ndarray of bool, shape (height, width)
        True where the front-most surface is one of the object's patch geoms (occluded parts are
        not labelled), aligned with :meth:`Simulation.render` of the same camera.
    """
    ids = {name: patch_geom_ids(sim, name) for name in objects}
    cam_id = sim.camera_id(camera)
    *_, width, height = sim.camera_parameters(camera)
    renderer = mujoco.Renderer(sim.model, height, width)
    try:
        renderer.enable_segmentation_rendering()
        renderer.update_scene(sim.data, camera=cam_id)
        seg = np.asarray(renderer.render())  # (H, W, 2): object id, object type
    finally:
        renderer.close()
    is_geom = seg[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM)
    return {name: is_geom & np.isin(seg[..., 0], idx) for name, idx in ids.items()}


@dataclass(frozen=True)
class Calibration:
    """What :meth:`SimTracker.from_simulation` measured at the calibration placement.

    Attributes
    ----------
    placement : dict str -> ndarray, shape (3,)
        True object positions during calibration.
    pixels : dict str -> tuple of int
        Labelled patch pixels per camera (a, b) used to fit each color model.
    raw_positions : dict str -> ndarray, shape (3,)
        Tracked positions before the offset correction.
    """

    placement: dict[str, Float]
    pixels: dict[str, tuple[int, int]]
    raw_positions: dict[str, Float]


class SimTracker:
    """The stereo tracker of a simulated scene: two renders -> object positions.

    Build it with :meth:`from_simulation` (cameras, colors and offsets calibrated on the scene).

    Parameters
    ----------
    tracker : StereoTracker
        Calibrated tracker; its ``cam_a`` / ``cam_b`` are the cameras ``cameras``.
    cameras : (str, str)
        Simulator camera names of ``tracker.cam_a`` and ``tracker.cam_b``.
    calibration : Calibration, optional
        What the calibration measured (for reports).

    Attributes
    ----------
    tracker : StereoTracker
    cameras : (str, str)
    objects : tuple of str
        Tracked objects (the tracker's models).
    calibration : Calibration or None
    """

    def __init__(
        self,
        tracker: StereoTracker,
        cameras: tuple[str, str] = (CAMERAS[0], CAMERAS[1]),
        calibration: Calibration | None = None,
    ) -> None:
        if not isinstance(tracker, StereoTracker):
            raise ValueError(f"tracker must be a StereoTracker, got {type(tracker).__name__}")
        if len(cameras) != 2 or cameras[0] == cameras[1]:
            raise ValueError(f"cameras must be two different camera names, got {cameras!r}")
        self.tracker = tracker
        self.cameras = (str(cameras[0]), str(cameras[1]))
        self.objects = tuple(tracker.models)
        self.calibration = calibration

    def __repr__(self) -> str:
        return f"SimTracker(objects={list(self.objects)}, cameras={list(self.cameras)})"

    @classmethod
    def from_simulation(
        cls,
        sim: Simulation,
        objects: Sequence[str] | None = None,
        *,
        cameras: tuple[str, str] = (CAMERAS[0], CAMERAS[1]),
        calibrated_cameras: tuple[PinholeCamera, PinholeCamera] | None = None,
        at_nominal: bool = True,
        correct_bias: bool = True,
        arm: npt.ArrayLike | None = None,
        **tracker_options: Any,
    ) -> SimTracker:
        """Calibrate a tracker on a simulated scene, as a calibration session would.

        With ``at_nominal`` (default), a separate scene of ``sim``'s task is built with every
        object at its nominal place (the centre of its placement range) and ``sim`` is left
        untouched; otherwise ``sim`` is used in its current state. On that scene: one RGB render
        and one segmentation render per camera; each object's color model is fitted on its
        labelled patch pixels of both images; then, with ``correct_bias``, the tracker runs on
        the same images and ``offset = true position - tracked position`` per object.

        Parameters
        ----------
        sim : Simulation
            A scene of the task to track.
        objects : sequence of str, optional
            Objects to track; default: those of the task that move (:func:`tracked_objects`).
        cameras : (str, str)
            Simulator camera names (a, b).
        calibrated_cameras : (PinholeCamera, PinholeCamera), optional
            The cameras as calibrated; default: exact, from :meth:`Simulation.camera_parameters`.
            Give e.g. ``cam.perturbed(0.001, 0.1)`` to study a calibration error (the offsets are
            then measured with those cameras, as they would be in a real session).
        at_nominal : bool
            Calibrate at the nominal placement (True) or on ``sim`` as it is (False).
        correct_bias : bool
            Measure and apply the per-object offset (see the module docstring).
        arm : array-like, shape (n,), optional
            Arm joint angles during the calibration (e.g. the skill's start posture, out of the
            cameras' way); default: as the scene has them (with ``at_nominal``: at rest, q = 0,
            where the fingers can hide part of a coaster placed near the robot).
        **tracker_options
            Passed to :class:`pbdkit.vision.StereoTracker` (``threshold``, ``min_area``, ...).

        Returns
        -------
        SimTracker

        Raises
        ------
        ValueError
            Unknown object or camera; a patch that no camera shows at the calibration placement;
            or (with ``correct_bias``) an object the calibrated tracker cannot locate there.
        """
        spec = sim.info.spec
        names = tuple(spec.tracked_objects if objects is None else objects)
        if not names:
            raise ValueError(f"objects must name at least one object to track, got {objects!r}")
        unknown = sorted(set(names) - set(sim.info.objects))
        if unknown:
            raise ValueError(
                f"objects: {unknown} are not objects of the {spec.name!r} task; expected some of "
                f"{sorted(sim.info.objects)}"
            )
        for cam in cameras:
            sim.camera_id(cam)
        calib = Simulation.from_task(spec, spec.nominal_objects()) if at_nominal else sim
        try:
            if arm is not None:
                calib.set_joints(check_array(arm, "arm", shape=(calib.n_joints,)))
            images, masks = [], []
            for cam in cameras:
                masks.append(label_patches(calib, cam, names))
                images.append(calib.render(cam))
            models: dict[str, ColorModel] = {}
            pixels: dict[str, tuple[int, int]] = {}
            for name in names:
                counts = (int(masks[0][name].sum()), int(masks[1][name].sum()))
                pixels[name] = counts
                if min(counts) == 0:
                    raise ValueError(
                        f"objects: the patch of {name!r} is not visible in camera "
                        f"{cameras[counts.index(0)]!r} at the calibration placement "
                        f"({counts[0]} and {counts[1]} labelled pixels)"
                    )
                models[name] = ColorModel.fit(images, [m[name] for m in masks])
            if calibrated_cameras is None:
                cam_a = PinholeCamera(*calib.camera_parameters(cameras[0]))
                cam_b = PinholeCamera(*calib.camera_parameters(cameras[1]))
            else:
                cam_a, cam_b = calibrated_cameras
            tracker = StereoTracker(cam_a, cam_b, models, **tracker_options)
            tracks = tracker.track(images[0], images[1])
            truth = calib.object_positions()
        finally:
            if at_nominal:
                calib.close()
        raw = {k: tr.position.copy() for k, tr in tracks.items() if tr.position is not None}
        if correct_bias:
            if len(raw) < len(names):
                raise ValueError(
                    "objects: cannot measure the tracking offsets at the calibration placement: "
                    f"{ObjectNotSeenError(tracks)}"
                )
            offsets = {k: truth[k] - raw[k] for k in names}
            options = {**tracker_options, "offsets": offsets}
            tracker = StereoTracker(cam_a, cam_b, models, **options)
        placement = {k: np.asarray(truth[k], dtype=np.float64) for k in names}
        return cls(tracker, cameras, Calibration(placement, pixels, raw))

    @property
    def offsets(self) -> dict[str, Float]:
        """Per-object offset added to the triangulated centroid, name -> (3,) (metres)."""
        return {k: v.copy() for k, v in self.tracker.offsets.items()}

    def images(self, sim: Simulation) -> tuple[NDArray[np.uint8], NDArray[np.uint8]]:
        """The two camera frames of ``sim``'s current state, each (240, 320, 3) uint8 RGB."""
        return sim.render(self.cameras[0]), sim.render(self.cameras[1])

    def locate(self, sim: Simulation) -> dict[str, Track]:
        """One tracker cycle: render both cameras, track, triangulate.

        Parameters
        ----------
        sim : Simulation
            The scene in its current state (the same task as the calibration).

        Returns
        -------
        tracks : dict str -> Track
            One per tracked object; ``track.position`` (3,) only when ``track.status == "ok"``.
        """
        img_a, img_b = self.images(sim)
        return self.tracker.track(img_a, img_b)


def observed_objects(
    sim: Simulation,
    tracker: SimTracker,
    fixed: Mapping[str, npt.ArrayLike] | None = None,
) -> dict[str, Float]:
    """Object positions as the robot knows them: tracked objects from the cameras, plus fixed ones.

    Parameters
    ----------
    sim : Simulation
        The scene in its current state.
    tracker : SimTracker
        Calibrated on the same task.
    fixed : dict str -> array-like, shape (3,), optional
        Positions known without vision (the basin); they must not be tracked objects.

    Returns
    -------
    objects : dict str -> ndarray, shape (3,)
        Tracked objects first (tracker order), then the fixed ones.

    Raises
    ------
    ObjectNotSeenError
        If a tracked object has no position (not visible, clipped, ambiguous, inconsistent);
        the error carries every track.
    ValueError
        If ``fixed`` names a tracked object or holds a position that is not a finite (3,) vector.
    """
    known = check_positions(fixed or {}, "fixed")
    for name in known:
        if name in tracker.objects:
            raise ValueError(
                f"fixed[{name!r}]: {name!r} is tracked by the cameras; fixed objects must be "
                f"others than {list(tracker.objects)}"
            )
    tracks = tracker.locate(sim)
    if not all(tr.ok for tr in tracks.values()):
        raise ObjectNotSeenError(tracks)
    out = {k: np.asarray(tr.position, dtype=np.float64).copy() for k, tr in tracks.items()}
    out.update(known)
    return out
