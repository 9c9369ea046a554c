"""Safe file I/O: atomic writes and pickle-free ``.npz`` archives."""

from __future__ import annotations

import io
import os
import tempfile
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["atomic_write_bytes", "load_npz_safe", "save_npz_atomic"]


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes) -> None:
    """Write ``data`` to ``path`` so that readers see either the old file or the new one.

    The bytes go to a temporary file in the same directory, are flushed to disk, and the
    temporary file is renamed over ``path`` (atomic on POSIX and Windows).
    """
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def save_npz_atomic(path: str | os.PathLike[str], arrays: Mapping[str, NDArray[Any]]) -> None:
    """Save arrays to an ``.npz`` file atomically; object arrays are refused (no pickle)."""
    for key, value in arrays.items():
        if np.asarray(value).dtype == object:
            raise TypeError(f"array {key!r} has dtype object, which would need pickle")
    buf = io.BytesIO()
    payload: dict[str, Any] = {k: np.asarray(v) for k, v in arrays.items()}
    np.savez_compressed(buf, **payload)
    atomic_write_bytes(path, buf.getvalue())


def load_npz_safe(path: str | os.PathLike[str], *, what: str = "file") -> dict[str, NDArray[Any]]:
    """Load every array of an ``.npz`` file with ``allow_pickle=False``.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If the file is not a readable ``.npz`` archive (corrupt, truncated, foreign, or one
        that would need pickle to load).
    """
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"{what} not found: {p}")
    try:
        # Open the file ourselves: np.load(path) leaks its handle when the archive is truncated.
        with open(p, "rb") as f, np.load(f, allow_pickle=False) as data:
            return {k: data[k] for k in data.files}
    except (zipfile.BadZipFile, OSError, EOFError, KeyError) as exc:
        raise ValueError(f"{p} is not a valid {what} (not a readable .npz archive): {exc}") from exc
    except ValueError as exc:
        raise ValueError(f"{p} is not a valid {what}: {exc}") from exc
