"""Write recorded camera frames to an MP4 file (H.264 through the ffmpeg of ``imageio-ffmpeg``)."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._io import atomic_write_bytes


def _frames(frames: npt.ArrayLike) -> NDArray[np.uint8]:
    """``frames`` as an array, refused unless a non-empty uint8 array of RGB frames."""
    arr = np.asarray(frames)
    if arr.dtype != np.uint8 or arr.ndim != 4 or arr.shape[0] == 0 or arr.shape[3] != 3:
        raise ValueError(
            f"frames must be a non-empty uint8 array of shape (F, H, W, 3), got "
            f"{arr.dtype} {arr.shape}"
        )
    return arr


def save_video(frames: npt.ArrayLike, path: str | os.PathLike[str], fps: float = 15.0) -> Path:
    """Encode RGB frames as an MP4 video, atomically (a temporary file renamed at the end).

    Parameters
    ----------
    frames : array-like of uint8, shape (F, H, W, 3)
        RGB frames, e.g. :attr:`pbdkit.sim.ExecutionResult.frames`. H and W must be even
        (H.264 with yuv420p), which 240 x 320 is.
    path : str or os.PathLike
        Output file (``.mp4``).
    fps : float
        Frame rate.

    Returns
    -------
    pathlib.Path
        The written file.

    Raises
    ------
    ValueError
        If frames is not a non-empty uint8 array of shape (F, H, W, 3) with even H and W, or
        fps is not positive.
    """
    import imageio_ffmpeg  # the sim extra; imported here so that the rest works without it

    arr = _frames(frames)
    if arr.shape[1] % 2 or arr.shape[2] % 2:
        raise ValueError(f"frames: height and width must be even, got {arr.shape[1:3]}")
    if not fps > 0:
        raise ValueError(f"fps must be > 0, got {fps}")
    out = Path(path)
    # Encoded in a private folder, then written in one piece with the user's umask
    # (atomic_write_bytes): a temporary file of mkstemp's left the video 0o600.
    with tempfile.TemporaryDirectory() as folder:
        tmp = os.path.join(folder, "video.mp4")
        writer = imageio_ffmpeg.write_frames(
            tmp,
            (arr.shape[2], arr.shape[1]),
            fps=fps,
            codec="libx264",
            pix_fmt_out="yuv420p",
            macro_block_size=1,
            ffmpeg_log_level="error",
        )
        writer.send(None)  # start the generator
        for frame in arr:
            writer.send(np.ascontiguousarray(frame))
        writer.close()
        atomic_write_bytes(out, Path(tmp).read_bytes())
    return out


def side_by_side(
    left: npt.ArrayLike, right: npt.ArrayLike, labels: tuple[str, str] = ("", "")
) -> NDArray[np.uint8]:
    """Two runs' frames side by side, each labelled in its top-left corner: (F, H, W1 + W2, 3).

    The shorter run holds its last frame until the longer one ends (F is the longer's count),
    so both start together and the end of each stays in view.

    Parameters
    ----------
    left, right : array-like of uint8, shape (F_i, H, W_i, 3)
        RGB frames of the same height.
    labels : (str, str)
        Drawn in white on a dark band at the top of each half ("" draws none).
    """
    import cv2  # the sim extra, as the cameras

    halves = [_frames(left), _frames(right)]
    if halves[0].shape[1] != halves[1].shape[1]:
        raise ValueError(f"frames of different heights: {halves[0].shape[1]}, {halves[1].shape[1]}")
    n = max(x.shape[0] for x in halves)
    padded = [np.concatenate([x, np.repeat(x[-1:], n - x.shape[0], axis=0)]) for x in halves]
    out = np.concatenate(padded, axis=2)
    x0 = 0
    for x, label in zip(halves, labels, strict=True):
        if label:
            out[:, :16, x0 : x0 + x.shape[2]] //= 3  # a dark band the text reads on
            for frame in out:
                cv2.putText(
                    frame, label, (x0 + 4, 12), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1,
                    cv2.LINE_AA,
                )  # fmt: skip
        x0 += x.shape[2]
    return out


def video_partner(runs: dict[str, Any]) -> str | None:
    """The single-space controller the report's video shows beside the fused one: the first
    that fails (the paper's point), else the first; None without one, or without frames."""
    others = [
        n
        for n, run in runs.items()
        if n != "fused" and run.execution.frames is not None and len(run.execution.frames)
    ]
    failing = [n for n in others if not runs[n].success]
    chosen = failing or others
    return chosen[0] if chosen else None


def verdict_label(name: str, success: bool) -> str:
    """A run's label in the video: its controller and its outcome."""
    return f"{name}: {'success' if success else 'failure'}"


def beside_caption(runs: dict[str, Any]) -> str:
    """What the report's caption adds when :func:`video_partner` is shown beside the fused run
    ("" without one)."""
    beside = video_partner(runs)
    if beside is None:
        return ""
    how = "succeeds too" if runs[beside].success else "fails"
    return f" on the left, the {beside} controller on the right ({how})"
