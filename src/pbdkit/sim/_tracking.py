"""The paper's vision system in the simulated world: object positions (and poses) from the two
cameras.

The experiment's object positions came from a stereo pair of 320x240 webcams tracking colored
patches (paper Sec. III, 5.9 +- 2.8 mm). Here the same :class:`pbdkit.vision.StereoTracker` runs on
the simulator's renders, calibrated the way a real session would be, with nothing hard-coded:

- cameras: K, R, t from :meth:`Simulation.camera_parameters` (or given, e.g. with a deliberate
  pose error, :meth:`pbdkit.vision.PinholeCamera.perturbed`);
- colors: one CbCr Gaussian per tracked object, fitted on a labelled image pair of the scene at
  the nominal placement. The labels are MuJoCo's segmentation rendering: a pixel belongs to an
  object's patch when the geom drawn there is one of the patch's geoms (the task's
  :attr:`pbdkit.sim.TaskSpec.patches`). Both cameras' pixels are pooled, so the model
  covers both views' shading;
- bias: a per-object offset measured once at the same calibration placement (see below).

Bias correction: why an offset, and not tracked positions in the demonstrations
-------------------------------------------------------------------------------
The cameras measure the centroid of what they see of a patch, which is not the object's reference
point (:mod:`pbdkit.sim._glass`): they see the front half of the glass's red band, and the top face
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

Objects that turn: a pose from two patches, an offset in the object's frame
------------------------------------------------------------------------------
An object placed as a pose (the slot task's block and tray, :mod:`pbdkit.sim._parts`) carries two
marks, one at each end (:attr:`pbdkit.sim.TaskSpec.patches` gives the pair). Each mark has
its own color model (``NAME:a``, ``NAME:b``: :func:`patch_models`) and is located as any patch;
the object's pose is the marks' midpoint and the heading from mark a to mark b
(:class:`pbdkit.vision.PoseModel`), returned as a 4x4 pose (a yaw about the vertical) where the
other objects get a (3,) position. It is "not seen" unless both marks are.

A constant world offset, as above, assumes the bias does not turn. It does when it belongs to
the object (a point off the line of the marks, a mark seen partly hidden by the object's own
rim): measured at yaw 0, it is wrong by ``2 |b| sin(delta / 2)`` at a yaw ``delta`` away. So a
posed object's position offset is kept in its own frame (``offset_world = R(yaw)
offset_local``), and a yaw offset is measured beside it; both are averaged over five views of
the calibration placement with the objects turned across their yaw range (``pose_views``), so
that the calibration's own noise (0.4 mm in depth per view) is not added to every estimate.
``tests/test_pose_tracking.py`` builds an object whose point lies 30 mm off its marks' line:
calibrated at yaw 0 and turned by up to 60 degrees, a world offset errs by up to 30 mm, the
object-frame offset stays within the tracker's noise. The slot's own marks are flat and
symmetric about the objects' points, so their bias is small either way: over 100 placements
(``benchmarks/bench_pose_tracking.py``, the arm at a start posture), position error mean +- sd
(largest 2.4 mm with the default calibration) and yaw error (largest 1.7 degrees):

========================  =====================  =====================
calibration               block                  tray
========================  =====================  =====================
raw (midpoint, heading)   0.54 +- 0.33 mm        0.52 +- 0.33 mm
world frame, 1 view       0.42 +- 0.37 mm        0.76 +- 0.45 mm
object frame, 1 view      0.42 +- 0.37 mm        0.69 +- 0.43 mm
world frame, 5 views      0.41 +- 0.37 mm        0.45 +- 0.35 mm
object frame, 5 views     0.43 +- 0.36 mm        0.41 +- 0.38 mm
yaw (any calibration)     0.40-0.48 +- 0.37 deg  0.22-0.23 +- 0.24 deg
========================  =====================  =====================

(the tray's lateral error, sd 0.13 mm in the object frame against 0.21 mm in the world's, is
the part of its bias that turns with it). The slot task has its own camera rig
(:data:`pbdkit.sim._taskdefs.slot.CAMERAS`), closer to the objects than the paper's, where a mark
covers 57-170 pixels instead of 12-36.

Occlusion is not detected (see :class:`pbdkit.vision.Track`): the arm must be out of the
cameras' way while they look. With the arm at rest (q = 0) its fingers hide part of a coaster
placed near the robot (up to 10 mm error) or of the glass on the table (up to 32 mm); at the
skill's start posture (hand raised in front of the robot) nothing is hidden.

Failures are never hidden: :func:`observed_objects` raises :class:`ObjectNotSeenError` (with every
object's :class:`pbdkit.vision.Track`) when a tracked object has no position; there is no
fallback to the simulator's ground truth.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._validation import check_array, check_int, check_positions, short
from ..vision import ColorModel, PinholeCamera, PoseModel, PoseTrack, StereoTracker
from ..vision._pose import OffsetFrame, ends_heading
from ..vision._stereo import ObjectTrack
from ._gl import mujoco
from ._scene import Simulation
from ._tasks import TaskSpec, yaw_of, yaw_pose
from ._world import CAMERAS

__all__ = [
    "Calibration",
    "ObjectNotSeenError",
    "SimTracker",
    "label_patches",
    "observed_objects",
    "patch_geom_ids",
    "patch_models",
]

Float = NDArray[np.float64]


class ObjectNotSeenError(RuntimeError):
    """A tracked object has no position in the current frame pair.

    Attributes
    ----------
    tracks : dict str -> Track or PoseTrack
        Every tracked object's result for the frame (statuses, blobs; a posed object's two
        ends), for diagnosis.
    missing : list of str
        The objects without a position (a posed object: without a pose, one end or both not
        located).
    """

    def __init__(self, tracks: Mapping[str, ObjectTrack]) -> None:
        self.tracks = dict(tracks)
        self.missing = [k for k, tr in self.tracks.items() if not tr.ok]
        detail = ", ".join(f"{k}: {_describe(self.tracks[k])}" for k in self.missing)
        super().__init__(
            f"the cameras did not locate {self.missing}: {detail}; statuses: 'not_visible_X' = "
            "no patch in camera X, 'clipped_X' = patch cut by the image border, 'ambiguous_X' = "
            "two blobs, 'inconsistent' = the views disagree. Move the object into both cameras' "
            "view, or run with ground-truth positions (--ground-truth)"
        )


def _describe(track: ObjectTrack) -> str:
    if isinstance(track, PoseTrack):
        return track.describe()
    return f"{track.status} (blob areas {track.area_a}, {track.area_b} px)"


def patch_models(spec: TaskSpec, objects: Sequence[str]) -> dict[str, str]:
    """The color models of the objects' patches: model name -> geom name prefix.

    An object with one patch has one model, named after it; an object placed as a pose has two,
    ``NAME:a`` and ``NAME:b``, its ends (:attr:`pbdkit.sim.TaskSpec.patches`).

    Raises
    ------
    ValueError
        An object without a patch in the task's ``patches``.
    """
    out: dict[str, str] = {}
    for name in objects:
        ends = spec.patch_ends(name)
        if ends is None:
            prefix = spec.patches[name]
            assert isinstance(prefix, str)  # patch_ends said so
            out[name] = prefix
        else:
            out[f"{name}:a"], out[f"{name}:b"] = ends
    return out


def patch_geom_ids(sim: Simulation, name: str) -> NDArray[np.intp]:
    """Geom ids of the colored patch of object ``name`` in ``sim``'s scene.

    The geoms are those whose name starts with the task's prefix for the object
    (:attr:`pbdkit.sim.TaskSpec.patches`: e.g. the glass's red band is 12 thin boxes
    ``glass_patch0..11``, the coaster one blue cylinder ``coaster``). For an object placed as a
    pose, its two end patches' geoms; ``NAME:a`` or ``NAME:b`` (:func:`patch_models`) names one
    end's.

    Parameters
    ----------
    sim : Simulation
    name : str
        An object with a patch in the task's ``patches``, or one end of a posed object.

    Returns
    -------
    ids : ndarray of int, shape (n_geoms,)
        At least one id.
    """
    spec = sim.info.spec
    obj, _, end = name.partition(":")
    if end and (obj not in spec.patches or spec.patch_ends(obj) is None or end not in "ab"):
        raise ValueError(
            f"objects: {short(name)} is not an end (NAME:a or NAME:b) of a posed object of the "
            f"{short(sim.info.task)} task"
        )
    models = patch_models(spec, [obj])
    prefixes = [models[name]] if end else list(models.values())
    model = sim.model
    ids = np.array(
        [
            i
            for i in range(model.ngeom)
            if any(model.geom(i).name.startswith(prefix) for prefix in prefixes)
        ],
        dtype=np.intp,
    )
    if ids.size == 0:
        shown = prefixes[0] if len(prefixes) == 1 else prefixes
        raise ValueError(
            f"objects: the scene has no geom named {short(shown)}... for {short(name)} (is "
            f"{short(obj)} an "
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
        Per color model (:func:`patch_models`: an object with one patch by its name, a posed
        object's two ends as ``NAME:a`` and ``NAME:b``): True where the front-most surface is
        one of the patch's geoms (occluded parts are not labelled), aligned with
        :meth:`Simulation.render` of the same camera.
    """
    keys = patch_models(sim.info.spec, objects)
    ids = {key: patch_geom_ids(sim, key) for key in keys}
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


@dataclass(frozen=True, kw_only=True)
class Calibration:
    """What :meth:`SimTracker.from_simulation` measured at the calibration placement.

    Attributes
    ----------
    placement : dict str -> ndarray, shape (3,) or (4, 4)
        True object positions during calibration (a posed object's pose).
    pixels : dict str -> tuple of int
        Labelled patch pixels per camera (a, b) used to fit each color model (a posed object's
        ends: ``NAME:a``, ``NAME:b``).
    raw_positions : dict str -> ndarray, shape (3,)
        Tracked positions before the offset correction (a posed object's: the midpoint of its
        ends).
    raw_yaws : dict str -> float
        A posed object's heading from end a to end b (rad), before the yaw offset.
    """

    placement: dict[str, Float]
    pixels: dict[str, tuple[int, int]]
    raw_positions: dict[str, Float]
    raw_yaws: dict[str, float] = field(default_factory=dict)


class SimTracker:
    """The stereo tracker of a simulated scene: two renders -> object positions (poses).

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
        Tracked objects (the tracker's ``objects``: its color models, a posed object in place
        of its two ends; the keys of :meth:`pbdkit.vision.StereoTracker.track_objects`).
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
            raise ValueError(f"cameras must be two different camera names, got {short(cameras)}")
        self.tracker = tracker
        self.cameras = (str(cameras[0]), str(cameras[1]))
        self.objects = tracker.objects
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
        offset_frame: OffsetFrame = "object",
        pose_views: int = 5,
        **tracker_options: Any,
    ) -> SimTracker:
        """Calibrate a tracker on a simulated scene, as a calibration session would.

        With ``at_nominal`` (default), a separate scene of ``sim``'s task is built with every
        object at its nominal place (the centre of its placement range) and ``sim`` is left
        untouched; otherwise ``sim`` is used in its current state. On that scene: one RGB render
        and one segmentation render per camera; each object's color model is fitted on its
        labelled patch pixels of both images; then, with ``correct_bias``, the tracker runs on
        the same images and ``offset = true position - tracked position`` per object. A posed
        object (two patches in the task's ``patches``) has a color model per end, and its
        :class:`pbdkit.vision.PoseModel` is measured there as well: the yaw offset (true yaw -
        heading from end a to end b), the offset from the ends' midpoint to its point in its
        own frame (``offset_frame``, module docstring) and the distance between the ends.

        Parameters
        ----------
        sim : Simulation
            A scene of the task to track.
        objects : sequence of str, optional
            Objects to track; default: those of the task that move
            (:attr:`TaskSpec.tracked_objects`).
        cameras : (str, str)
            Simulator camera names (a, b).
        calibrated_cameras : (PinholeCamera, PinholeCamera), optional
            The cameras as calibrated; default: exact, from :meth:`Simulation.camera_parameters`.
            Give e.g. ``cam.perturbed(0.001, 0.1)`` to study a calibration error (the offsets are
            then measured with those cameras, as they would be in a real session).
        at_nominal : bool
            Calibrate at the nominal placement (True) or on ``sim`` as it is (False).
        correct_bias : bool
            Measure and apply the per-object offset (see the module docstring); a posed
            object's pose is otherwise the raw one (the ends' midpoint and heading).
        arm : array-like, shape (n,), optional
            Arm joint angles during the calibration (e.g. the skill's start posture, out of the
            cameras' way); default: as the scene has them (with ``at_nominal``: at rest, q = 0,
            where the fingers can hide part of a coaster placed near the robot).
        offset_frame : {"object", "world"}
            The frame of a posed object's position offset: its own (default: the offset turns
            with it), or the world's (a constant vector, as for the other objects: for
            comparison, ``benchmarks/bench_pose_tracking.py``).
        pose_views : int
            Views in which a posed object's model is measured (with ``correct_bias``): 1, the
            calibration placement; k > 1 (default 5): the calibration placement's positions with
            each posed object turned to k yaws spread over its yaw range (the centres of k
            equal parts: -48, -24, 0, 24, 48 degrees for -60..60), the arm as in the
            calibration, and the k measurements averaged
            (:meth:`pbdkit.vision.PoseModel.calibrate`; module docstring).
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
            raise ValueError(
                f"objects must name at least one object to track, got {short(objects)}"
            )
        unknown = sorted(set(names) - set(sim.info.objects))
        if unknown:
            raise ValueError(
                f"objects: {unknown} are not objects of the {short(spec.name)} task; expected some "
                "of "
                f"{sorted(sim.info.objects)}"
            )
        for cam in cameras:
            sim.camera_id(cam)
        keys = patch_models(spec, names)
        posed = {k: (f"{k}:a", f"{k}:b") for k in names if spec.patch_ends(k) is not None}
        views = check_int(pose_views, "pose_views", minimum=1)
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
            for key in keys:
                counts = (int(masks[0][key].sum()), int(masks[1][key].sum()))
                pixels[key] = counts
                if min(counts) == 0:
                    raise ValueError(
                        f"objects: the patch of {short(key)} is not visible in camera "
                        f"{short(cameras[counts.index(0)])} at the calibration placement "
                        f"({counts[0]} and {counts[1]} labelled pixels)"
                    )
                models[key] = ColorModel.fit(images, [m[key] for m in masks])
            if calibrated_cameras is None:
                cam_a = PinholeCamera(*calib.camera_parameters(cameras[0]))
                cam_b = PinholeCamera(*calib.camera_parameters(cameras[1]))
            else:
                cam_a, cam_b = calibrated_cameras
            tracker = StereoTracker(cam_a, cam_b, models, **tracker_options)
            tracks = tracker.track(images[0], images[1])
            truth = calib.object_positions()
            poses = calib.object_poses()
            turned = (
                _turned_views(calib, tracker, posed, views, cameras)
                if posed and views > 1 and correct_bias
                else None
            )
        finally:
            if at_nominal:
                calib.close()
        found = {k: tr.position.copy() for k, tr in tracks.items() if tr.position is not None}
        raw = {k: v for k, v in found.items() if k in names}
        raw_yaws: dict[str, float] = {}
        for name, (a, b) in posed.items():
            if a in found and b in found:
                raw[name], raw_yaws[name] = ends_heading(found[a], found[b])
        pose_models = {name: PoseModel(ends) for name, ends in posed.items()}
        if correct_bias:
            if len(found) < len(keys):
                raise ValueError(
                    "objects: cannot measure the tracking offsets at the calibration placement: "
                    f"{ObjectNotSeenError(tracks)}"
                )
            offsets = {k: truth[k] - raw[k] for k in names if k not in posed}
            seen = turned or {
                name: (found[a], found[b], poses[name]) for name, (a, b) in posed.items()
            }
            pose_models = {
                name: PoseModel.calibrate(ends, *seen[name], frame=offset_frame)
                for name, ends in posed.items()
            }
            options = {**tracker_options, "offsets": offsets}
            if pose_models:
                options["poses"] = pose_models
            tracker = StereoTracker(cam_a, cam_b, models, **options)
        elif pose_models:
            tracker = StereoTracker(cam_a, cam_b, models, poses=pose_models, **tracker_options)
        placement = {
            k: np.asarray(poses[k] if k in posed else truth[k], dtype=np.float64) for k in names
        }
        return cls(
            tracker,
            cameras,
            Calibration(placement=placement, pixels=pixels, raw_positions=raw, raw_yaws=raw_yaws),
        )

    @property
    def offsets(self) -> dict[str, Float]:
        """Per-object offset added to the triangulated centroid, name -> (3,) (metres); a
        posed object's ends have none (see :attr:`pose_models`)."""
        return {k: v.copy() for k, v in self.tracker.offsets.items()}

    @property
    def pose_models(self) -> dict[str, PoseModel]:
        """The posed objects' :class:`pbdkit.vision.PoseModel` (offsets, yaw offset, span)."""
        return dict(self.tracker.poses)

    def images(self, sim: Simulation) -> tuple[NDArray[np.uint8], NDArray[np.uint8]]:
        """The two camera frames of ``sim``'s current state, each (240, 320, 3) uint8 RGB."""
        return sim.render(self.cameras[0]), sim.render(self.cameras[1])

    def locate(self, sim: Simulation) -> dict[str, ObjectTrack]:
        """One tracker cycle: render both cameras, track, triangulate.

        Parameters
        ----------
        sim : Simulation
            The scene in its current state (the same task as the calibration).

        Returns
        -------
        tracks : dict str -> Track or PoseTrack
            One per tracked object (:meth:`pbdkit.vision.StereoTracker.track_objects`);
            ``track.position`` (3,) only when ``track.status == "ok"``, and a posed object's
            ``track.pose`` (4, 4).
        """
        img_a, img_b = self.images(sim)
        return self.tracker.track_objects(img_a, img_b)


def _turned_views(
    calib: Simulation,
    tracker: StereoTracker,
    posed: Mapping[str, tuple[str, str]],
    views: int,
    cameras: tuple[str, str],
) -> dict[str, tuple[Float, Float, Float]]:
    """A posed object's end points and true poses over ``views`` scenes of ``calib``'s task:
    its placement, each posed object turned to the i-th of ``views`` yaws spread over its yaw
    range, the arm as in ``calib``. Name -> (a (k, 3), b (k, 3), poses (k, 4, 4))."""
    spec = calib.info.spec
    base = calib.object_placements()
    q = calib.joints()
    rows: dict[str, list[tuple[Float, Float, Float]]] = {k: [] for k in posed}
    for i in range(views):
        placement = dict(base)
        for name in posed:
            yaw_range = spec.ranges[name].yaw
            assert yaw_range is not None  # a posed object's range has a yaw
            lo, hi = yaw_range
            placement[name] = yaw_pose(base[name][:3, 3], lo + (i + 0.5) * (hi - lo) / views)
        view = Simulation.from_task(spec, placement)
        try:
            view.set_joints(q)
            tracks = tracker.track(view.render(cameras[0]), view.render(cameras[1]))
            truth = view.object_poses()
        finally:
            view.close()
        for name, (a, b) in posed.items():
            ta, tb = tracks[a], tracks[b]
            if ta.position is None or tb.position is None:
                raise ValueError(
                    f"objects: cannot measure the pose model of {short(name)} in calibration view "
                    f"{i} "
                    f"(turned to {math.degrees(yaw_of(placement[name])):.1f} deg): end a "
                    f"{ta.status}, end b {tb.status}"
                )
            rows[name].append((ta.position, tb.position, truth[name]))
    return {
        k: (np.array([r[0] for r in v]), np.array([r[1] for r in v]), np.array([r[2] for r in v]))
        for k, v in rows.items()
    }


def observed_objects(
    sim: Simulation,
    tracker: SimTracker,
    fixed: Mapping[str, npt.ArrayLike] | None = None,
) -> dict[str, Float]:
    """Object positions as the robot knows them: tracked objects from the cameras, plus fixed ones.

    A posed object's is its pose (4, 4), from its two end patches; it is not seen unless both
    ends are.

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
    objects : dict str -> ndarray, shape (3,) or (4, 4)
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
                f"fixed[{short(name)}]: {short(name)} is tracked by the cameras; fixed objects "
                "must be "
                f"others than {list(tracker.objects)}"
            )
    tracks = tracker.locate(sim)
    if not all(tr.ok for tr in tracks.values()):
        raise ObjectNotSeenError(tracks)
    out = {
        k: np.array(tr.pose if isinstance(tr, PoseTrack) else tr.position, dtype=np.float64)
        for k, tr in tracks.items()
    }
    out.update(known)
    return out
