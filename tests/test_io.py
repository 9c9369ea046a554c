"""Safe file I/O (pbdkit._io): atomic writes that behave like a plain write (mode, symlinks),
and ``.npz`` loading that never unpickles and names what is wrong with a foreign file."""

from __future__ import annotations

import io
import math
import os
import stat
import time
import tracemalloc
import warnings
import zipfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pbdkit._io import NpyHeader, atomic_write_bytes, open_npz, save_npz_atomic
from pbdkit.data._demonstration import Demonstration


def _load_all(path: Path, *, keys: Any = None, **options: Any) -> dict[str, np.ndarray]:
    """Every array of the archive at ``path``, read as the loaders read them: its headers
    checked on opening, then its keys (``keys``: the keys the format has), then each array."""
    with open_npz(path, **options) as archive:
        if keys is not None:
            archive.check_keys(keys)
        return {k: archive.read(k) for k in archive}


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


def test_open_npz_names_foreign_content(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    noise = tmp_path / "noise.npz"
    noise.write_bytes(rng.bytes(1000))
    with pytest.raises(ValueError, match=r"noise\.npz is not a NumPy \.npz archive"):
        _load_all(noise)
    npy = tmp_path / "array.npz"
    with npy.open("wb") as f:
        np.save(f, np.zeros(3))
    with pytest.raises(ValueError, match=r"array\.npz is not a NumPy \.npz archive"):
        _load_all(npy)
    empty = tmp_path / "empty.npz"
    empty.write_bytes(b"")
    with pytest.raises(ValueError, match=r"empty\.npz is not a NumPy \.npz archive"):
        _load_all(empty)
    # A real archive that holds an object array: the pickle is named, and never loaded.
    pickled = tmp_path / "pickled.npz"
    np.savez(pickled, a=np.array([{"x": 1}], dtype=object))
    with pytest.raises(ValueError, match=r"pickled\.npz .*pickle"):
        _load_all(pickled)


def test_save_and_load_round_trip(tmp_path: Path) -> None:
    path = tmp_path / "a.npz"
    save_npz_atomic(path, {"x": np.arange(3.0), "name": np.array("abc")})
    data = _load_all(path)
    np.testing.assert_array_equal(data["x"], np.arange(3.0))
    assert str(data["name"]) == "abc"
    with pytest.raises(TypeError, match="dtype object"):
        save_npz_atomic(path, {"x": np.array([None], dtype=object)})


# ----------------------------------------------------------------------------- .npz bombs
def _bomb(path: Path, arrays: dict[str, np.ndarray], key: str, shape: tuple[int, ...]) -> None:
    """An archive of ``arrays`` plus ``key``: zeros of ``shape`` (float64), compressed."""
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED, compresslevel=1) as zf:
        for k, v in arrays.items():
            with zf.open(f"{k}.npy", "w") as m:
                np.lib.format.write_array(m, np.asarray(v), allow_pickle=False)
        with zf.open(f"{key}.npy", "w", force_zip64=True) as m:
            header = {"descr": "<f8", "fortran_order": False, "shape": shape}
            np.lib.format.write_array_header_1_0(m, header)
            left, chunk = 8 * math.prod(shape), bytes(2**22)
            while left > 0:
                m.write(chunk[: min(left, len(chunk))])
                left -= len(chunk)


@pytest.fixture
def no_array_read(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """Record every array loaded through pbdkit._io (by the shape it has)."""
    loaded: list[str] = []
    real = np.lib.format.read_array

    def spy(fp: Any, *args: Any, **kwargs: Any) -> np.ndarray:
        out = real(fp, *args, **kwargs)
        loaded.append(str(out.shape))
        return out

    monkeypatch.setattr(np.lib.format, "read_array", spy)
    return loaded


def test_open_npz_reads_headers_only(tmp_path: Path, no_array_read: list[str]) -> None:
    path = tmp_path / "a.npz"
    save_npz_atomic(path, {"x": np.arange(6.0).reshape(2, 3), "name": np.array("abc")})
    with open_npz(path) as archive:
        assert set(archive) == {"x", "name"} and len(archive) == 2 and "x" in archive
        assert archive.headers["x"] == NpyHeader((2, 3), np.dtype("<f8"), 48)
        assert no_array_read == []
        np.testing.assert_array_equal(archive["x"], np.arange(6.0).reshape(2, 3))
        assert no_array_read == ["(2, 3)"]
        with pytest.raises(KeyError):
            archive["y"]


def test_npz_beyond_the_bound_is_refused_from_its_headers(
    tmp_path: Path, no_array_read: list[str]
) -> None:
    path = tmp_path / "big.npz"
    _bomb(path, {"x": np.zeros(3)}, "big", (2**17,))  # 1 MiB of zeros in a few kB
    assert path.stat().st_size < 10_000
    msg = r"big\.npz is not a valid file: its arrays would take more than 1.05 MB once loaded"
    with pytest.raises(ValueError, match=msg + r" \(at least 1.05 MB; key 'big': 1.05 MB\)"):
        _load_all(path, max_bytes=2**20)
    assert no_array_read == []
    assert set(_load_all(path, max_bytes=2**20 + 24)) == {"x", "big"}


def test_npz_unknown_keys_are_refused_before_loading(
    tmp_path: Path, no_array_read: list[str]
) -> None:
    path = tmp_path / "a.npz"
    _bomb(path, {"x": np.zeros(3)}, "extra", (1000,))
    with pytest.raises(ValueError, match=r"a\.npz is not a valid thing: unknown key\(s\) 'extra'"):
        _load_all(path, what="thing", keys={"x"})
    with pytest.raises(ValueError, match=r"unknown key\(s\) 'extra' \(8 kB\)"):
        _load_all(path, keys=lambda k: k.startswith("x"))
    assert no_array_read == []


def test_npz_members_that_are_not_arrays_truncated_or_twice_are_refused(tmp_path: Path) -> None:
    path = tmp_path / "a.npz"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("notes.txt", b"hello")
    with pytest.raises(ValueError, match=r"the member 'notes\.txt' is not an \.npy array"):
        _load_all(path)
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.arange(100.0))
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("x.npy", buf.getvalue()[:-80])
    with pytest.raises(ValueError, match=r"key 'x': the array declares 800 B .*\(truncated\)"):
        _load_all(path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # zipfile: "Duplicate name"
        with zipfile.ZipFile(path, "w") as zf:
            zf.writestr("x.npy", buf.getvalue())
            zf.writestr("x.npy", buf.getvalue())
    with pytest.raises(ValueError, match="the key 'x' is stored twice"):
        _load_all(path)


def test_npz_header_length_is_checked_before_the_header_is_read(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A version-2 .npy header may declare 4 GiB: its length is bounded before it is read."""
    path = tmp_path / "a.npz"
    length = 10**7
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("x.npy", b"\x93NUMPY\x02\x00" + length.to_bytes(4, "little") + b" " * length)
    reads: list[int] = []
    real = zipfile.ZipExtFile.read

    def read(self: zipfile.ZipExtFile, n: int = -1) -> bytes:
        reads.append(n)
        return real(self, n)

    monkeypatch.setattr(zipfile.ZipExtFile, "read", read)
    with pytest.raises(ValueError, match=r"key 'x': the \.npy header declares 10000000 bytes"):
        _load_all(path)
    assert max(reads) < 100


def _small_skill(tmp_path: Path) -> Path:
    from pbdkit.robots import katana
    from pbdkit.skill._skill import Skill

    rng = np.random.default_rng(3)
    arm = katana()
    mid = (arm.lower + arm.upper) / 2
    demos = [
        Demonstration(
            np.linspace(0, 2, 40),
            mid + 0.3 * np.sin(np.linspace(0, 3, 40))[:, None] + 0.01 * rng.normal(size=(40, 5)),
            {"glass": rng.normal(size=3) * 0.01 + [0.3, 0.0, 0.1]},
        )
        for _ in range(3)
    ]
    path = tmp_path / "skill.npz"
    Skill.learn(demos, arm, n_steps=30, n_components=1).save(path)
    return path


def test_skill_load_refuses_unknown_keys_and_bombs_before_loading(
    tmp_path: Path, no_array_read: list[str]
) -> None:
    from pbdkit.skill._skill import Skill
    from pbdkit.skill._skill_file import MAX_FILE_BYTES

    with np.load(_small_skill(tmp_path)) as data:
        arrays = {k: data[k] for k in data.files}
    no_array_read.clear()
    extra = tmp_path / "extra.npz"
    _bomb(extra, arrays, "evil", (4,))
    with pytest.raises(
        ValueError, match=r"extra\.npz is not a valid pbdkit-skill file: unknown key\(s\) 'evil'"
    ):
        Skill.load(extra)
    # Only the header keys were read (format, version, object_names).
    assert len(no_array_read) == 3
    # An object beyond object_names: gmm_1_* for a skill of one object.
    np.savez(tmp_path / "more.npz", **arrays, gmm_1_means=arrays["gmm_0_means"])
    with pytest.raises(ValueError, match=r"unknown key\(s\) 'gmm_1_means'"):
        Skill.load(tmp_path / "more.npz")
    no_array_read.clear()
    bomb = tmp_path / "bomb.npz"
    _bomb(bomb, arrays, "evil", (MAX_FILE_BYTES // 8 + 1,))
    assert bomb.stat().st_size < MAX_FILE_BYTES // 100
    with pytest.raises(ValueError, match=r"bomb\.npz .* would take more than 67.1 MB"):
        Skill.load(bomb)
    assert no_array_read == []


@pytest.mark.slow
def test_a_2_gb_bomb_is_refused_in_bounded_time_and_memory(tmp_path: Path) -> None:
    """The issue's case: a demonstrations file of a few MB with an extra 2 GB array."""
    from pbdkit.data._demonstration import load_demonstrations, save_demonstrations

    rng = np.random.default_rng(4)
    demos = [Demonstration(np.arange(50.0), rng.normal(size=(50, 3))) for _ in range(2)]
    save_demonstrations(demos, tmp_path / "d.npz")
    with np.load(tmp_path / "d.npz") as data:
        arrays = {k: data[k] for k in data.files}
    bomb = tmp_path / "bomb.npz"
    _bomb(bomb, arrays, "demo_9_t", (2**28,))
    tracemalloc.start()
    start = time.perf_counter()
    try:
        with pytest.raises(ValueError, match=r"would take more than 1.07 GB .* 'demo_9_t': 2.15"):
            load_demonstrations(bomb)
        seconds = time.perf_counter() - start
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert seconds < 2.0 and peak < 10 * 2**20
