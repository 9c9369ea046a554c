"""The report's video (issue 40): the fused run beside a failing single-space run, each half
labelled, the shorter run held on its last frame; and the MP4 written with the user's umask."""

from __future__ import annotations

import os
import stat
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from pbdkit.sim._video import save_video, side_by_side, video_partner


def _frames(n: int, width: int, value: int) -> np.ndarray:
    return np.full((n, 40, width, 3), value, dtype=np.uint8)


def test_two_runs_side_by_side_hold_the_shorter_one_and_carry_their_labels() -> None:
    rng = np.random.default_rng(0)
    left = rng.integers(0, 256, (5, 40, 32, 3), dtype=np.uint8)
    right = rng.integers(0, 256, (3, 40, 24, 3), dtype=np.uint8)
    out = side_by_side(left, right, ("fused: success", "joint: failure"))
    assert out.shape == (5, 40, 56, 3) and out.dtype == np.uint8
    # Below the label band, each half is its run; the shorter holds its last frame.
    np.testing.assert_array_equal(out[:, 16:, :32], left[:, 16:])
    np.testing.assert_array_equal(out[:3, 16:, 32:], right[:, 16:])
    np.testing.assert_array_equal(out[3:, 16:, 32:], np.repeat(right[-1:, 16:], 2, axis=0))
    # The band is darkened (to a third) and the text is drawn on it, in both halves.
    plain = side_by_side(left, right)
    np.testing.assert_array_equal(plain[:3, :16], np.concatenate([left[:3], right], 2)[:, :16])
    padded = np.concatenate([right, right[-1:], right[-1:]])
    for half, run in ((slice(0, 32), left), (slice(32, 56), padded)):
        labelled = out[:, :16, half]
        assert (labelled >= 250).any()  # white text
        # Elsewhere in the band, the run darkened: most pixels are exactly a third.
        assert np.mean(labelled == run[:, :16] // 3) > 0.5


def test_runs_of_different_heights_are_refused() -> None:
    with pytest.raises(ValueError, match="different heights"):
        side_by_side(_frames(2, 8, 0), np.zeros((2, 20, 8, 3), np.uint8))
    with pytest.raises(ValueError, match="uint8"):
        side_by_side(_frames(2, 8, 0), np.zeros((2, 40, 8, 3)))


def _run(success: bool, frames: np.ndarray | None) -> SimpleNamespace:
    return SimpleNamespace(success=success, execution=SimpleNamespace(frames=frames))


def test_the_run_beside_the_fused_one_is_the_first_that_fails() -> None:
    f = _frames(2, 8, 0)
    runs = {"fused": _run(True, f), "joint": _run(True, f), "task:glass": _run(False, f)}
    assert video_partner(runs) == "task:glass"
    runs["task:glass"] = _run(False, None)  # not filmed: the first filmed one instead
    assert video_partner(runs) == "joint"
    assert video_partner({"fused": _run(True, f)}) is None


@pytest.mark.parametrize("umask", [0o022, 0o077])
def test_the_video_gets_the_mode_the_umask_gives(tmp_path: Path, umask: int) -> None:
    old = os.umask(umask)
    try:
        path = save_video(_frames(3, 32, 128), tmp_path / "run.mp4")
    finally:
        os.umask(old)
    assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~umask  # mkstemp's was 0o600
    assert path.read_bytes()[4:8] == b"ftyp"
    assert [p.name for p in tmp_path.iterdir()] == ["run.mp4"]  # no temporary left
