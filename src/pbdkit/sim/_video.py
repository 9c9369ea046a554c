"""Write recorded camera frames to an MP4 file (H.264 through the ffmpeg of ``imageio-ffmpeg``)."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
import numpy.typing as npt


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

    arr = np.asarray(frames)
    if arr.dtype != np.uint8 or arr.ndim != 4 or arr.shape[0] == 0 or arr.shape[3] != 3:
        raise ValueError(
            f"frames must be a non-empty uint8 array of shape (F, H, W, 3), got "
            f"{arr.dtype} {arr.shape}"
        )
    if arr.shape[1] % 2 or arr.shape[2] % 2:
        raise ValueError(f"frames: height and width must be even, got {arr.shape[1:3]}")
    if not fps > 0:
        raise ValueError(f"fps must be > 0, got {fps}")
    out = Path(path)
    fd, tmp = tempfile.mkstemp(suffix=".mp4", dir=out.parent if str(out.parent) else ".")
    os.close(fd)
    try:
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
        os.replace(tmp, out)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return out
