"""Safe file I/O (pbdkit._io): atomic writes that behave like a plain write (mode, symlinks),
and ``.npz`` loading that never unpickles and names what is wrong with a foreign file."""

from __future__ import annotations

import os
import stat
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from pbdkit._io import atomic_write_bytes, load_npz_safe, save_npz_atomic


@contextmanager
def umask(mask: int) -> Iterator[None]:
    old = os.umask(mask)
    try:
        yield
    finally:
        os.umask(old)


def mode(path: Path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


def leftovers(folder: Path) -> list[Path]:
    return sorted(folder.glob(".*.tmp"))


@pytest.mark.parametrize(("mask", "expected"), [(0o022, 0o644), (0o077, 0o600), (0o002, 0o664)])
def test_new_file_gets_the_mode_the_umask_gives(tmp_path: Path, mask: int, expected: int) -> None:
    path = tmp_path / "new.bin"
    with umask(mask):
        atomic_write_bytes(path, b"data")
    assert path.read_bytes() == b"data"
    assert mode(path) == expected
    assert leftovers(tmp_path) == []


@pytest.mark.parametrize("existing", [0o644, 0o640, 0o600])
def test_overwriting_keeps_the_existing_mode(tmp_path: Path, existing: int) -> None:
    path = tmp_path / "old.bin"
    path.write_bytes(b"old")
    path.chmod(existing)
    with umask(0o077):
        atomic_write_bytes(path, b"new")
    assert path.read_bytes() == b"new"
    assert mode(path) == existing


def test_writing_through_a_symlink_writes_the_target_and_keeps_the_link(tmp_path: Path) -> None:
    real_dir = tmp_path / "real"
    real_dir.mkdir()
    target = real_dir / "skill.npz"
    target.write_bytes(b"old")
    target.chmod(0o644)
    link = tmp_path / "link.npz"
    link.symlink_to(os.path.relpath(target, tmp_path))
    with umask(0o077):
        atomic_write_bytes(link, b"new")
    assert link.is_symlink()
    assert target.read_bytes() == b"new"
    assert mode(target) == 0o644
    assert leftovers(tmp_path) == [] and leftovers(real_dir) == []
    # A dangling link: the file it names is created, as open(link, "wb") would.
    dangling = tmp_path / "dangling.npz"
    dangling.symlink_to(real_dir / "later.npz")
    atomic_write_bytes(dangling, b"later")
    assert dangling.is_symlink()
    assert (real_dir / "later.npz").read_bytes() == b"later"


def test_a_failed_write_keeps_the_old_file_and_leaves_no_temporary(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "keep.bin"
    path.write_bytes(b"old")

    def fail(*args: object, **kwargs: object) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "fsync", fail)
    with pytest.raises(OSError, match="No space left"):
        atomic_write_bytes(path, b"new")
    assert path.read_bytes() == b"old"
    assert leftovers(tmp_path) == []


def test_writing_over_a_directory_is_refused(tmp_path: Path) -> None:
    folder = tmp_path / "out"
    folder.mkdir()
    with pytest.raises(IsADirectoryError, match="out"):
        atomic_write_bytes(folder, b"x")
    assert leftovers(tmp_path) == []


def test_load_npz_safe_names_foreign_content(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    noise = tmp_path / "noise.npz"
    noise.write_bytes(rng.bytes(1000))
    with pytest.raises(ValueError, match=r"noise\.npz is not a NumPy \.npz archive"):
        load_npz_safe(noise)
    npy = tmp_path / "array.npz"
    with npy.open("wb") as f:
        np.save(f, np.zeros(3))
    with pytest.raises(ValueError, match=r"array\.npz is not a NumPy \.npz archive"):
        load_npz_safe(npy)
    empty = tmp_path / "empty.npz"
    empty.write_bytes(b"")
    with pytest.raises(ValueError, match=r"empty\.npz is not a NumPy \.npz archive"):
        load_npz_safe(empty)
    # A real archive that holds an object array: the pickle is named, and never loaded.
    pickled = tmp_path / "pickled.npz"
    np.savez(pickled, a=np.array([{"x": 1}], dtype=object))
    with pytest.raises(ValueError, match=r"pickled\.npz .*pickle"):
        load_npz_safe(pickled)


def test_save_and_load_round_trip(tmp_path: Path) -> None:
    path = tmp_path / "a.npz"
    save_npz_atomic(path, {"x": np.arange(3.0), "name": np.array("abc")})
    data = load_npz_safe(path)
    np.testing.assert_array_equal(data["x"], np.arange(3.0))
    assert str(data["name"]) == "abc"
    with pytest.raises(TypeError, match="dtype object"):
        save_npz_atomic(path, {"x": np.array([None], dtype=object)})
